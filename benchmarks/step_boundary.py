"""What the Python/numba boundary of the compiled step costs at B = 1: ``python -m benchmarks.step_boundary``.

A profile behind section (a) of BENCHMARKS.md, not a comparison of its own. It times, on ``narrow_passage``:
``Engine.step``; the compiled step called with the engine's own arguments; and trivial numba functions that take
the same ``Consts`` and ``Episode`` records (and the ``Consts`` fields passed flat), the step's arrays, or return
17 arrays, as the step does. The differences say what a different boundary could save.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np
from numba import njit

from formation_env.env.engine import _NO_NOISE, _NO_STATE, Engine


def per_call_us(fn: Callable[[], Any], calls: int = 20_000) -> float:
    """Mean microseconds per call of ``fn`` (after one warm-up call)."""
    fn()
    t0 = time.perf_counter()
    for _ in range(calls):
        fn()
    return (time.perf_counter() - t0) / calls * 1e6


@njit
def _read_consts(c: Any) -> float:
    return c.dt


@njit
def _read_episode(ep: Any) -> int:
    return ep.pvec.shape[0]


@njit
def _take_arrays(*arrays: Any) -> int:
    return len(arrays)


@njit
def _return_17(n: int) -> tuple[Any, ...]:
    e = np.empty
    return (e(n), e(n), e(n), e(n), e(n), e(n), e(n), e(n), e(n), e(n), e(n), e(n), e(n), e(n), e(n)), e(n), e(n)


def main() -> None:
    eng = Engine("narrow_passage")
    state = eng.reset(np.random.default_rng(0), 1)
    acts = np.zeros((1, eng.n_l, eng.p))
    eng.step(state, acts)
    consts, mod = eng._kernel()
    args = eng._args(consts, state, acts, _NO_STATE, _NO_STATE, _NO_NOISE)
    names = ", ".join(type(consts)._fields)
    scope: dict[str, Any] = {}
    exec(f"def read_flat({names}):\n    return dt\n", scope)
    read_flat = njit(scope["read_flat"])
    flat = tuple(consts)
    rows = [
        ("Engine.step", lambda: eng.step(state, acts)),
        ("compiled step, the engine's arguments", lambda: mod.step(*args)),
        (f"Consts record in ({len(flat)} fields)", lambda: _read_consts(args[0])),
        ("the same fields passed flat", lambda: read_flat(*flat)),
        ("Episode record in", lambda: _read_episode(args[1])),
        (f"the step's other {len(args) - 2} arguments in", lambda: _take_arrays(*args[2:])),
        ("17 arrays returned", lambda: _return_17(3)),
    ]
    print("| call (B = 1) | us per call |\n|---|---|")
    for name, fn in rows:
        print(f"| {name} | {per_call_us(fn):.1f} |")


if __name__ == "__main__":
    main()
