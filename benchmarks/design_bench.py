"""Stress design: wall time of ``design_stress`` per method and size, and the condition number it reaches.

"sdp" (max-min eigenvalue) and "fast" (= "min_cond", minimum cond(Omega_ff)) run
on random 8-nearest-neighbour frameworks in 2D (``random_knn(n, 2, k=8, seed=0)``);
"constructive" on ``trilateration(n, 2, seed=0)``. Times include the final
``check_stress`` (sparse for "constructive") and the scaling to
lambda_max(Omega_ff) = 1; they exclude building the framework. kappa =
cond(Omega_ff); the best sampled-data rate (eq. 17, T = 2 / (lambda_min +
lambda_max)) is rho = (kappa - 1) / (kappa + 1), and "samples to 1e-6" is
ln(1e-6) / ln(rho), the number of samples for the error to fall by 10^6.
Run alone: ``python -m benchmarks.design_bench [--quick]``.
"""

from __future__ import annotations

import argparse
import functools
import math
import time
from collections.abc import Sequence

from formation_env.core.design import condition_number, design_stress
from formation_env.core.frameworks import hexagon, random_knn, trilateration

from .timing import summary

TITLE = "Stress design (design_stress): time and cond(Omega_ff) per method"


def _row(method: str, fw_name: str, n: int, fn: functools.partial, leaders: Sequence[int], repeat: int) -> dict:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        omega = fn()
        times.append(time.perf_counter() - t0)
    med, lo, hi = summary(times)
    kappa = condition_number(omega, leaders)
    rho = (kappa - 1) / (kappa + 1)
    return {
        "method": method,
        "framework": fw_name,
        "n": n,
        "median_s": med,
        "min_s": lo,
        "max_s": hi,
        "repeat": repeat,
        "cond": kappa,
        "samples_to_1e-6": math.ceil(math.log(1e-6) / math.log(rho)) if rho > 0 else 1,
    }


def run(
    quick: bool = False,
    sdp_sizes: Sequence[int] = (10, 20, 40),
    constructive_sizes: Sequence[int] = (100, 1000, 10_000),
    k: int = 8,
    seed: int = 0,
) -> list[dict]:
    """Time each method at each size; one row per (method, n), "sdp" and "fast" side by side."""
    repeat = 1 if quick else 3
    design_stress(hexagon())  # import cvxpy and its solvers outside the timings
    rows = []
    for n in sdp_sizes:
        fw = random_knn(n, 2, k=k, seed=seed)
        for method in ("sdp", "fast"):
            rows.append(
                _row(method, f"random_knn k={k}", n, functools.partial(design_stress, fw, method), fw.leaders, repeat)
            )
    for n in constructive_sizes:
        fw = trilateration(n, 2, seed=seed)
        fn = functools.partial(design_stress, fw, "constructive")
        rows.append(_row("constructive", "trilateration", n, fn, fw.leaders, repeat))
    return rows


def markdown(rows: list[dict]) -> str:
    """The rows as a markdown table."""
    out = [
        "| method | framework (2D) | n | time, median (min-max) | cond(Omega_ff) | samples to 1e-6 |",
        "|---|---|---:|---|---:|---:|",
    ]
    for r in rows:
        time = f"{r['median_s']:.3g} s ({r['min_s']:.3g}-{r['max_s']:.3g})"
        out.append(
            f"| {r['method']} | {r['framework']} | {r['n']:,} | {time} | {r['cond']:.3g} | {r['samples_to_1e-6']:,} |"
        )
    return "\n".join(out)


def main(argv: Sequence[str] | None = None) -> None:
    """Print the table; ``--sizes`` and ``--constructive-sizes`` override the defaults."""
    p = argparse.ArgumentParser(prog="python -m benchmarks.design_bench", description=__doc__)
    p.add_argument("--quick", action="store_true", help="one repeat instead of three")
    p.add_argument("--sizes", type=int, nargs="*", default=[10, 20, 40], help="n for sdp and fast")
    p.add_argument("--constructive-sizes", type=int, nargs="*", default=[100, 1000, 10_000], help="n for constructive")
    args = p.parse_args(argv)
    print(markdown(run(args.quick, args.sizes, args.constructive_sizes)))


if __name__ == "__main__":
    main()
