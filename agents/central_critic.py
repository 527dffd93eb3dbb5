"""A decentralised actor with a centralised critic (MAPPO's split) as an SB3 ``ActorCriticPolicy``.

Each slot's observation is ``[o_i, s]``: leader i's own observation o_i (``actor_dim`` entries, first) and the
global state s (``Engine.global_state``, ``FormationVecEnv(critic_state=True)``). The critic reads both; the
actor reads only o_i: its features are the observation with every entry past ``actor_dim`` set to zero, so its
action cannot depend on s (the gradient through the zeroed entries is zero too). At run time a leader therefore
needs only its own observation (``agents.policy.LearnedPolicy`` passes zeros for s).

Example::

    from stable_baselines3 import PPO
    from formation_env.env.vector import FormationVecEnv
    from agents.central_critic import LocalActorPolicy

    venv = FormationVecEnv("narrow_passage", num_envs=8, mode="shared", critic_state=True)
    PPO(LocalActorPolicy, venv, policy_kwargs={"actor_dim": venv.engine.obs_dim}).learn(2_048)
"""

from __future__ import annotations

from typing import Any

import gymnasium
import torch as th
from stable_baselines3.common.policies import ActorCriticPolicy
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor

__all__ = ["LocalActorPolicy", "LocalFeatures"]


class LocalFeatures(BaseFeaturesExtractor):
    """The observation (batch, dim) with entries ``actor_dim:`` set to zero: the actor's own part only."""

    def __init__(self, observation_space: gymnasium.spaces.Box, actor_dim: int) -> None:
        dim = int(observation_space.shape[0])
        if not 0 < actor_dim <= dim:
            raise ValueError(f"actor_dim must be in [1, {dim}] (the observation's size), got {actor_dim}")
        super().__init__(observation_space, dim)
        mask = th.zeros(dim)
        mask[:actor_dim] = 1.0
        self.register_buffer("mask", mask)

    mask: th.Tensor  # (dim,) 1 on the actor's entries, a registered buffer

    def forward(self, observations: th.Tensor) -> th.Tensor:
        return th.flatten(observations, start_dim=1) * self.mask


class LocalActorPolicy(ActorCriticPolicy):
    """PPO's policy with the actor on the first ``actor_dim`` observation entries and the critic on all of them
    (separate feature extractors; see the module docstring)."""

    def __init__(self, *args: Any, actor_dim: int, **kwargs: Any) -> None:
        self.actor_dim = int(actor_dim)
        kwargs["share_features_extractor"] = False
        super().__init__(*args, **kwargs)

    def _build(self, lr_schedule: Any) -> None:
        self.pi_features_extractor = LocalFeatures(self.observation_space, self.actor_dim)  # type: ignore[arg-type]
        super()._build(lr_schedule)

    def _get_constructor_parameters(self) -> dict[str, Any]:
        return {**super()._get_constructor_parameters(), "actor_dim": self.actor_dim}
