"""SuperSuit's PettingZoo-to-vector route made safe for Stable-Baselines3.

The stock route, ``concat_vec_envs_v1(pettingzoo_env_to_vec_env_v1(env), k,
base_class="stable_baselines3")``, has two defects for SB3 today:

1. ``PPO(seed=...)`` calls ``env.seed(seed)``, which the concatenated vector env
   does not have, and crashes.
2. It merges ``terminated | truncated`` into ``dones`` and drops the
   difference: SB3 never sees ``info["TimeLimit.truncated"]``, so a time-limit
   cut is treated as a true end and its value is not bootstrapped.

:class:`SharedPolicyVecEnv` keeps SuperSuit's ``MarkovVectorEnv`` (one vector
slot per agent, auto-reset, ``terminal_observation``) and replaces the
concatenation with a small SB3 ``VecEnv`` that seeds every copy
deterministically (copy i gets seed + i) and reports truncations as SB3 expects.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from pettingzoo import ParallelEnv
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvIndices
from supersuit.vector.markov_vector_wrapper import MarkovVectorEnv

__all__ = ["SharedPolicyVecEnv"]


class SharedPolicyVecEnv(VecEnv):
    """An SB3 ``VecEnv`` over ``len(env_fns)`` parallel-env copies x their agents.

    Slot ``i * n_agents + j`` is agent j of copy i, so one policy acts for every
    agent (parameter sharing, decentralised execution: each agent sees only its
    own observation).

    Args:
        env_fns: callables making PettingZoo ``ParallelEnv`` copies with the same agents and spaces.
    """

    def __init__(self, env_fns: Sequence[Callable[[], ParallelEnv]]) -> None:
        if not env_fns:
            raise ValueError("SharedPolicyVecEnv needs at least one environment factory")
        self.envs = [MarkovVectorEnv(fn()) for fn in env_fns]
        self.n_agents = self.envs[0].num_envs
        if any(e.num_envs != self.n_agents for e in self.envs):
            raise ValueError("every environment copy must have the same number of agents")
        first = self.envs[0]
        super().__init__(len(self.envs) * self.n_agents, first.observation_space, first.action_space)
        self.render_mode = first.render_mode
        self._actions: np.ndarray | None = None

    # ---------------------------------------------------------------- VecEnv API
    def reset(self) -> np.ndarray:
        obs, infos = [], []
        for i, env in enumerate(self.envs):
            seed = self._seeds[i * self.n_agents]
            o, inf = env.reset(seed=seed, options=self._options[i * self.n_agents] or None)
            obs.append(o)
            infos.extend(inf)
        self.reset_infos = infos
        self._reset_seeds()
        self._reset_options()
        return np.concatenate(obs)

    def seed(self, seed: int | None = None) -> Sequence[int | None]:
        """Seed the next reset: copy i (all its agents) gets ``seed + i``."""
        if seed is None:
            seed = int(np.random.SeedSequence().generate_state(1)[0])
        self._seeds = [seed + i for i in range(len(self.envs)) for _ in range(self.n_agents)]
        return self._seeds

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[dict[str, Any]]]:
        if self._actions is None:
            raise RuntimeError("step_wait called before step_async")
        obs, rews, dones, infos = [], [], [], []
        k = self.n_agents
        for i, env in enumerate(self.envs):
            o, r, term, trunc, inf = env.step(self._actions[i * k : (i + 1) * k])
            term = np.asarray(term, dtype=bool)
            trunc = np.asarray(trunc, dtype=bool)
            for j in range(k):
                if trunc[j] and not term[j]:
                    inf[j]["TimeLimit.truncated"] = True
            obs.append(o)
            rews.append(r)
            dones.append(term | trunc)
            infos.extend(inf)
        self._actions = None
        return np.concatenate(obs), np.concatenate(rews).astype(np.float32), np.concatenate(dones), infos

    def close(self) -> None:
        for env in self.envs:
            env.close()

    def render(self, mode: str | None = None) -> Any:
        return self.envs[0].render()

    def get_images(self) -> Sequence[np.ndarray | None]:
        return [env.render() for env in self.envs]

    # ---------------------------------------------------------------- attribute plumbing
    def _slot_envs(self, indices: VecEnvIndices) -> list[Any]:
        return [self.envs[i // self.n_agents].par_env for i in self._get_indices(indices)]

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        return [getattr(e.unwrapped, attr_name) for e in self._slot_envs(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        for e in self._slot_envs(indices):
            setattr(e.unwrapped, attr_name, value)

    def env_method(
        self, method_name: str, *method_args: Any, indices: VecEnvIndices = None, **method_kwargs: Any
    ) -> list[Any]:
        return [getattr(e.unwrapped, method_name)(*method_args, **method_kwargs) for e in self._slot_envs(indices)]

    def env_is_wrapped(self, wrapper_class: type, indices: VecEnvIndices = None) -> list[bool]:
        return [False for _ in self._get_indices(indices)]
