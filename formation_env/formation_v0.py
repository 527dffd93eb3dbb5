"""formation_v0: the PettingZoo environment (MPE2-style versioned entry module).

``parallel_env(**kwargs)`` is the parallel env (leaders are the agents), ``env(**kwargs)`` its AEC view
(PettingZoo's ``parallel_to_aec`` wrapper, checking each action as it is given, and the order-enforcing
wrapper; actions are clipped by the env itself), ``raw_env`` the unwrapped parallel class. See
:class:`formation_env.env.formation.FormationEnv` for spaces, rewards and arguments.
"""

from __future__ import annotations

from typing import Any

from pettingzoo import AECEnv

from formation_env.env.formation import FormationEnv, aec_env

__all__ = ["env", "parallel_env", "raw_env"]

raw_env = FormationEnv


def parallel_env(**kwargs: Any) -> FormationEnv:
    """The parallel env; keyword arguments as :class:`FormationEnv`."""
    return FormationEnv(**kwargs)


def env(**kwargs: Any) -> AECEnv:
    """The AEC view of :func:`parallel_env` (agents act in turn; the step happens after the last)."""
    return aec_env(FormationEnv(**kwargs))
