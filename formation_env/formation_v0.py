"""formation_v0: the PettingZoo environment (MPE2-style versioned entry module).

``parallel_env(**kwargs)`` is the parallel env (leaders are the agents), ``env(**kwargs)``
its AEC view (``pettingzoo.utils.parallel_to_aec``, which adds the order-enforcing wrapper;
actions are clipped by the env itself), ``raw_env`` the unwrapped parallel class. See
:class:`formation_env.env.formation.FormationEnv` for spaces, rewards and arguments.
"""

from __future__ import annotations

from typing import Any

from pettingzoo import AECEnv
from pettingzoo.utils import parallel_to_aec

from formation_env.env.formation import FormationEnv

__all__ = ["env", "parallel_env", "raw_env"]

raw_env = FormationEnv


def parallel_env(**kwargs: Any) -> FormationEnv:
    """The parallel env; keyword arguments as :class:`FormationEnv`."""
    return FormationEnv(**kwargs)


def env(**kwargs: Any) -> AECEnv:
    """The AEC view of :func:`parallel_env` (agents act in turn; the step happens after the last)."""
    return parallel_to_aec(FormationEnv(**kwargs))
