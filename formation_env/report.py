"""The main job's report: paper reproduction, stability of every law, learned-vs-analytic table.

``write_report(out)`` writes ``out/REPORT.md`` and its figures. Every number in
it is computed by this run.
"""

from __future__ import annotations

import datetime as _dt
import platform
from pathlib import Path
from typing import Any

from .core import LinearDynamics, paper_example, paper_omega, stability_report

__all__ = ["stability_table", "write_report"]


def stability_table() -> list[dict[str, Any]]:
    """Each law on the paper's (exact) stress at T = 1 s and 0.1 s: spectral radius and admissible range."""
    fw = paper_example()
    om = paper_omega(exact=True)
    rows = []
    cases: list[tuple[str, str, dict[str, Any]]] = [
        ("stationary", "single", {}),
        ("dynamic", "single", {}),
        ("dynamic_distributed", "single", {"rounds": 1}),
        ("dynamic_distributed", "single", {"rounds": 5}),
        ("linear", "double", {}),
        ("dynamic", "double", {}),
        ("linear_paper", "double", {}),
    ]
    for law, dyn_name, params in cases:
        dyn = LinearDynamics.single_integrator(2) if dyn_name == "single" else LinearDynamics.double_integrator(2)
        for dt in (1.0, 0.1):
            rep = stability_report(om, fw.leaders, dt=dt, law=law, dynamics=dyn, **params)
            rng = rep.dt_range if rep.dt_range is not None else rep.eps_range
            rows.append(
                {
                    "law": law + (f" (m={params['rounds']})" if "rounds" in params else ""),
                    "agents": f"{dyn_name} integrator",
                    "T": dt,
                    "rho": rep.spectral_radius,
                    "stable": rep.stable,
                    "range": ("T" if rep.dt_range is not None else "eps", rng),
                    "steps_to_1e-6": rep.steps_to_1e6,
                }
            )
    return rows


def _fmt_range(kind_rng: tuple[str, Any]) -> str:
    kind, rng = kind_rng
    if rng is None:
        return "-"
    lo, hi = rng
    return f"{kind} in ({lo:.4g}, {hi:.4g})"


def write_report(out: Path, quick: bool = False, progress: bool | None = False) -> Path:
    """Write ``out/REPORT.md`` with figures beside it; returns its path. ``progress``: a bar of the report's
    parts (and of each evaluation's steps) on stderr (None: when stderr is a terminal)."""
    from ._progress import progress_bar
    from .reproduce import plot_reproduction, reproduce_paper

    out.mkdir(parents=True, exist_ok=True)
    bar = progress_bar(4, "report", progress, "part")
    bar.set_description_str("report: paper reproduction")
    lines = [
        "# formation-env report",
        "",
        f"Generated {_dt.datetime.now(_dt.timezone.utc):%Y-%m-%d %H:%M} UTC on {platform.machine()} "
        f"({platform.python_implementation()} {platform.python_version()}) by `formation-env report`.",
        "",
        "## 1. Paper reproduction (Section 4.3)",
        "",
    ]
    for printed in (True, False):
        s = reproduce_paper(printed=printed)
        fig = plot_reproduction(s, out / ("reproduction.png" if printed else "reproduction_exact.png"))
        lines += [
            f"**Stress: {s['stress']}.** mu_min = {s['mu_min']} (paper: -1.49); T mu_min = {s['T_mu_min']} > -2; "
            f"Theorem 1 bound T < {s['theorem1_bound_T_max']} s.",
            "",
            "| quantity | paper | measured |",
            "|---|---|---|",
            f"| follower 4 after 180 s | (-1, 0) | {tuple(s['followers_final'][0])} |",
            f"| follower 5 after 180 s | (-2, 0) | {tuple(s['followers_final'][1])} |",
            f"| error decay per step | - | predicted {s['predicted_decay_per_step']}, "
            f"measured {s['measured_decay_per_step']} |",
            f"| after {s['maneuver']} | followers follow | {s['followers_after_maneuver']} "
            f"(targets {s['scaled_targets']}) |",
            "",
            f"Reproduced: **{s['reproduced']}**. ![reproduction]({fig.name})",
            "",
        ]
        bar.update()
    bar.set_description_str("report: stability")
    lines += [
        "## 2. Stability of every law on the paper's framework",
        "",
        "Spectral radius rho of the closed-loop error dynamics (the error shrinks by rho per sample) and the "
        "admissible range of T (or eps), from `stability_report`. `linear_paper` is the paper's literal eq. 25: "
        "even where it is Schur it settles away from the formation (see tests).",
        "",
        "| law | agents | T (s) | rho | stable | admissible | steps to 1e-6 |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in stability_table():
        lines.append(
            f"| {r['law']} | {r['agents']} | {r['T']:g} | {r['rho']:.4g} | {r['stable']} | "
            f"{_fmt_range(r['range'])} | {r['steps_to_1e-6']:.4g} |"
        )
    lines.append("")
    bar.update()
    bar.set_description_str("report: evaluation")
    try:
        from train.report_section import evaluation_section  # learned vs analytic
    except ImportError:
        lines.append("(learned-vs-analytic evaluation unavailable: the `agents` package is not installed)")
    else:
        lines += evaluation_section(out, quick=quick, progress=progress)
    bar.update()
    bar.close()
    path = out / "REPORT.md"
    path.write_text("\n".join(lines) + "\n")
    return path
