"""The leaderboard: every registered scenario, every entry, on that scenario's fixed seeded suite.

Entries (:data:`ENTRIES`): ``random`` (uniform actions, seeded), ``analytic`` (the scenario's tuned planner,
:mod:`agents.planner`), and the learned ones, ``ppo_commander`` (one policy on the global state, from
scratch), ``ppo_shared`` (decentralised leaders sharing one policy), ``sac_commander``, ``ppo_residual`` (a
learned correction on the planner: action = planner + scale policy, ``train.leaders --residual``) and
``ppo_commander_ttg`` (a second commander from scratch where ``ppo_commander``'s recipe is the quick one to train:
its reward's potential is the team's time to go and it trains longer). A learned entry is the policies
``<scenario>_<entry>_seed<k>.zip`` found in the policy folder (``agents/pretrained/`` by default), one per training
seed: its metrics are the mean over seeds of each seed's suite metrics, with the spread across seeds (min, max)
beside them. An entry with no shipped policy is listed as not trained.

Every entry of a scenario meets the same episodes (seeds ``seed .. seed + episodes - 1``). Beside the time
to goal stands ``time_lower_bound``: the mean over the same solved episodes of :mod:`agents.bounds`' lower
bound (over all episodes when none is solved); ``time_vs_analytic`` is the entry's time minus the planner's, paired
by episode over the episodes both solved (s; negative: faster than the planner), with each seed's 95 % interval in
the JSON (``time_vs_analytic_ci95``).

``formation-env leaderboard [--episodes N] [--seed S] [--json] [--out FOLDER]`` writes ``FOLDER/leaderboard.md``
(``out/leaderboard.md`` by default, like the other commands' ``--out``); ``--project`` writes the project's own
instead: ``docs/leaderboard.md`` and the results table of ``README.md`` in the source checkout. With ``--json`` it
prints ``{"scenarios": {scenario: {entry: {"kind", "metrics", ...}}}}``.
"""

from __future__ import annotations

import argparse
import json
import platform
import re
import time
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from agents.bounds import time_lower_bound_seeds
from agents.policy import POLICY_DIR, load_policy
from formation_env._progress import add_progress_argument, progress_bar
from formation_env.env.scenarios import REGISTRY

from .evaluate import _finite, make_engine, paired_difference
from .evaluate import evaluate as evaluate_suite

__all__ = [
    "ENTRIES", "LEARNED", "NETWORKS", "NETWORK_LAW", "NETWORK_TRAINED", "PROJECT_ROOT", "SHOWN", "SHOWN_TRACKING",
    "find_policies", "leaderboard", "main", "markdown", "robustness_markdown", "robustness_table", "shown",
    "write_project",
]  # fmt: skip

#: Learned entries: name -> (algo, mode).
LEARNED: dict[str, tuple[str, str]] = {
    "ppo_commander": ("ppo", "commander"),
    "ppo_shared": ("ppo", "shared"),
    "sac_commander": ("sac", "commander"),
    "ppo_residual": ("ppo", "commander"),
    "ppo_commander_ttg": ("ppo", "commander"),
}
#: Every entry, in table order.
ENTRIES: tuple[str, ...] = ("random", "analytic", *LEARNED)
#: Metrics of every entry's tables (``evaluate``'s, with the time bound and the paired time against the planner).
SHOWN = ("success_rate", "collision_rate", "time_to_goal", "time_vs_analytic", "time_lower_bound", "mean_formation_err")
#: The columns of a tracking scenario (judged at its last sample, not timed: ``maneuver``, ``maneuver_3d``), whose
#: agents start on the reference and succeed at once: how well they track, and the formation once formed.
SHOWN_TRACKING = ("success_rate", "collision_rate", "tracking_err", "mean_formation_err", "max_formation_err")
PRETRAINED = POLICY_DIR
#: The source checkout whose ``docs/leaderboard.md`` and ``README.md`` table ``--project`` rewrites.
PROJECT_ROOT = Path(__file__).resolve().parents[1]


#: Named conditions of the robustness view (``--network NAME``): the fields of a :class:`formation_env.core.Network`
#: (None: a perfect network). Periods are in s (the env's T is 0.1 s), the quantiser's step in m.
NETWORKS: dict[str, dict[str, Any] | None] = {
    "ideal": None,
    "delay2": {"delay": 2},
    "loss20": {"loss": 0.2},
    "jitter": {"jitter": [0.05, 0.15]},
    "quantise": {"quantise": ["uniform", 0.05]},
}
#: The followers' law under every condition of the robustness view: the env runs a network on the distributed stress
#: feedback only (``dynamic`` is a centralised solve), so ``ideal`` runs it too and the conditions differ by the
#: network alone.
NETWORK_LAW = "linear"
#: Entries of the robustness view only: commanders trained under a network condition, ``<scenario>_<entry>_seed<k>.zip``
#: (entry -> (algo, mode)).
NETWORK_TRAINED: dict[str, tuple[str, str]] = {"ppo_commander_loss20": ("ppo", "commander")}


def shown(scenario: str) -> tuple[str, ...]:
    """The metric columns of ``scenario``'s table: :data:`SHOWN`, or :data:`SHOWN_TRACKING` for a tracking task."""
    return SHOWN if REGISTRY[scenario].terminate_on_success else SHOWN_TRACKING


def find_policies(folder: str | Path, scenario: str, entry: str) -> list[Path]:
    """The shipped policies of a learned entry, ``<scenario>_<entry>_seed<k>.zip``, by seed."""
    pat = re.compile(rf"^{re.escape(scenario)}_{re.escape(entry)}_seed(\d+)\.zip$")
    found = [(int(m.group(1)), p) for p in Path(folder).glob("*.zip") if (m := pat.match(p.name))]
    return [p for _, p in sorted(found)]


def _suite_metrics(result: dict[str, Any], bound: np.ndarray, vs_analytic: float) -> dict[str, float]:
    """``evaluate``'s metrics with ``time_lower_bound`` and ``time_vs_analytic`` (``vs_analytic``, s)."""
    metrics = dict(result["metrics"])
    t = np.asarray(result["per_episode"]["time_to_goal"], dtype=np.float64)
    solved = np.isfinite(t)
    metrics["time_lower_bound"] = float(np.mean(bound[solved] if solved.any() else bound))
    metrics["time_vs_analytic"] = vs_analytic
    return metrics


def leaderboard(
    episodes: int = 100,
    seed: int = 0,
    policies: str | Path = PRETRAINED,
    scenarios: Sequence[str] | None = None,
    progress: bool | None = False,
    network: str | None = None,
) -> dict[str, Any]:
    """Evaluate every entry on every scenario's suite; the JSON contract ``{"scenarios": {...}}`` plus
    ``"episodes"``, ``"seed"``, ``"policies"`` and ``"network"``. ``progress``: a bar of the suites evaluated, on
    stderr (None: when stderr is a terminal). ``network``: a condition of :data:`NETWORKS`: every entry's followers
    run :data:`NETWORK_LAW` over that network (each learned policy with its own training arguments besides), and the
    entries of :data:`NETWORK_TRAINED` join the board."""
    if network is not None and network not in NETWORKS:
        raise ValueError(f"network must be one of {list(NETWORKS)}, got {network!r}")
    out: dict[str, Any] = {}
    scenarios = list(scenarios or sorted(REGISTRY))
    learned = dict(LEARNED) if network is None else {**LEARNED, **NETWORK_TRAINED}
    total = sum(2 + sum(len(find_policies(policies, sc, e)) for e in learned) for sc in scenarios)
    bar = progress_bar(total, "leaderboard", progress, "suite")

    def evaluate(spec: str, sc: str) -> dict[str, Any]:
        bar.set_description_str(f"{sc}: {Path(spec).stem}")
        if network is None:
            res = evaluate_suite(spec, sc, episodes, seed, gif=False, generalisation=False)
        else:
            policy = load_policy(spec, scenario=sc)
            kw = {**policy.env_kwargs, "follower_law": NETWORK_LAW, "network": NETWORKS[network]}
            res = evaluate_suite(policy, sc, episodes, seed, env_kwargs=kw, gif=False, generalisation=False)
        bar.update()
        return res

    for sc in scenarios:
        seeds = list(range(int(seed), int(seed) + int(episodes)))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            bound = time_lower_bound_seeds(make_engine(sc), seeds)
        rows: dict[str, Any] = {}
        base = {entry: evaluate(entry, sc) for entry in ("random", "analytic")}
        for entry, res in base.items():
            rows[entry] = {
                "kind": entry,
                "metrics": _suite_metrics(res, bound, paired_difference(base["analytic"], res)[0]),
                "ci95": res["ci95"],
                "worst": res["worst"],
            }
        for entry in learned:
            paths = find_policies(policies, sc, entry)
            if not paths:
                rows[entry] = {"kind": "learned", "metrics": None, "note": "no shipped policy"}
                continue
            results = [evaluate(str(p), sc) for p in paths]
            diffs = [paired_difference(base["analytic"], r) for r in results]  # (mean, lo, hi, n) per seed
            per_seed = [_suite_metrics(r, bound, d[0]) for r, d in zip(results, diffs, strict=True)]
            keys = per_seed[0].keys()
            mean = {k: float(np.nanmean([m[k] for m in per_seed])) if _any_finite(per_seed, k) else float("nan")
                    for k in keys}  # fmt: skip
            spread = {k: [float(np.nanmin([m[k] for m in per_seed])), float(np.nanmax([m[k] for m in per_seed]))]
                      if _any_finite(per_seed, k) else [float("nan")] * 2 for k in keys}  # fmt: skip
            rows[entry] = {
                "kind": "learned",
                "metrics": mean,
                "spread_across_seeds": spread,
                "per_seed": per_seed,
                "time_vs_analytic_ci95": [[d[1], d[2]] for d in diffs],
                "policies": [p.name for p in paths],
            }
        out[sc] = rows
    bar.close()
    return {"scenarios": out, "episodes": int(episodes), "seed": int(seed), "policies": str(policies),
            "network": network}  # fmt: skip


def _any_finite(rows: list[dict[str, float]], key: str) -> bool:
    return any(np.isfinite(m[key]) for m in rows)


def _cell(entry: dict[str, Any], key: str) -> str:
    m = entry.get("metrics")
    if m is None:
        return "-"
    v = m[key]
    txt = "-" if not np.isfinite(v) else f"{v:.3g}"
    spread = entry.get("spread_across_seeds")
    if spread is not None and np.isfinite(v) and len(entry.get("per_seed", [])) > 1:
        lo, hi = spread[key]
        txt += f" ({lo:.3g} to {hi:.3g})"
    return txt


def markdown(board: dict[str, Any], command: str) -> str:
    """docs/leaderboard.md: one table per scenario, how it was made, what the columns mean."""
    lines = [
        "# Leaderboard",
        "",
        f"Made by `{command}` on {time.strftime('%Y-%m-%d')} ({platform.machine()}, {platform.python_version()}). "
        f"{board['episodes']} episodes per scenario, seeds {board['seed']}..{board['seed'] + board['episodes'] - 1}; "
        "every entry meets the same episodes.",
        "",
        "Columns: success and collision rates over the suite; time to goal (s) over solved episodes; "
        "`time_vs_analytic`: that time minus the planner's, paired by episode over the episodes both solved (s; "
        "negative: faster); the lower bound on the time (s, `agents/bounds.py`: the leaders' travel under the "
        "input bound, obstacles ignored) over the solved episodes; mean formation error (m). Tracking scenarios "
        "(`maneuver`, `maneuver_3d`: the agents start on a moving reference and are judged at the last sample) show "
        "instead `tracking_err`: the largest distance of an agent to its reference position, averaged over the "
        "episode's samples (m), and `max_formation_err`: the largest formation error once the team has formed, "
        "from the first sample whose error is at most a tenth of the scenario's success tolerance (5 mm for the "
        "default 0.05 m), so that the followers' start noise is not counted (m). `ppo_residual`: a "
        "correction learned on top of the planner (action = planner + scale policy), not from scratch. "
        "`ppo_commander_ttg`: a second commander from scratch where `ppo_commander`'s recipe is the quick one to "
        "train: its reward's potential is the team's time to go and it trains longer (docs/learning.md). Learned "
        "entries: mean over training seeds, (min to max across seeds) beside it; `-`: not trained or no episode "
        "solved.",
        "",
    ]
    for sc, rows in board["scenarios"].items():
        cols = shown(sc)
        lines += [f"## {sc}", "", "| entry | " + " | ".join(cols) + " | seeds |", "|---" * (len(cols) + 2) + "|"]
        for entry, row in rows.items():
            n = len(row.get("per_seed", [])) if row["kind"] == "learned" else "-"
            n = n if row.get("metrics") is not None else "not trained"
            lines.append(f"| {entry} | " + " | ".join(_cell(row, k) for k in cols) + f" | {n} |")
        lines.append("")
    return "\n".join(lines)


def summary_table(board: dict[str, Any]) -> str:
    """The README's table: success rate and time to goal (s) of every entry on every scenario (tracking
    scenarios, judged at their last sample, show the success rate and the mean tracking error, m)."""
    lines = ["| scenario | " + " | ".join(ENTRIES) + " | time bound (s) |", "|---" * (len(ENTRIES) + 2) + "|"]
    for sc, rows in board["scenarios"].items():
        timed = REGISTRY[sc].terminate_on_success  # tracking tasks are judged at the last sample, not timed
        cells = []
        for e in ENTRIES:
            m = rows[e].get("metrics")
            if m is None:
                cells.append("-")
                continue
            if timed:
                t = m["time_to_goal"]
                cells.append(f"{m['success_rate']:.2f}" + (f" / {t:.1f} s" if np.isfinite(t) else ""))
            else:
                e = m["tracking_err"]
                cells.append(f"{m['success_rate']:.2f}" + (f" / {e:.3f} m" if np.isfinite(e) else ""))
        tb = f"{rows['analytic']['metrics']['time_lower_bound']:.1f}" if timed else "tracking"
        lines.append(f"| {sc} | " + " | ".join(cells) + f" | {tb} |")
    return "\n".join(lines)


ROBUSTNESS_HEADING = "## Over an imperfect network"
#: Entries of the README's robustness table.
ROBUST_SHOWN = ("analytic", "ppo_commander", "ppo_residual", *NETWORK_TRAINED)


def _robust_cell(row: dict[str, Any] | None, timed: bool) -> str:
    m = None if row is None else row.get("metrics")
    if m is None:
        return "-"
    last = m["time_to_goal"] if timed else m["tracking_err"]
    unit = " s" if timed else " m"
    tail = f" / {last:.3g}{unit}" if np.isfinite(last) else ""
    return f"{m['success_rate']:.2f} / {m['collision_rate']:.2f}{tail}"


def _describe_network(name: str) -> str:
    fields = NETWORKS[name]
    return "a perfect network" if fields is None else ", ".join(f"{k}={v}" for k, v in fields.items())


def robustness_markdown(boards: dict[str, dict[str, Any]], command: str) -> str:
    """The robustness section of docs/leaderboard.md: per scenario, every entry (rows) under every condition of
    ``boards`` (condition -> :func:`leaderboard` board, columns): success / collisions / time to goal (s), or the
    tracking error (m) on a tracking scenario."""
    names = list(boards)
    first = boards[names[0]]
    nets = "; ".join(f"`{n}`: {_describe_network(n)}" for n in names)
    lines = [
        ROBUSTNESS_HEADING,
        "",
        f"Made by `{command}` on {time.strftime('%Y-%m-%d')} ({platform.machine()}, {platform.python_version()}). "
        f"{first['episodes']} episodes per scenario, seeds {first['seed']}..{first['seed'] + first['episodes'] - 1}, "
        f"the same under every condition. Every condition, `ideal` included, runs the followers' distributed "
        f'stress feedback (`follower_law="{NETWORK_LAW}"`; the board above runs the centralised `dynamic` law, '
        "which a per-link network does not define), so the columns differ by the network alone. Conditions "
        f"(`formation_env.core.Network`, docs/networks.md): {nets}. Cells: success / collisions / time to goal (s) "
        "over solved episodes, or the tracking error (m) on a tracking scenario; learned entries are the mean over "
        "their training seeds. The planners are those of the board above, tuned for the `dynamic` law and not "
        "retuned for this one. `ppo_commander_loss20`: a commander trained from scratch under `loss20` with this law "
        "(docs/networks.md).",
        "",
    ]
    for sc in first["scenarios"]:
        timed = REGISTRY[sc].terminate_on_success
        rows = boards[names[0]]["scenarios"][sc]
        entries = [e for e in rows if any(b["scenarios"][sc][e].get("metrics") is not None for b in boards.values())]
        lines += [f"### {sc}", "", "| entry | " + " | ".join(names) + " |", "|---" * (len(names) + 1) + "|"]
        for e in entries:
            lines.append(f"| {e} | " + " | ".join(_robust_cell(boards[n]["scenarios"][sc].get(e), timed)
                                                   for n in names) + " |")  # fmt: skip
        lines.append("")
    return "\n".join(lines)


def robustness_table(boards: dict[str, dict[str, Any]]) -> str:
    """The README's robustness table: success / collisions (/ time to goal, s) of the planner and the learned
    commanders on every scenario under every condition."""
    names = list(boards)
    first = boards[names[0]]
    lines = ["| scenario | entry | " + " | ".join(names) + " |", "|---" * (len(names) + 2) + "|"]
    for sc in first["scenarios"]:
        timed = REGISTRY[sc].terminate_on_success
        for e in ROBUST_SHOWN:
            cells = [_robust_cell(boards[n]["scenarios"][sc].get(e), timed) for n in names]
            if all(c == "-" for c in cells):
                continue
            lines.append(f"| {sc} | {e} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _replace_table(lines: list[str], table: list[str], path: Path) -> list[str]:
    """``lines`` with the Markdown table whose header row is ``table[0]`` replaced by ``table``."""
    start = next((i for i, line in enumerate(lines) if line.rstrip("\n") == table[0]), None)
    if start is None:
        raise ValueError(f"{path} has no table to replace (no line {table[0]!r})")
    end = start
    while end < len(lines) and lines[end].startswith("|"):
        end += 1
    return lines[:start] + [line + "\n" for line in table] + lines[end:]


def write_project(board: dict[str, Any], page: str, root: str | Path | None = None) -> list[Path]:
    """The project's own leaderboard: ``page`` as ``docs/leaderboard.md`` and :func:`summary_table` in place of the
    results table of ``README.md`` (the lines from its header row to the first line not a table row). Returns the
    paths written. ``root``: the checkout (default :data:`PROJECT_ROOT`).

    Raises:
        FileNotFoundError: ``root`` is not a source checkout (no README.md or docs/ in it).
        ValueError: the README has no results table to replace.
    """
    root = Path(PROJECT_ROOT if root is None else root)
    readme, docs = root / "README.md", root / "docs"
    if not readme.is_file() or not docs.is_dir():
        raise FileNotFoundError(
            f"--project rewrites the source checkout's docs/leaderboard.md and README.md, and {root} is not one "
            "(no README.md or docs/ in it): run from a clone, or write elsewhere with --out"
        )
    robust = board.get("robustness")  # condition -> board: the robustness section and table instead
    table = (summary_table(board) if robust is None else robustness_table(robust)).splitlines()
    lines = _replace_table(readme.read_text().splitlines(keepends=True), table, readme)
    doc = docs / "leaderboard.md"
    old = doc.read_text() if doc.is_file() else ""
    head, _, tail = old.partition(ROBUSTNESS_HEADING)
    if robust is None:  # the standard board; the robustness section stays
        text = page.rstrip("\n") + ("\n\n" + ROBUSTNESS_HEADING + tail if tail else "\n")
    else:
        text = head.rstrip("\n") + "\n\n" + page.rstrip("\n") + "\n"
    doc.write_text(text)
    readme.write_text("".join(lines))
    return [doc, readme]


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="formation-env leaderboard", description=__doc__.splitlines()[0])
    add_arguments(p)
    return run_cli(p.parse_args(argv))


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The leaderboard's options (shared with ``formation-env leaderboard``)."""
    p.add_argument("--episodes", type=int, default=100, help="episodes per scenario suite")
    p.add_argument("--seed", type=int, default=0, help="first episode seed of every suite")
    p.add_argument("--json", action="store_true", help='print one JSON object {"scenarios": {...}}')
    p.add_argument("--policies", default=str(PRETRAINED), help="folder of the shipped learned policies")
    p.add_argument("--scenarios", nargs="*", default=None, choices=sorted(REGISTRY), help="default: every one")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--out", default=None, help="folder of the leaderboard.md written (default: out)")
    where.add_argument(
        "--project",
        action="store_true",
        help="write the project's own docs/leaderboard.md and README table (every scenario; a source checkout)",
    )
    p.add_argument(
        "--network", nargs="+", default=None, metavar="NAME", choices=[*NETWORKS, "all"],
        help=f"the robustness view: every entry under these network conditions ({', '.join(NETWORKS)}, or all); "
        "writes leaderboard_network.md (--project: the section of docs/leaderboard.md and the README's table)",
    )  # fmt: skip
    add_progress_argument(p)


def run_cli(args: argparse.Namespace) -> int:
    out = Path(args.out if args.out is not None else "out")
    if out.suffix == ".md":
        raise ValueError(f"--out is a folder (leaderboard.md is written inside it), got the file name {args.out!r}")
    if args.project and args.scenarios:
        raise ValueError("--project writes the whole table: it takes every scenario, drop --scenarios")
    if not Path(args.policies).is_dir():
        raise FileNotFoundError(
            f"--policies must be a folder of learned policies, got {args.policies} (no such folder)"
        )
    cmd = f"formation-env leaderboard --episodes {args.episodes} --seed {args.seed}"
    if args.network:
        names = list(NETWORKS) if "all" in args.network else list(dict.fromkeys(args.network))
        if args.project and names != list(NETWORKS):
            raise ValueError("--project writes the whole robustness table: pass --network all")
        cmd += " --network " + " ".join(args.network) + (" --project" if args.project else "")
        boards = {n: leaderboard(args.episodes, args.seed, args.policies, args.scenarios, args.progress, network=n)
                  for n in names}  # fmt: skip
        board: dict[str, Any] = {"robustness": boards}
        page, table, name = robustness_markdown(boards, cmd) + "\n", robustness_table(boards), "leaderboard_network.md"
    else:
        cmd += " --project" if args.project else ""
        board = leaderboard(args.episodes, args.seed, args.policies, args.scenarios, progress=args.progress)
        page = markdown(board, cmd) + "\n## Summary\n\n" + summary_table(board) + "\n"
        table, name = summary_table(board), "leaderboard.md"
    if args.project:
        written = write_project(board, page)
    else:
        out.mkdir(parents=True, exist_ok=True)
        written = [out / name]
        written[0].write_text(page)
    if args.json:
        print(json.dumps(_finite(board)))
    else:
        print(table)
        print("written to " + ", ".join(str(w) for w in written))
    return 0


if __name__ == "__main__":
    import sys

    sys.exit(main())
