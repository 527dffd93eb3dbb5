"""Where a ``FormationVecEnv`` step's time goes: ``python -m benchmarks.vec_profile [--switch] [scenario ...]``.

A profile, not a comparison: B = 1024 envs of the benchmark's 10-agent framework (section b of
BENCHMARKS.md), random actions in [-0.3, 0.3], timed in the steady state of auto-resets. It prints, per
step (ms), the whole SB3 ``step`` and its parts: the engine's batched step, the auto-resets
(``_next_episodes``: drawing ahead and taking the next episodes' rows), the finished slots' infos
(``_slot_infos``) and the per-slot empty info dicts (unpickled, timed alone on the same list).

``--switch`` (needs vmas) times instead each call after a switch between ours and VMAS's 3-agent
simple_spread (B = 1024 both), turn by turn as the benchmark's interleaved comparisons take turns: the
first calls after a switch are slower for both (caches, the other library's OpenMP threads), which is why
section (b) of the benchmark gives each a turn of about the same wall time.
"""

from __future__ import annotations

import pickle
import sys
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from .env_bench import _ten_agent_framework


def _timed(owner: Any, name: str, totals: dict[str, float]) -> None:
    """Wrap ``owner.name`` so that its seconds add up in ``totals[name]``."""
    fn: Callable[..., Any] = getattr(owner, name)

    def wrapper(*args: Any, **kwargs: Any) -> Any:
        t0 = time.perf_counter()
        try:
            return fn(*args, **kwargs)
        finally:
            totals[name] += time.perf_counter() - t0

    setattr(owner, name, wrapper)


def _warm(scenario: str, B: int) -> tuple[Any, list[np.ndarray]]:
    """The benchmark's vec env (B envs of the 10-agent framework) after 150 steps, in the steady state of auto-resets,
    and its 8 action sets (random, in [-0.3, 0.3])."""
    from formation_env.env.vector import FormationVecEnv

    v = FormationVecEnv(scenario, num_envs=B, mode="shared", seed=0, framework=_ten_agent_framework())
    v.reset()
    rng = np.random.default_rng(0)
    acts = [rng.uniform(-0.3, 0.3, (v.num_envs, v.p)).astype(np.float32) for _ in range(8)]
    for i in range(150):
        v.step(acts[i & 7])
    return v, acts


def profile(scenario: str, B: int = 1024, steps: int = 400) -> dict[str, float]:
    """Milliseconds per step of the whole step and of its parts (see the module docstring)."""
    v, acts = _warm(scenario, B)
    totals = dict.fromkeys(("step", "_next_episodes", "_slot_infos"), 0.0)
    _timed(v.engine, "step", totals)
    _timed(v, "_next_episodes", totals)
    _timed(v, "_slot_infos", totals)
    t0 = time.perf_counter()
    for i in range(steps):
        v.step(acts[i & 7])
    whole = time.perf_counter() - t0
    t0 = time.perf_counter()
    for _ in range(steps):
        pickle.loads(v._empty_infos)
    dicts = time.perf_counter() - t0
    ms = 1e3 / steps
    return {
        "VecEnv.step": whole * ms,
        "Engine.step": totals["step"] * ms,
        "auto-resets": totals["_next_episodes"] * ms,
        "finished slots' infos": totals["_slot_infos"] * ms,
        f"{v.num_envs} empty info dicts": dicts * ms,
    }


def switch_cost(scenario: str, B: int = 1024, turns: int = 40, calls: int = 30) -> dict[str, list[float]]:
    """Median milliseconds of the j-th call of a turn (j = 0 .. calls - 1), ours and VMAS's alternating."""
    import torch

    from .env_bench import _vmas_env, _vmas_step

    v, acts = _warm(scenario, B)
    vstep = _vmas_step(*_vmas_env("simple_spread", B), torch.get_num_threads())
    fns = {"ours": lambda j: v.step(acts[j & 7]), "vmas": lambda j: vstep()}
    per = {k: np.zeros((turns, calls)) for k in fns}
    for t in range(turns):
        for name, fn in fns.items():
            for j in range(calls):
                t0 = time.perf_counter()
                fn(j)
                per[name][t, j] = time.perf_counter() - t0
    return {k: (np.median(a, axis=0) * 1e3).tolist() for k, a in per.items()}


def main(argv: list[str]) -> int:
    if argv[:1] == ["--switch"]:
        for scenario in argv[1:] or ["narrow_passage"]:
            for name, ms in switch_cost(scenario).items():
                print(f"{scenario}: {name}, ms of the j-th call after a switch: " + " ".join(f"{x:.2f}" for x in ms))
        return 0
    for scenario in argv or ["narrow_passage", "hold"]:
        parts = profile(scenario)
        print(f"{scenario} (B=1024, n=10, ms per step): " + ", ".join(f"{k} {v:.3f}" for k, v in parts.items()))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
