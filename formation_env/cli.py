"""The ``formation-env`` command line: reproduce, report, and the env / training tools."""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from ._progress import add_progress_argument


def _jsonable(summary: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in summary.items() if not k.startswith("_")}


def cmd_reproduce(args: argparse.Namespace) -> int:
    """Run the paper's example, write the figure, print a summary (or JSON)."""
    from .reproduce import plot_reproduction, reproduce_paper

    summary = reproduce_paper(printed=not args.exact)
    fig = plot_reproduction(summary, Path(args.out) / "reproduction.png")
    summary["figure"] = str(fig)
    if args.json:
        print(json.dumps(_jsonable(summary), indent=2))
    else:
        s = summary
        print("Paper reproduction (Section 4.3): 5 agents, law 1 (eq. 19), T = 1 s, 180 s")
        print(f"  stress matrix: {s['stress']}")
        print(f"  mu_min = {s['mu_min']} (paper: -1.49), T*mu_min = {s['T_mu_min']} > -2: stable = {s['stable']}")
        print(f"  Theorem 1 bound: T < {s['theorem1_bound_T_max']} s")
        print(f"  followers reach {s['followers_final']} (paper: {s['paper_followers_final']})")
        print(
            f"  error decay per step: predicted {s['predicted_decay_per_step']}, "
            f"measured {s['measured_decay_per_step']}"
        )
        print(f"  {s['maneuver']}: followers at {s['followers_after_maneuver']} (targets {s['scaled_targets']})")
        print(f"  reproduced: {s['reproduced']}; figure: {fig}")
    return 0 if summary["reproduced"] else 1


def cmd_report(args: argparse.Namespace) -> int:
    """The main job: paper reproduction and whatever evaluation results exist, as markdown + figures."""
    from .report import write_report

    path = write_report(Path(args.out), quick=args.quick, progress=args.progress)
    print(Path(path).read_text())
    print(f"report written to {path}")
    return 0


def cmd_bench(args: argparse.Namespace) -> int:
    """Run the benchmark suite (benchmarks/) and write BENCHMARKS.md into the ``--out`` folder; with ``--train``,
    the training benchmark instead (``benchmarks.train_bench``: train_bench.md and .json)."""
    if args.train:
        if args.only:
            raise ValueError("bench --train runs the training benchmark alone: drop --only")
        from benchmarks.train_bench import main as train_bench_main

        return train_bench_main(["--out", args.out] + (["--quick"] if args.quick else []))
    from benchmarks.__main__ import main as bench_main

    argv = ["--out", args.out] + (["--quick"] if args.quick else []) + (["--only", *args.only] if args.only else [])
    if args.progress is not None:
        argv.append("--progress" if args.progress else "--no-progress")
    return bench_main(argv)


def cmd_rollout(args: argparse.Namespace) -> int:
    """Roll out one episode of a scenario and save it as a GIF or MP4."""
    import numpy as np

    from train.recipes import json_object

    from . import formation_v0
    from .env.video import save_animation

    kwargs = json_object("--env-kwargs", args.env_kwargs)
    env = formation_v0.parallel_env(scenario=args.scenario, render_mode="rgb_array", **kwargs)
    obs, _ = env.reset(seed=args.seed)
    policy = None
    if args.policy != "random":
        from agents import load_policy

        policy = load_policy(args.policy, env)
    rng = np.random.default_rng(args.seed)
    frames: list[Any] = [env.render()]
    info: dict[str, Any] = {}
    for _ in range(args.steps):
        if not env.agents:
            break
        if policy is None:
            actions = {a: rng.uniform(-1, 1, env.action_space(a).shape).astype(np.float32) for a in env.agents}
        else:
            actions = policy.act_parallel(obs, env)
        obs, _, _, _, infos = env.step(actions)
        info = next(iter(infos.values()), info)
        frames.append(env.render())
    env.close()
    path = save_animation(frames, args.out, fps=args.fps)
    print(f"wrote {path} ({len(frames)} frames); last info: {info}")
    return 0


def cmd_evaluate(args: argparse.Namespace) -> int:
    """Evaluate a policy (analytic or a saved model) on a seeded suite; metrics with 95 % intervals."""
    from train.evaluate import run_cli

    return run_cli(args)


def cmd_train(args: argparse.Namespace) -> int:
    """Train leader policies with SB3: ``python -m train.leaders`` with the same flags (``formation-env train -h``)."""
    from train.leaders import main as train_main

    return train_main(args.train_args, prog="formation-env train")


def cmd_leaderboard(args: argparse.Namespace) -> int:
    """Every entry (random, analytic, learned) on every scenario's seeded suite; writes ``--out``/leaderboard.md
    (``--project``: the project's own docs/leaderboard.md and README table)."""
    from train.leaderboard import run_cli

    return run_cli(args)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="formation-env", description=__doc__)
    parser.add_argument("--debug", action="store_true", help="show the full traceback of an error")
    sub = parser.add_subparsers(dest="command", required=True)
    fmt = argparse.ArgumentDefaultsHelpFormatter
    p = sub.add_parser("reproduce", formatter_class=fmt, help="reproduce the paper's 5-agent example")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.add_argument("--exact", action="store_true", help="use the projected exact stress instead of the printed one")
    p.add_argument("--out", default="out", help="folder for the figure (default: out)")
    p.set_defaults(func=cmd_reproduce)
    p = sub.add_parser(
        "report", formatter_class=fmt, help="the main job: reproduction and evaluation report (markdown + figures)"
    )
    p.add_argument("--out", default="out", help="output folder (default: out)")
    p.add_argument("--quick", action="store_true", help="fewer evaluation episodes")
    add_progress_argument(p)
    p.set_defaults(func=cmd_report)
    p = sub.add_parser("rollout", formatter_class=fmt, help="render one episode to a GIF or MP4")
    from .env.scenarios import REGISTRY

    p.add_argument("--scenario", default="narrow_passage", choices=sorted(REGISTRY))
    p.add_argument("--policy", default="random", help="random, analytic, or a saved model's path")
    p.add_argument("--steps", type=int, default=400)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--fps", type=int, default=20)
    p.add_argument("--env-kwargs", default="", help='JSON dict of env arguments, e.g. {"dt": 0.05}')
    p.add_argument("--out", default="out/rollout.gif", help="output .gif or .mp4")
    p.set_defaults(func=cmd_rollout)
    what = "evaluate a policy on a seeded suite (success, collisions, time to goal)"
    p = sub.add_parser("evaluate", formatter_class=fmt, help=what)
    from train.evaluate import add_arguments

    add_arguments(p)
    p.set_defaults(func=cmd_evaluate)
    # the flags are train.leaders' own (one parser): everything after `train` goes to it, -h included
    p = sub.add_parser("train", add_help=False, help="train leader policies with SB3 (python -m train.leaders)")
    p.set_defaults(func=cmd_train, train_args=[])
    p = sub.add_parser(
        "leaderboard", formatter_class=fmt, help="every policy on every scenario's suite (out/leaderboard.md)"
    )
    from train.leaderboard import add_arguments as leaderboard_arguments

    leaderboard_arguments(p)
    p.set_defaults(func=cmd_leaderboard)
    p = sub.add_parser("bench", formatter_class=fmt, help="run the benchmarks and write BENCHMARKS.md into a folder")
    p.add_argument(
        "--only", nargs="*", choices=["core", "design", "env", "conditioning"], help="sections (default: all)"
    )
    p.add_argument("--quick", action="store_true", help="fewer repeats (with --train: the recipes' smoke runs)")
    p.add_argument(
        "--train",
        action="store_true",
        help="time end-to-end training of every recipe beside PPO on MPE2 through SuperSuit "
        "(python -m benchmarks.train_bench has more options)",
    )
    p.add_argument(
        "--out", default="out", help="folder of the BENCHMARKS.md written (--out . rewrites the committed one)"
    )
    add_progress_argument(p)
    p.set_defaults(func=cmd_bench)
    return parser


#: Errors that are the user's (a bad value, a missing or corrupt file, invalid JSON, an unwritable output):
#: one line on stderr and exit code 2; ``--debug`` shows the traceback instead.
USER_ERRORS: tuple[type[BaseException], ...] = (ValueError, TypeError, KeyError, OSError, ImportError)


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args, rest = parser.parse_known_args(argv)
    if args.command == "train":
        args.train_args = rest
    elif rest:
        parser.error(f"unrecognized arguments: {' '.join(rest)}")
    for name in ("episodes", "steps", "seed", "fps"):
        value = getattr(args, name, None)
        if isinstance(value, int) and (value < 0 or (value == 0 and name != "seed")):
            parser.error(f"--{name} must be {'>= 0' if name == 'seed' else 'a positive integer'}, got {value}")
    try:
        return int(args.func(args))
    except USER_ERRORS as exc:
        if args.debug:
            raise
        what = type(exc).__name__
        msg = str(exc).splitlines()[0] if str(exc) else what
        print(f"formation-env {args.command}: {msg} ({what}; --debug shows the traceback)", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
