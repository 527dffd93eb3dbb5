"""Where a ``FormationVecEnv`` step's time goes: ``python -m benchmarks.vec_profile [--switch] [scenario ...]``.

A profile, not a comparison: B = 1024 envs of the benchmark's 10-agent framework (section b of
BENCHMARKS.md), random actions in [-0.3, 0.3], timed in the steady state of auto-resets. It prints, per
step (ms), the whole SB3 ``step`` and its parts: the engine's batched step, the auto-resets
(``_next_episodes``: drawing ahead and taking the next episodes' rows), the finished slots' infos
(``_slot_infos``) and the per-slot empty info dicts (unpickled, timed alone on the same list).

Then, interleaved in turns, the whole step with the default per-slot empty infos against
``share_empty_infos=True`` (the unfinished slots share one read-only empty info): what SB3's dict per slot
costs in place, where making and freeing them competes with the step for the caches (the ratio is shared /
default, medians and quartiles over 31 turns of ~50 ms).

``--switch`` (needs vmas) times instead each call after a switch between ours and VMAS's 3-agent
simple_spread (B = 1024 both), turn by turn as the benchmark's interleaved comparisons take turns: the
first calls after a switch are slower for both (caches, the other library's OpenMP threads), which is why
section (b) of the benchmark gives each a turn of about the same wall time.
"""

from __future__ import annotations

import pickle
import statistics
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


def _warm(scenario: str, B: int, **kwargs: Any) -> tuple[Any, list[np.ndarray]]:
    """The benchmark's vec env (B envs of the 10-agent framework; ``kwargs`` to ``FormationVecEnv``) after 150 steps,
    in the steady state of auto-resets, and its 8 action sets (random, in [-0.3, 0.3])."""
    from formation_env.env.vector import FormationVecEnv

    v = FormationVecEnv(scenario, num_envs=B, mode="shared", seed=0, framework=_ten_agent_framework(), **kwargs)
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


def infos_gain(scenario: str, B: int = 1024, repeat: int = 31) -> dict[str, float]:
    """Env-steps/s of the whole step with per-slot empty infos (the default) and with ``share_empty_infos=True``,
    in alternating turns of ~50 ms (``env_bench._rates``): medians, and the quartiles of the per-turn ratios."""
    from .env_bench import _rates

    fns = {}
    for name, shared in (("per-slot", False), ("shared", True)):
        v, acts = _warm(scenario, B, share_empty_infos=shared)
        count = [0]

        def step(v: Any = v, acts: list[np.ndarray] = acts, count: list[int] = count) -> None:
            v.step(acts[count[0] & 7])
            count[0] += 1

        fns[name] = step
    rates = _rates(fns, dict.fromkeys(fns, float(B)), 10, repeat, turn_s=0.05)
    q1, med, q3 = statistics.quantiles([a / b for a, b in zip(rates["shared"], rates["per-slot"], strict=True)], n=4)
    return {
        "per-slot infos (env-steps/s)": statistics.median(rates["per-slot"]),
        "shared empty infos (env-steps/s)": statistics.median(rates["shared"]),
        "ratio": med,
        "ratio q1": q1,
        "ratio q3": q3,
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
    for scenario in argv or ["narrow_passage", "hold"]:
        g = infos_gain(scenario)
        print(
            f"{scenario}: per-slot infos {g['per-slot infos (env-steps/s)']:,.0f} env-steps/s, shared empty infos "
            f"{g['shared empty infos (env-steps/s)']:,.0f}: {g['ratio']:.2f}x (quartiles {g['ratio q1']:.2f}-"
            f"{g['ratio q3']:.2f})"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
