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
from typing import Any

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from formation_env.core.analysis import extreme_eigenvalues
from formation_env.core.design import design_stress
from formation_env.core.frameworks import trilateration
from formation_env.core.stress import Partition

#: Section title in BENCHMARKS.md (``python -m benchmarks --only conditioning``).
TITLE = "Large swarms: cond(Omega_ff) and samples to 1e-6 at T_opt (constructive stress on trilateration)"


def row(n: int, d: int, k: int | None) -> dict[str, Any]:
    """One framework: build, design and check it (timed), then measure cond(Omega_ff) and the samples to 1e-6."""
    t0 = time.perf_counter()
    fw = trilateration(n, d, seed=0, n_leaders=k)
    omega = design_stress(fw, "constructive")
    t_design = time.perf_counter() - t0
    lo, hi = extreme_eigenvalues(Partition(omega, fw.leaders))
    cond = hi / lo
    rho = (cond - 1) / (cond + 1)
    label = f"{len(fw.leaders)} (default)" if k is None else str(k)
    return {"n": n, "leaders": label, "cond": cond, "t_opt": 2 / (lo + hi), "samples": math.log(1e-6) / math.log(rho),
            "max_degree": int(fw.degree().max()), "seconds": t_design}  # fmt: skip


def run(quick: bool = False, d: int = 2) -> list[dict[str, Any]]:
    """Every row: n = 100, 1,000, 10,000 (``quick``: up to 1,000), the default leaders and k = d + 1 .. 1 % of n."""
    rows = []
    for n in (100, 1000) if quick else (100, 1000, 10000):
        rows.append(row(n, d, None))
        for k in sorted({d + 1, max(d + 1, n // 400), max(d + 1, n // 200), max(d + 1, n // 100)}):
            rows.append(row(n, d, k))
    return rows


def markdown(rows: list[dict[str, Any]]) -> str:
    """The rows as a markdown table."""
    out = [
        "| n | leaders k | cond(Omega_ff) | T_opt (s) | samples to 1e-6 at T_opt | max degree "
        "| build + design + check (s) |",
        "|---:|---:|---:|---:|---:|---:|---:|",
    ]
    out += [
        f"| {r['n']:,} | {r['leaders']} | {r['cond']:,.0f} | {r['t_opt']:.3g} | {r['samples']:,.0f} | "
        f"{r['max_degree']} | {r['seconds']:.2f} |"
        for r in rows
    ]
    return "\n".join(out)


def main(argv: list[str]) -> None:
    print(
        f"Machine: {platform.node()} ({platform.machine()}, {os.cpu_count()} cores), Python "
        f"{platform.python_version()}; {datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC"
    )
    print("Command: `python -m benchmarks.conditioning`\n")
    print(markdown(run(quick="--quick" in argv)))


if __name__ == "__main__":
    main(sys.argv[1:])
