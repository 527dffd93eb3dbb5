"""formation_v1: the PettingZoo environment with the learnable defaults of env version 1.

The same env as :mod:`formation_env.formation_v0` (:class:`formation_env.env.formation.FormationEnv`) with
the defaults of :data:`formation_env.env.versions.ENV_VERSIONS` ``[1]``: the ``approach`` and ``proximity``
reward terms instead of ``progress``. Keyword arguments sit over them (``reward_weights`` term by term).
"""

from __future__ import annotations

from typing import Any

from pettingzoo import AECEnv

from formation_env.env.formation import FormationEnv, aec_env
from formation_env.env.versions import with_version

__all__ = ["VERSION", "env", "parallel_env", "raw_env"]

VERSION = 1
raw_env = FormationEnv


def parallel_env(**kwargs: Any) -> FormationEnv:
    """The parallel env of version 1; keyword arguments as :class:`FormationEnv`."""
    return FormationEnv(**with_version(VERSION, kwargs))


def env(**kwargs: Any) -> AECEnv:
    """The AEC view of :func:`parallel_env`."""
    return aec_env(parallel_env(**kwargs))
