"""Core step time: one sample of the follower laws for n = 5, 100 and 10,000 agents.

n = 5 is the paper's example (dense stress); n = 100 and 10,000 are trilateration
frameworks with the constructive sparse stress (n = 100 also dense). The step is
``FollowerLaw.step`` (all agents, single integrators, 2D), the same function the env uses.
"""

from __future__ import annotations

import functools
import time

import numpy as np

from formation_env.core import LinearDynamics, Partition, make_law, paper_example, paper_omega

from .timing import summary, time_call

TITLE = "Core step time (one sample, all agents, 2D single integrators)"


def _system(n: int, sparse: bool) -> tuple[object, list[int], float]:
    if n == 5:
        fw = paper_example()
        return paper_omega(), list(fw.leaders), 0.0
    from formation_env.core.design import design_stress
    from formation_env.core.frameworks import trilateration

    fw = trilateration(n, 2, seed=0)
    t0 = time.perf_counter()
    om = design_stress(fw, "constructive")
    build = time.perf_counter() - t0
    if not sparse:
        om = om.toarray()
    return om, list(fw.leaders), build


def run(quick: bool = False) -> list[dict]:
    rows = []
    dyn = LinearDynamics.single_integrator(2)
    cases = [(5, False), (100, False), (100, True), (10_000, True)]
    for n, sparse in cases:
        try:
            omega, leaders, build = _system(n, sparse)
        except Exception as exc:  # design_stress / trilateration absent or failing: report, go on
            why = f"{type(exc).__name__}: {str(exc)[:200]}"
            rows.append({"n": n, "stress": "sparse" if sparse else "dense", "skipped": why})
            continue
        part = Partition(omega, leaders)
        rng = np.random.default_rng(0)
        x = rng.normal(size=(n, 2))
        u_l = np.zeros((part.n_l, 2))
        for law, params in (("stationary", {"gain": 0.1}), ("dynamic", {"gain": 1.0})):
            lw = make_law(law, part, dyn, 0.1, **params)
            mem = lw.initial_memory()
            lw.step(x, u_l, mem)  # warm the factorisation
            number = 2000 if n <= 100 else 50
            fn = functools.partial(lw.step, x, u_l, mem)
            med, lo, hi = summary(time_call(fn, number, 3 if quick else 7))
            rows.append(
                {
                    "n": n,
                    "stress": "sparse" if sparse else "dense",
                    "law": law,
                    "step_us": med * 1e6,
                    "min_us": lo * 1e6,
                    "max_us": hi * 1e6,
                    "design_s": build,
                }
            )
    return rows


def markdown(rows: list[dict]) -> str:
    out = ["| n | stress | law | step median (µs) | min-max (µs) |", "|---|---|---|---|---|"]
    for r in rows:
        if "skipped" in r:
            out.append(f"| {r['n']:,} | {r['stress']} | all | skipped: {r['skipped']} | |")
            continue
        out.append(
            f"| {r['n']:,} | {r['stress']} | {r['law']} | {r['step_us']:.1f} | {r['min_us']:.1f}-{r['max_us']:.1f} |"
        )
    return "\n".join(out)


if __name__ == "__main__":
    print(markdown(run()))
