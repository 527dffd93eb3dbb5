"""Evaluation harness: a fixed seeded suite, episodes paired by seed across policies, metrics with CIs.

Episode i of a suite with base seed S is drawn with ``Engine.reset(np.random.default_rng(S + i), 1)``,
so every policy meets the same episodes (paired by seed). The episodes run batched through the pure
engine (one ``step`` for the whole suite); a policy acts on the batch through
:meth:`agents.policy.Policy.act_engine` (analytic planners read the engine state, learned commander
policies the commander observation), so the harness never cares which it runs.

Metrics (per episode, then means over the suite with 95 % confidence intervals: Wilson for rates, from
``scipy.stats.binomtest``, Student t for means; the worst episode's values are reported apart, under
``"worst"``):

==================  ==========================================================================
key                 meaning
==================  ==========================================================================
success_rate        the scenario's success (goal pose reached, formation error below tolerance)
collision_rate      any contact (agent-agent, wall, circle, world box) during the episode
time_to_goal        s, first success, over successful episodes
mean_formation_err  m, affine-image formation error averaged over the episode's samples
max_formation_err   m, largest formation error once the team has formed: from the first sample whose error is at
                    most a tenth of the scenario's success tolerance (``agents.rollout.FORMED_FRACTION``; 5 mm
                    for the default 0.05 m), so that the followers' start noise is not counted; over the
                    episodes that formed (``formed_time`` in ``per_episode``: when, s)
tracking_err        m, largest distance of an agent to its reference position (its goal at that sample),
                    averaged over the episode's samples: how well a moving reference is tracked (``maneuver``,
                    ``maneuver_3d``); on a fixed goal, how far from it the team spent the episode
min_clearance       m, smallest clearance to obstacles/agents (negative: contact)
control_effort      sum over samples and leaders of |u|^2 dt  (u in m/s^2 for double integrators)
==================  ==========================================================================

``python -m train.evaluate --policy analytic --scenario narrow_passage --episodes 100 --seed 0 --json``
(also ``formation-env evaluate``) prints ``{"metrics": {...}}``.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from agents.rollout import ENDINGS, reset_paired, run_batch
from formation_env._progress import add_progress_argument, progress_bar
from formation_env.env.engine import Engine

from .recipes import json_object

__all__ = ["METRIC_KEYS", "evaluate", "mean_ci", "paired_difference", "reset_paired", "run_batch", "wilson"]

Array = NDArray[np.float64]

#: The keys of ``evaluate(...)["metrics"]`` (the JSON contract).
METRIC_KEYS: tuple[str, ...] = (
    "success_rate",
    "collision_rate",
    "time_to_goal",
    "mean_formation_err",
    "max_formation_err",
    "tracking_err",
    "min_clearance",
    "control_effort",
)

#: Gap widths (m) of the generalisation check: training range is [1.0, 1.6].
GAP_SUITES: dict[str, tuple[float, float]] = {
    "train_range": (1.0, 1.6),
    "narrow_0.8-1.0": (0.8, 1.0),
    "wide_1.6-2.0": (1.6, 2.0),
}


def wilson(k: int, n: int, confidence: float = 0.95) -> tuple[float, float]:
    """Wilson score interval of a rate k / n (``scipy.stats.binomtest(k, n).proportion_ci``)."""
    from scipy import stats

    if n == 0:
        return (float("nan"), float("nan"))
    ci = stats.binomtest(int(k), int(n)).proportion_ci(confidence_level=confidence, method="wilson")
    return (float(ci.low), float(ci.high))


def mean_ci(x: Array) -> tuple[float, float, float]:
    """Mean and Student-t 95 % interval of the finite entries of x (nan when empty)."""
    from scipy import stats

    x = np.asarray(x, dtype=np.float64)
    x = x[np.isfinite(x)]
    if x.size == 0:
        return (float("nan"), float("nan"), float("nan"))
    m = float(x.mean())
    if x.size < 2:
        return (m, m, m)
    h = float(stats.t.ppf(0.975, x.size - 1) * x.std(ddof=1) / math.sqrt(x.size))
    return (m, m - h, m + h)


def paired_difference(
    a: dict[str, Any], b: dict[str, Any], key: str = "time_to_goal"
) -> tuple[float, float, float, int]:
    """Mean, 95 % t interval and count of b - a over the episodes (same seeds) where both are finite."""
    if a["seeds"] != b["seeds"]:
        raise ValueError(f"results are not paired: seeds {a['seeds']} vs {b['seeds']}")
    x = np.asarray(a["per_episode"][key], dtype=np.float64)
    y = np.asarray(b["per_episode"][key], dtype=np.float64)
    diff = y - x
    m, lo, hi = mean_ci(diff)
    return m, lo, hi, int(np.isfinite(diff).sum())


def summarise(res: dict[str, Any]) -> tuple[dict[str, float], dict[str, list[float]], dict[str, float]]:
    """Metrics (the contract keys, means over episodes), their 95 % intervals, and the worst episodes' values.

    Every metric is a mean over the suite's episodes (``time_to_goal`` over successful ones) with its
    interval; ``max_formation_err`` is the mean of each episode's largest error once formed (over the episodes
    that formed) and ``min_clearance`` the mean of each episode's smallest clearance. The worst episode is reported
    on its own (``worst``): the largest ``max_formation_err`` and ``tracking_err``, the smallest ``min_clearance``
    and the longest ``time_to_goal``.
    """
    n = int(res["success"].size)
    metrics: dict[str, float] = {}
    cis: dict[str, list[float]] = {}
    for key, src in (("success_rate", "success"), ("collision_rate", "collision")):
        k = int(res[src].sum())
        metrics[key] = k / n
        cis[key] = list(wilson(k, n))
    for key in ("time_to_goal", "mean_formation_err", "max_formation_err", "tracking_err", "min_clearance",
                "control_effort"):  # fmt: skip
        m, lo, hi = mean_ci(res[key])
        metrics[key], cis[key] = m, [lo, hi]
    ttg = np.asarray(res["time_to_goal"], dtype=np.float64)
    emax = np.asarray(res["max_formation_err"], dtype=np.float64)
    worst = {
        "max_formation_err": float(np.max(emax[np.isfinite(emax)])) if np.isfinite(emax).any() else float("nan"),
        "tracking_err": float(np.max(res["tracking_err"])),
        "min_clearance": float(np.min(res["min_clearance"])),
        "time_to_goal": float(np.max(ttg[np.isfinite(ttg)])) if np.isfinite(ttg).any() else float("nan"),
    }
    return metrics, cis, worst


def make_engine(scenario: str, env_kwargs: dict[str, Any] | None = None) -> Engine:
    """The evaluation engine (the env's defaults: double integrators, ``dynamic`` law, dt 0.1 s, 400 samples)."""
    return Engine(scenario, **(env_kwargs or {}))


def gap_engine(gap_width: tuple[float, float], env_kwargs: dict[str, Any] | None = None) -> Engine:
    """A ``narrow_passage`` engine whose gap widths are drawn from ``gap_width`` (m)."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return make_engine("narrow_passage", {**(env_kwargs or {}), "gap_width": gap_width})


def evaluate(
    policy_spec: str | Any,
    scenario: str | None = None,
    episodes: int = 100,
    seed: int = 0,
    *,
    env_kwargs: dict[str, Any] | None = None,
    out: str | Path | None = None,
    gif: bool = True,
    generalisation: bool = True,
    progress: bool | None = False,
) -> dict[str, Any]:
    """Evaluate a policy on the seeded suite ``seed .. seed + episodes - 1`` of ``scenario``.

    Args:
        policy_spec: ``"analytic"``, ``"random"``, a path to a saved SB3 model (.zip), an RLlib checkpoint folder
            (``python -m train.rllib``'s ``--out`` or its ``checkpoint/``), or a :class:`agents.policy.Policy`
            (resolved by :func:`agents.policy.load_policy`).
        scenario: a scenario name; None: the policy's (a saved policy's training scenario, else ``narrow_passage``).
        env_kwargs: engine arguments (scenario keyword arguments included); None: the policy's (a saved policy's
            training values of :data:`agents.policy.POLICY_ENV_KWARGS`, else none).
        out: folder for ``episodes.csv``, ``metrics.json``, ``metrics.md``, plots and a GIF (None: nothing written).
        generalisation: for ``narrow_passage``, also evaluate gap widths outside the training range.
        progress: a progress bar of the suite's steps on stderr (None: when stderr is a terminal).
    Returns:
        ``{"metrics": {METRIC_KEYS...}, "ci95": {...}, "worst": {...}, "episodes": n, "seeds": [...], "policy": name,
        "scenario": ..., "per_episode": {...}, "endings": {ending: episodes} (``agents.rollout.ENDINGS``),
        "generalisation": {suite: metrics}}``.
    """
    from agents.policy import Policy, load_policy

    if isinstance(policy_spec, Policy):  # made by the caller: its scenario and arguments unless given
        policy = policy_spec
        scenario = policy.scenario if scenario is None else scenario
        env_kwargs = policy.env_kwargs if env_kwargs is None else env_kwargs
        engine = make_engine(scenario, env_kwargs)
    else:
        policy = load_policy(policy_spec, scenario=scenario, env_kwargs=env_kwargs)
        engine, scenario, env_kwargs = policy.engine, policy.scenario, policy.env_kwargs
    seeds = list(range(int(seed), int(seed) + int(episodes)))
    gen_suites = (
        [n for n in GAP_SUITES if n != "train_range"] if generalisation and scenario == "narrow_passage" else []
    )
    bar = progress_bar((1 + len(gen_suites)) * engine.max_cycles, f"{policy.name} on {scenario}", progress, "step")

    def run(eng: Engine) -> dict[str, Any]:
        start = bar.n
        out = run_batch(eng, policy.act_engine, seeds, on_step=bar.update)
        bar.update(start + eng.max_cycles - bar.n)  # a suite whose episodes all ended early counts in full
        return out

    res = run(engine)
    metrics, cis, worst = summarise(res)
    result: dict[str, Any] = {
        "metrics": metrics,
        "ci95": cis,
        "worst": worst,
        "episodes": len(seeds),
        "seeds": [seeds[0], seeds[-1]],
        "policy": policy.name,
        "scenario": scenario,
        "per_episode": {k: np.asarray(v).tolist() for k, v in res.items() if k != "frames"},
        "endings": {e: int(np.sum(res["ending"] == e)) for e in ENDINGS},
    }
    if gen_suites:
        result["generalisation"] = {name: summarise(run(gap_engine(GAP_SUITES[name], env_kwargs)))[0]
                                    for name in gen_suites}  # fmt: skip
    bar.close()
    if out is not None:
        write_outputs(result, engine, policy, seeds, Path(out), gif=gif)
    return result


def _finite(x: Any) -> Any:
    """``x`` with NaN and inf floats replaced by None (strict JSON)."""
    if isinstance(x, dict):
        return {k: _finite(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_finite(v) for v in x]
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


def _fmt(v: float) -> str:
    return "nan" if not np.isfinite(v) else f"{v:.3g}"


def markdown_table(results: Sequence[dict[str, Any]]) -> list[str]:
    """A markdown table of metrics (means with 95 % intervals) and the worst episode's values, a row per result."""
    head = "| policy | " + " | ".join(METRIC_KEYS) + " | worst episode |"
    lines = [head, "|" + "---|" * (len(METRIC_KEYS) + 2)]
    for r in results:
        cells = []
        for k in METRIC_KEYS:
            lo, hi = r["ci95"][k]
            cells.append(f"{_fmt(r['metrics'][k])} [{_fmt(lo)}, {_fmt(hi)}]")
        w = r.get("worst", {})
        cells.append(", ".join(f"{k} {_fmt(v)}" for k, v in w.items()))
        lines.append(f"| {r['policy']} | " + " | ".join(cells) + " |")
    return lines


def write_outputs(
    result: dict[str, Any], engine: Engine, policy: Any, seeds: Sequence[int], out: Path, gif: bool = True
) -> None:
    """episodes.csv, metrics.json, metrics.md, a histogram plot and a GIF of a typical episode."""
    import csv

    out.mkdir(parents=True, exist_ok=True)
    tag = policy.name.replace("/", "_")
    pe = result["per_episode"]
    with open(out / f"episodes_{tag}.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        keys = list(pe)
        w.writerow(["seed", *keys])
        for i, s in enumerate(seeds):
            w.writerow([s, *[pe[k][i] for k in keys]])
    (out / f"metrics_{tag}.json").write_text(
        json.dumps(_finite({k: v for k, v in result.items() if k != "per_episode"}), indent=2)
    )
    lines = markdown_table([result])
    if "generalisation" in result:
        lines += ["", "Gap widths outside the training range [1.0, 1.6] m:", ""]
        lines += ["| suite | success_rate | collision_rate | time_to_goal |", "|---|---|---|---|"]
        for name, m in result["generalisation"].items():
            lines.append(
                f"| {name} | {_fmt(m['success_rate'])} | {_fmt(m['collision_rate'])} | {_fmt(m['time_to_goal'])} |"
            )
    (out / f"metrics_{tag}.md").write_text("\n".join(lines) + "\n")
    plot_episodes([result], out / f"episodes_{tag}.png")
    if gif:
        save_gif(engine, policy, seeds, result, out / f"episode_{tag}.gif")


def plot_episodes(results: Sequence[dict[str, Any]], path: Path) -> Path:
    """Histograms of time to goal and min clearance, one colour per policy."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(12, 3.2))
    for r in results:
        pe = r["per_episode"]
        for ax, key, unit in zip(
            axes, ("time_to_goal", "min_clearance", "mean_formation_err"), ("s", "m", "m"), strict=True
        ):
            x = np.asarray(pe[key], dtype=np.float64)
            x = x[np.isfinite(x)]
            if x.size:
                ax.hist(x, bins=20, alpha=0.6, label=r["policy"])
            ax.set_xlabel(f"{key} ({unit})")
    axes[0].set_ylabel("episodes")
    if axes[0].get_legend_handles_labels()[0]:
        axes[0].legend()
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def save_gif(engine: Engine, policy: Any, seeds: Sequence[int], result: dict[str, Any], path: Path) -> Path | None:
    """GIF of a typical episode: the successful one whose time to goal is nearest the median (else the first)."""
    from formation_env.env.rendering import Renderer
    from formation_env.env.video import save_animation

    t = np.asarray(result["per_episode"]["time_to_goal"], dtype=np.float64)
    ok = np.isfinite(t)
    idx = int(np.argmin(np.where(ok, np.abs(t - np.nanmedian(t)), np.inf))) if ok.any() else 0
    res = run_batch(engine, policy.act_engine, [seeds[idx]], record=0)
    try:
        rend = Renderer(engine.d, "rgb_array", width=400, height=300)
        rend.set_bounds(engine.bounds)
        images = [rend.draw(f) for f in res["frames"][::2]]
        rend.close()
    except Exception as exc:  # rendering needs pygame; never fail an evaluation on it
        print(f"GIF skipped: {exc}", file=sys.stderr)
        return None
    return save_animation([im for im in images if im is not None], path, fps=10)


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The evaluation options (shared by ``python -m train.evaluate`` and ``formation-env evaluate``)."""
    from formation_env.env.scenarios import REGISTRY

    p.add_argument(
        "--policy",
        default="analytic",
        help="analytic, random, a saved SB3 model's .zip path, or an RLlib checkpoint folder (train.rllib --out)",
    )
    p.add_argument(
        "--scenario", default=None, choices=sorted(REGISTRY),
        help="default: a saved policy's training scenario, else narrow_passage",
    )  # fmt: skip
    p.add_argument("--episodes", type=int, default=100, help="episodes of the suite")
    p.add_argument("--seed", type=int, default=0, help="first episode seed of the suite")
    p.add_argument("--json", action="store_true", help='print one JSON object {"metrics": {...}}')
    p.add_argument("--out", default=None, help="folder for CSV/JSON/markdown, plots and a GIF")
    p.add_argument("--env-kwargs", default="", help="JSON dict of engine arguments")
    add_progress_argument(p)


def run_cli(args: argparse.Namespace) -> int:
    """Run an evaluation from parsed arguments; print JSON or a table."""
    kw = json_object("--env-kwargs", getattr(args, "env_kwargs", "")) or None
    res = evaluate(
        args.policy, args.scenario, args.episodes, args.seed, env_kwargs=kw, out=args.out, progress=args.progress
    )
    if args.json:
        blob = {
            "scenario": res["scenario"],
            "metrics": res["metrics"],
            "ci95": res["ci95"],
            "worst": res["worst"],
            "endings": res["endings"],
            "generalisation": res.get("generalisation"),
        }
        print(json.dumps(_finite(blob)))
    else:
        print("\n".join(markdown_table([res])))
        print("endings: " + ", ".join(f"{e} {k}" for e, k in res["endings"].items()))
        for name, m in res.get("generalisation", {}).items():
            print(f"{name}: " + ", ".join(f"{k}={_fmt(v)}" for k, v in m.items()))
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m train.evaluate", description=__doc__.splitlines()[0])
    add_arguments(p)
    return run_cli(p.parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
