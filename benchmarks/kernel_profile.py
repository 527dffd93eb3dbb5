"""What the compiled batched measurement and a numba call cost: ``python -m benchmarks.kernel_profile``.

A profile behind the README's "what is left", not a comparison of its own. Two parts:

* ``measure_rows`` (the batched step's non-linear part) on the arguments of one step of the benchmark's vec env
  (B = 1024, narrow passage, 10 agents; section b of BENCHMARKS.md), on one thread, and the same call without the
  rays (the sensing given), without the agent pairs, and without the walls as well: what each part costs;
* the cost of calling a compiled function from Python: per array argument and per array it returns (the reason
  ``Engine.step1`` takes packed vectors and fills arrays the caller allocates).

Medians of interleaved repeats, microseconds.
"""

from __future__ import annotations

import statistics
import sys
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from .vec_profile import _warm

#: ``measure_rows``' arguments after (b0, b1), by name.
_MEASURE = (
    "pos prev vel ref act gprev circles walls rays thr pairs leaders perm pinv hfit box fast inv_cycles lin_lo lin_hi "
    "err_hi w_tail sense_in mode obs dist flags rew"
).split()


def _interleaved(fns: dict[str, Callable[[], Any]], calls: int, repeat: int = 15) -> dict[str, float]:
    """Median microseconds per call of each fn, the fns taking turns."""
    per: dict[str, list[float]] = {k: [] for k in fns}
    for fn in fns.values():
        fn()
    for _ in range(repeat):
        for name, fn in fns.items():
            t0 = time.perf_counter()
            for _ in range(calls):
                fn()
            per[name].append((time.perf_counter() - t0) / calls * 1e6)
    return {k: statistics.median(v) for k, v in per.items()}


def measure_parts(B: int = 1024) -> dict[str, float]:
    """``measure_rows`` on one thread, whole and with parts left out (see the module docstring)."""
    from formation_env.env import _kernel

    v, acts = _warm("narrow_passage", B)
    captured: dict[str, Any] = {}
    run0 = _kernel.run_rows

    def capture(fn: Any, b: int, threads: int, *args: Any) -> None:
        if fn is _kernel.step_end_rows:
            captured["measure"] = args[1]
        run0(fn, b, threads, *args)

    _kernel.run_rows = capture
    try:
        v.step(acts[0])
    finally:
        _kernel.run_rows = run0
    meas = list(captured["measure"])
    i = {name: j for j, name in enumerate(_MEASURE)}
    nl, od, L1 = meas[i["leaders"]].shape[0], meas[i["obs"]].shape[2], meas[i["lin_lo"]].shape[1]
    no_rays = list(meas)
    no_rays[i["mode"]], no_rays[i["sense_in"]] = _kernel.SENSE_GIVEN, np.zeros((B, nl, od - L1 - 1))
    no_pairs = list(no_rays)
    no_pairs[i["pairs"]] = np.ascontiguousarray(meas[i["pairs"]][:0])
    no_walls = list(no_pairs)
    no_walls[i["walls"]] = np.ascontiguousarray(meas[i["walls"]][:, :, :0])
    no_walls[i["rays"]] = np.ascontiguousarray(meas[i["rays"]][:, :, :0])
    cases = {"whole": meas, "without rays": no_rays, "and without pairs": no_pairs, "and without walls": no_walls}
    fns = {k: (lambda m=m: _kernel.measure_rows(0, B, *m)) for k, m in cases.items()}
    return _interleaved(fns, 20)


def call_costs() -> dict[str, float]:
    """Microseconds of a call of a compiled function that does nothing, by its arguments and returns."""
    from numba import njit

    x = np.ones(5)
    ns: dict[str, Any] = {}
    exec("def args28(" + ",".join(f"a{j}" for j in range(28)) + "): return 0", ns)
    args28 = njit(ns["args28"])

    @njit
    def args1(a: Any) -> int:
        return 0

    @njit
    def returns6(a: Any) -> Any:
        return np.empty(5), np.empty(5), np.empty(5), np.empty(5), np.empty(5), np.empty(5)

    @njit
    def returns1(a: Any) -> Any:
        return np.empty(5)

    arrays = [x] * 28
    fns = {
        "1 array argument": lambda: args1(x),
        "28 array arguments": lambda: args28(*arrays),
        "1 array argument, 1 new array returned": lambda: returns1(x),
        "1 array argument, 6 new arrays returned": lambda: returns6(x),
        "np.empty(5) (for comparison)": lambda: np.empty(5),
    }
    return _interleaved(fns, 20000, 7)


def main(argv: list[str]) -> int:
    parts = measure_parts()
    print(
        "measure_rows, B=1024, narrow passage, n=10, one thread (us): "
        + ", ".join(f"{k} {t:.0f}" for k, t in parts.items())
    )
    costs = call_costs()
    print("a numba call from Python (us): " + ", ".join(f"{k} {t:.2f}" for k, t in costs.items()))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
