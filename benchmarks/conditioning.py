"""cond(Omega_ff) and samples to 1e-6 at T_opt of the constructive stress on trilateration swarms.

For n = 100, 1,000, 10,000 in 2D and leader counts k = d + 1 .. 1 % of n, builds
``trilateration(n, 2, seed=0, n_leaders=k)`` (hierarchical, farthest-point leaders),
designs ``design_stress(fw, "constructive")`` (checked by ``check_stress``), measures
lambda_min, lambda_max of Omega_ff with ``extreme_eigenvalues`` (sparse Lanczos above
2,000 followers) and prints a Markdown table: cond, the stationary law's rho at
T_opt = 2 / (lambda_min + lambda_max), i.e. (cond - 1) / (cond + 1), the samples to shrink
the error by 1e6, ln(1e-6) / ln(rho), and the build + design + check time. The default
(``n_leaders=None``, leaders 0..d, random insertion) is the first row of each n.

Run: ``python -m benchmarks.conditioning`` (``--quick`` stops at n = 1,000).
"""

from __future__ import annotations

import math
import os
import platform
import sys
import time
from datetime import datetime, timezone

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from formation_env.core.analysis import extreme_eigenvalues
from formation_env.core.design import design_stress
from formation_env.core.frameworks import trilateration
from formation_env.core.stress import Partition


def row(n: int, d: int, k: int | None) -> str:
    t0 = time.perf_counter()
    fw = trilateration(n, d, seed=0, n_leaders=k)
    omega = design_stress(fw, "constructive")
    t_design = time.perf_counter() - t0
    lo, hi = extreme_eigenvalues(Partition(omega, fw.leaders))
    cond = hi / lo
    rho = (cond - 1) / (cond + 1)
    steps = math.log(1e-6) / math.log(rho)
    t_opt = 2 / (lo + hi)
    label = f"{len(fw.leaders)} (default)" if k is None else str(k)
    return f"| {n:,} | {label} | {cond:,.0f} | {t_opt:.3g} | {steps:,.0f} | {int(fw.degree().max())} | {t_design:.2f} |"


def main(argv: list[str]) -> None:
    sizes = (100, 1000) if "--quick" in argv else (100, 1000, 10000)
    d = 2
    print(
        f"Machine: {platform.node()} ({platform.machine()}, {os.cpu_count()} cores), Python "
        f"{platform.python_version()}; {datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC"
    )
    print("Command: `python -m benchmarks.conditioning`\n")
    print(
        "| n | leaders k | cond(Omega_ff) | T_opt (s) | samples to 1e-6 at T_opt | max degree "
        "| build + design + check (s) |"
    )
    print("|---:|---:|---:|---:|---:|---:|---:|")
    for n in sizes:
        ks = sorted({d + 1, max(d + 1, n // 400), max(d + 1, n // 200), max(d + 1, n // 100)})
        print(row(n, d, None))
        for k in ks:
            print(row(n, d, k))


if __name__ == "__main__":
    main(sys.argv[1:])
