"""The evaluation section of the main job's report: learned vs analytic on the standard suite.

:func:`evaluation_section` is called by :func:`formation_env.report.write_report`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from agents.policy import POLICY_DIR

__all__ = ["PRETRAINED", "STANDARD_SUITE", "evaluation_section"]

#: The committed pretrained commander policy for ``narrow_passage``.
PRETRAINED = POLICY_DIR / "narrow_passage_commander.zip"
#: The standard suite: scenario, episodes (full, quick), first seed.
STANDARD_SUITE: dict[str, Any] = {"scenario": "narrow_passage", "episodes": 100, "quick_episodes": 20, "seed": 0}


def evaluation_section(out: Path, quick: bool = False, progress: bool | None = False) -> list[str]:
    """Evaluate the analytic planner (and the pretrained policy, if present) on the standard suite.

    Writes CSV/JSON/markdown, histograms and GIFs under ``out / "evaluation"``; returns markdown lines.
    """
    from .evaluate import _fmt, evaluate, markdown_table, paired_difference, plot_episodes

    suite = STANDARD_SUITE
    n = suite["quick_episodes"] if quick else suite["episodes"]
    folder = Path(out) / "evaluation"
    folder.mkdir(parents=True, exist_ok=True)
    specs: list[str] = ["analytic"] + ([str(PRETRAINED)] if PRETRAINED.exists() else [])
    results = [
        evaluate(s, suite["scenario"], n, suite["seed"], out=folder, gif=True, generalisation=True, progress=progress)
        for s in specs
    ]
    fig = plot_episodes(results, folder / "comparison.png")
    lines = [
        "## Evaluation: learned vs analytic",
        "",
        f"Scenario `{suite['scenario']}`, {n} episodes with seeds {suite['seed']}..{suite['seed'] + n - 1} "
        "(paired: every policy meets the same episodes). Means over episodes with 95 % intervals (Wilson for "
        "rates, Student t for means; `max_formation_err` is each episode's largest formation error once the team "
        "has formed, from the first sample whose error is at most a tenth of the success tolerance, averaged over "
        "the episodes that formed; `min_clearance` each episode's smallest clearance, averaged); the worst "
        "episode's values stand in the last column. Time to goal in s over successful episodes.",
        "",
        *markdown_table(results),
        "",
    ]
    if len(results) == 2:
        m, lo, hi, k = paired_difference(results[0], results[1])
        ratio = results[1]["metrics"]["time_to_goal"] / results[0]["metrics"]["time_to_goal"]
        lines += [
            f"Paired time to goal, {results[1]['policy']} minus analytic, over the {k} episodes both solved: "
            f"{_fmt(m)} s [{_fmt(lo)}, {_fmt(hi)}]; ratio of means {_fmt(ratio)}.",
            "",
        ]
    if len(results) == 1:
        lines += ["No pretrained policy found (`agents/pretrained/narrow_passage_commander.zip`): analytic only.", ""]
    lines += ["Gap widths outside the training range [1.0, 1.6] m (same seeds):", ""]
    lines += ["| policy | suite | success_rate | collision_rate | time_to_goal |", "|---|---|---|---|---|"]
    for r in results:
        for name, m in r.get("generalisation", {}).items():
            lines.append(
                f"| {r['policy']} | {name} | {_fmt(m['success_rate'])} | {_fmt(m['collision_rate'])} "
                f"| {_fmt(m['time_to_goal'])} |"
            )
    rel = fig.relative_to(out) if fig.is_relative_to(out) else fig
    lines += ["", f"![per-episode distributions]({rel})", ""]
    for r in results:
        gif = folder / f"episode_{r['policy']}.gif"
        if gif.exists():
            lines.append(f"![typical episode, {r['policy']}]({gif.relative_to(out)})")
    lines.append("")
    return lines
