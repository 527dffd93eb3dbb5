"""Where PPO's time goes with one env: ``python -m benchmarks.ppo_profile``.

A profile behind section (c) of BENCHMARKS.md, not a comparison of its own. Two parts, PPO with the
benchmark's settings (n_steps 256, batch 64, 4 epochs, torch on one thread):

* the time of each env's ``step`` (the unwrapped env's, and resets) inside ``learn``, for the commander env
  and Pendulum-v1: the cost of an env step within PPO's loop, where caches hold the policy's data;
* PPO on a constant env with the commander's spaces and with Pendulum's (nothing computed per step): what
  the larger observation and action (49 and 6 against 3 and 1) cost the policy by themselves.
"""

from __future__ import annotations

import statistics
import sys
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from .env_bench import PPO_SETTINGS as SETTINGS

COMMANDER = "formation_env/FormationCommander-v0"


def step_times(make: Callable[[], Any], steps: int = 4096) -> dict[str, float]:
    """Timesteps/s of PPO ``learn``, the microseconds per timestep spent in the env's step and resets, and the
    mean episode length."""
    from stable_baselines3 import PPO

    env = make()
    inner = env.unwrapped
    tot = {"step": 0.0, "reset": 0.0, "n": 0, "resets": 0}
    step0, reset0 = inner.step, inner.reset

    def step(action: Any) -> Any:
        t0 = time.perf_counter()
        out = step0(action)
        tot["step"] += time.perf_counter() - t0
        tot["n"] += 1
        return out

    def reset(*args: Any, **kwargs: Any) -> Any:
        t0 = time.perf_counter()
        out = reset0(*args, **kwargs)
        tot["reset"] += time.perf_counter() - t0
        tot["resets"] += 1
        return out

    inner.step, inner.reset = step, reset
    model = PPO("MlpPolicy", env, n_steps=256, **SETTINGS)
    t0 = time.perf_counter()
    model.learn(steps)
    wall = time.perf_counter() - t0
    n = max(int(tot["n"]), 1)
    return {
        "timesteps/s": steps / wall,
        "step us": tot["step"] / n * 1e6,
        "reset us": tot["reset"] / n * 1e6,
        "steps an episode": n / max(int(tot["resets"]), 1),
    }


def constant_env(like: Any) -> Any:
    """An env with ``like``'s spaces that computes nothing: a fixed observation, episodes of 200 steps."""
    import gymnasium as gym

    class Constant(gym.Env):  # type: ignore[type-arg]
        def __init__(self) -> None:
            self.observation_space, self.action_space = like.observation_space, like.action_space
            self._obs = np.zeros(like.observation_space.shape, dtype=like.observation_space.dtype)
            self._t = 0

        def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> Any:
            super().reset(seed=seed)
            self._t = 0
            return self._obs, {}

        def step(self, action: Any) -> Any:
            self._t += 1
            return self._obs, 0.0, False, self._t >= 200, {}

    return Constant()


def main(argv: list[str]) -> int:
    import gymnasium as gym
    import torch
    from stable_baselines3 import PPO

    import formation_env  # noqa: F401  (registers the commander env)

    torch.set_num_threads(1)
    makers = {"commander": lambda: gym.make(COMMANDER), "Pendulum-v1": lambda: gym.make("Pendulum-v1")}
    for name, make in makers.items():
        PPO("MlpPolicy", make(), n_steps=256, **SETTINGS).learn(256)  # warm up
        t = step_times(make)
        print(
            f"{name}: PPO {t['timesteps/s']:.0f} timesteps/s; per timestep, the env's step {t['step us']:.1f} us "
            f"and its resets {t['reset us']:.1f} us ({t['steps an episode']:.0f} steps an episode)"
        )
    spaces = {"commander's spaces": gym.make(COMMANDER), "Pendulum's spaces": gym.make("Pendulum-v1")}
    rates: dict[str, list[float]] = {k: [] for k in spaces}
    for _ in range(3):
        for name, like in spaces.items():
            env = constant_env(like)
            t0 = time.perf_counter()
            PPO("MlpPolicy", env, n_steps=256, **SETTINGS).learn(2048)
            rates[name].append(2048 / (time.perf_counter() - t0))
    for name, r in rates.items():
        obs, act = spaces[name].observation_space.shape, spaces[name].action_space.shape
        print(f"constant env with the {name} (obs {obs}, action {act}): PPO {statistics.median(r):.0f} timesteps/s")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
