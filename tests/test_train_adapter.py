"""The SuperSuit -> SB3 adapter: seeding works with PPO(seed=...), truncations reach SB3 as such."""

from __future__ import annotations

import functools

import numpy as np
import pytest
from gymnasium import spaces
from pettingzoo import ParallelEnv

from train.shared_vec_env import SharedPolicyVecEnv


class _Toy(ParallelEnv):
    """Two agents on a line; terminates when an agent passes 3, truncates after ``max_cycles``."""

    metadata = {"name": "toy_v0", "render_modes": []}

    def __init__(self, max_cycles: int = 5) -> None:
        self.possible_agents = ["a_0", "a_1"]
        self.max_cycles = max_cycles
        self._obs = spaces.Box(-10, 10, (1,), np.float32)
        self._act = spaces.Box(-1, 1, (1,), np.float32)
        self.render_mode = None

    def observation_space(self, agent: str) -> spaces.Box:
        return self._obs

    def action_space(self, agent: str) -> spaces.Box:
        return self._act

    def reset(self, seed=None, options=None):
        if seed is not None or not hasattr(self, "rng"):
            self.rng = np.random.default_rng(seed)
        self.agents = list(self.possible_agents)
        self.x = self.rng.uniform(-1, 1, size=2).astype(np.float32)
        self.t = 0
        return {a: self.x[i : i + 1].copy() for i, a in enumerate(self.agents)}, {a: {} for a in self.agents}

    def step(self, actions):
        self.t += 1
        for i, a in enumerate(self.agents):
            self.x[i] += float(actions[a][0])
        term = bool(np.any(np.abs(self.x) > 3))
        trunc = self.t >= self.max_cycles and not term
        obs = {a: np.clip(self.x[i : i + 1], -10, 10) for i, a in enumerate(self.agents)}
        rew = {a: float(-abs(self.x[i])) for i, a in enumerate(self.agents)}
        terms = {a: term for a in self.agents}
        truncs = {a: trunc for a in self.agents}
        infos = {a: {} for a in self.agents}
        if term or trunc:
            self.agents = []
        return obs, rew, terms, truncs, infos


def _vec(n: int = 3, max_cycles: int = 5) -> SharedPolicyVecEnv:
    return SharedPolicyVecEnv([functools.partial(_Toy, max_cycles)] * n)


def test_slots_are_copies_times_agents():
    v = _vec(3)
    assert v.num_envs == 6
    assert v.reset().shape == (6, 1)


def test_truncation_is_reported_to_sb3():
    v = _vec(2, max_cycles=4)
    v.seed(0)
    v.reset()
    for _ in range(3):
        _, _, dones, infos = v.step(np.zeros((4, 1), np.float32))
        assert not dones.any()
    _, _, dones, infos = v.step(np.zeros((4, 1), np.float32))
    assert dones.all()
    assert all(inf.get("TimeLimit.truncated") is True for inf in infos)
    assert all("terminal_observation" in inf for inf in infos)


def test_termination_is_not_marked_truncated():
    v = _vec(1, max_cycles=50)
    v.seed(0)
    v.reset()
    _, _, dones, infos = v.step(np.ones((2, 1), np.float32))
    while not dones.any():
        _, _, dones, infos = v.step(np.ones((2, 1), np.float32))
    assert not any(inf.get("TimeLimit.truncated", False) for inf in infos)


def test_seed_makes_resets_reproducible_and_copies_differ():
    a, b = _vec(3), _vec(3)
    a.seed(7)
    b.seed(7)
    oa, ob = a.reset(), b.reset()
    np.testing.assert_array_equal(oa, ob)
    assert not np.array_equal(oa[0:2], oa[2:4]), "copies must get different seeds (seed + i)"


def test_ppo_with_seed_runs_and_is_reproducible():
    from stable_baselines3 import PPO

    def train() -> np.ndarray:
        model = PPO("MlpPolicy", _vec(2), n_steps=16, batch_size=32, n_epochs=1, seed=3, device="cpu")
        model.learn(64)
        return next(iter(model.policy.parameters())).detach().numpy().copy()

    np.testing.assert_array_equal(train(), train())


def test_empty_factory_list_is_refused():
    with pytest.raises(ValueError, match="at least one"):
        SharedPolicyVecEnv([])
