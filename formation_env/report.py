"""The main job's report: paper reproduction, stability of every law, learned-vs-analytic table.

``write_report(out)`` writes ``out/REPORT.md`` and its figures. Every number in
it is computed by this run.
"""

from __future__ import annotations

import datetime as _dt
import platform
from pathlib import Path
from typing import Any

import numpy as np

from .core import LinearDynamics, Network, paper_example, paper_omega, stability_report
from .core.analysis import network_dt_max
from .core.network import levin_may_bound

__all__ = ["network_regions", "network_table", "plot_network_regions", "stability_table", "write_report"]

#: Delays (samples) and loss probabilities of the network figures.
NETWORK_DELAYS = tuple(range(11))
NETWORK_LOSSES = tuple(float(p) for p in np.round(np.linspace(0.0, 0.95, 20), 2))


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


def network_table() -> list[dict[str, Any]]:
    """The stationary law on the paper's exact stress at T = 1 s over one network per model."""
    fw = paper_example()
    om = paper_omega(exact=True)
    xl = fw.positions[list(fw.leaders)]
    cases = [
        ("delay 1, input", Network(delay=1, delayed="input")),
        ("delay 2, input", Network(delay=2, delayed="input")),
        ("delay 2, neighbours", Network(delay=2)),
        ("loss 0.3, hold", Network(loss=0.3)),
        ("loss 0.3, drop", Network(loss=0.3, loss_model="drop")),
        ("jitter [0.5, 1.2] s", Network(jitter=(0.5, 1.2))),
        ("jitter [0.5, 1.5] s", Network(jitter=(0.5, 1.5))),
        ("uniform quantiser 0.05 m", Network(quantise=("uniform", 0.05))),
        ("log quantiser rho = 0.95", Network(quantise=("log", 0.95))),
    ]
    rows = []
    for name, net in cases:
        rep = stability_report(om, fw.leaders, dt=1.0, network=net, x_leaders=xl)
        extra = []
        if rep.delay_max is not None:
            extra.append(f"largest stable delay {rep.delay_max}" + (" (search cap)" if rep.delay_max == 64 else ""))
        if rep.loss_max is not None:
            extra.append("stable for every p < 1" if rep.loss_max == 1.0 else f"stable for p < {rep.loss_max:.4f}")
        if rep.steady_error is not None:
            extra.append(f"stationary RMS error {rep.steady_error:.4g} m")
        if rep.ultimate_bound is not None:
            extra.append(f"limsup max abs(e) <= {rep.ultimate_bound:.4g} m")
        rows.append(
            {
                "network": name,
                "rho": rep.spectral_radius,
                "stable": rep.stable,
                "exact": rep.exact,
                "dt_max": rep.dt_max,
                "extra": "; ".join(extra),
            }
        )
    return rows


def network_regions() -> dict[str, Any]:
    """Largest stable T (s) of the stationary law on the paper's exact stress against delay and against loss."""
    fw = paper_example()
    om = paper_omega(exact=True)
    lam_max = float(np.linalg.eigvalsh(om[np.ix_(fw.followers, fw.followers)])[-1])
    out: dict[str, Any] = {"delays": list(NETWORK_DELAYS), "losses": list(NETWORK_LOSSES)}
    for mode in ("input", "neighbours"):
        out[f"delay_{mode}"] = [network_dt_max(om, fw.leaders, Network(delay=d, delayed=mode)) for d in NETWORK_DELAYS]
    out["levin_may"] = [levin_may_bound(d) / lam_max for d in NETWORK_DELAYS]
    for model in ("hold", "drop"):
        out[f"loss_{model}"] = [
            network_dt_max(om, fw.leaders, Network(loss=p, loss_model=model)) for p in NETWORK_LOSSES
        ]
    return out


def plot_network_regions(regions: dict[str, Any], out: Path) -> tuple[Path, Path]:
    """Two PNGs in ``out``: stable T against delay, stable T against loss (the regions below the curves)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    paths = (out / "networks_delay.png", out / "networks_loss.png")
    d = np.array(regions["delays"])
    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    ax.fill_between(d, 0, regions["delay_input"], step=None, color="tab:blue", alpha=0.15)
    ax.plot(d, regions["delay_neighbours"], "s-", color="tab:green", label='delayed="neighbours" (own x_i current)')
    ax.plot(d, regions["delay_input"], "o-", color="tab:blue", label='delayed="input" (companion matrix)')
    fine = np.linspace(0, d[-1], 200)
    lam_max = levin_may_bound(0) / regions["levin_may"][0]
    lm = [2 * np.sin(np.pi / (2 * (2 * x + 1))) / lam_max for x in fine]
    ax.plot(fine, lm, "k--", lw=1, label="Levin-May 2 sin(pi / (2(2d+1))) / (g lambda_max)")
    _save_region(fig, ax, "delay d (samples)", "largest stable T (s)", 1.6, paths[0])
    p = np.array(regions["losses"])
    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    for model, c in (("hold", "tab:blue"), ("drop", "tab:red")):
        ax.plot(p, regions[f"loss_{model}"], "o-", color=c, ms=4, label=f'loss_model="{model}" (mean square, exact)')
    ax.fill_between(p, 0, np.minimum(regions["loss_hold"], regions["loss_drop"]), color="0.5", alpha=0.12)
    _save_region(fig, ax, "loss probability p per link and sample", "largest mean-square stable T (s)", 1.7, paths[1])
    return paths


def _save_region(fig: Any, ax: Any, xlabel: str, ylabel: str, top: float, path: Path) -> None:
    """Label a stable-region figure of the paper example (T from 0 to ``top`` s, T = 1 dotted), save and close it."""
    import matplotlib.pyplot as plt

    ax.axhline(1.0, color="0.5", lw=0.8, ls=":")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title("paper example, stationary law: stable below each curve")
    ax.set_ylim(0, top)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


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
    bar = progress_bar(5, "report", progress, "part")
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
    bar.set_description_str("report: networks")
    lines += _network_section(out)
    bar.set_description_str("report: evaluation")
    try:
        from train.report_section import evaluation_section  # learned vs analytic
    except ImportError:
        lines.append("(learned-vs-analytic evaluation unavailable: the `agents` package is not installed)")
    else:
        lines += evaluation_section(out, quick=quick, progress=progress)
    bar.update()
    bar.update()
    bar.close()
    path = out / "REPORT.md"
    path.write_text("\n".join(lines) + "\n")
    return path


def _network_section(out: Path) -> list[str]:
    lines = [
        "## 3. Communication networks on the paper's framework",
        "",
        "The stationary law over an imperfect network (`stability_report(..., network=Network(...))`, "
        "docs/networks.md). rho: per-sample decay of the error (delays) or of its RMS over the random losses "
        "and periods, sqrt(rho(E[A kron A])). 'exact': the stability test is necessary and sufficient. "
        "Under jitter 'stable' means for every sequence of periods in the interval.",
        "",
        "| network at T = 1 s | rho | stable | exact | largest stable T (s) | more |",
        "|---|---|---|---|---|---|",
    ]
    for r in network_table():
        dtm = "-" if r["dt_max"] is None else f"{r['dt_max']:.4g}"
        lines.append(f"| {r['network']} | {r['rho']:.4g} | {r['stable']} | {r['exact']} | {dtm} | {r['extra']} |")
    regions = network_regions()
    fig_d, fig_l = plot_network_regions(regions, out)
    lines += [
        "",
        "Largest stable T against the delay (input delay: the companion-matrix radius, on the Levin-May curve) "
        "and against the loss probability (mean square):",
        "",
        "| d | " + " | ".join(str(d) for d in regions["delays"]) + " |",
        "|---|" + "---|" * len(regions["delays"]),
        '| delayed="input" | ' + " | ".join(f"{t:.4g}" for t in regions["delay_input"]) + " |",
        "| Levin-May | " + " | ".join(f"{t:.4g}" for t in regions["levin_may"]) + " |",
        '| delayed="neighbours" | ' + " | ".join(f"{t:.4g}" for t in regions["delay_neighbours"]) + " |",
        "",
        "| p | " + " | ".join(f"{p:g}" for p in regions["losses"]) + " |",
        "|---|" + "---|" * len(regions["losses"]),
        "| hold | " + " | ".join(f"{t:.4g}" for t in regions["loss_hold"]) + " |",
        "| drop | " + " | ".join(f"{t:.4g}" for t in regions["loss_drop"]) + " |",
        "",
        f"![stable T against delay]({fig_d.name}) ![stable T against loss]({fig_l.name})",
        "",
    ]
    return lines
