"""RLlib PPO throughput with 0, 1 and 2 env runners: ``python -m benchmarks.rllib_bench``.

Trains the shared leader policy of ``python -m train.rllib`` (its PPO settings: 4,000 env steps per iteration,
5 epochs, a 64x64 network, one env per runner) on a local Ray and reports env steps per wall-clock second of
whole training iterations (sampling and the learner's update), after one warm-up iteration that is not counted.
``0`` runners samples in the driver; ``N`` >= 1 samples in N remote env-runner processes while the driver learns.
An env step is one step of the team (every leader acts once).

The machine's load average is printed beside the figures: other processes on the same cores slow the runners.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import sys
import time
from typing import Any

from .timing import machine

TITLE = "RLlib PPO: env steps/s by env runners"


def measure(runners: int, iterations: int, scenario: str, seed: int = 0) -> dict[str, Any]:
    """Env steps/s of ``iterations`` timed ``Algorithm.train()`` calls with ``runners`` remote env runners."""
    from train.rllib import PPO_DEFAULTS, build_config, metrics_of

    algo = build_config(scenario, seed, runners, {}, dict(PPO_DEFAULTS), [64, 64]).build_algo()
    try:
        steps0 = metrics_of(algo.train())["env_steps"]  # warm-up: workers start, torch and the env compile
        t0 = time.perf_counter()
        for _ in range(iterations):
            steps = metrics_of(algo.train())["env_steps"]
        wall = time.perf_counter() - t0
    finally:
        algo.stop()
    return {"env_runners": runners, "iterations": iterations, "env_steps": steps - steps0,
            "wall_s": round(wall, 1), "steps_per_s": round((steps - steps0) / wall)}  # fmt: skip


def run(runners: list[int], iterations: int, scenario: str) -> list[dict[str, Any]]:
    """:func:`measure` for each runner count, on one local Ray."""
    import ray

    ray.init(include_dashboard=False, log_to_driver=False, logging_level="ERROR")
    try:
        return [measure(n, iterations, scenario) for n in runners]
    finally:
        ray.shutdown()


def markdown(rows: list[dict[str, Any]]) -> str:
    """A markdown table of the rows of :func:`run`."""
    lines = ["| env runners | env steps | wall (s) | env steps/s |", "|---|---|---|---|"]
    lines += [f"| {r['env_runners']} | {r['env_steps']} | {r['wall_s']} | {r['steps_per_s']} |" for r in rows]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.rllib_bench", description=__doc__.splitlines()[0],
                                formatter_class=argparse.ArgumentDefaultsHelpFormatter)  # fmt: skip
    p.add_argument("--runners", type=int, nargs="+", default=[0, 1, 2], help="env-runner counts to measure")
    p.add_argument("--iterations", type=int, default=3, help="timed training iterations per count")
    p.add_argument("--scenario", default="narrow_passage")
    p.add_argument("--json", action="store_true", help="print the rows as one JSON object instead of a table")
    args = p.parse_args(argv)
    if args.iterations < 1 or min(args.runners) < 0:
        p.error(f"--iterations must be >= 1 and --runners >= 0, got {args.iterations}, {args.runners}")
    load0 = os.getloadavg()[0]
    rows = run(args.runners, args.iterations, args.scenario)
    load1 = os.getloadavg()[0]
    stamp = dt.datetime.now(dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    where = f"{machine()}; load average {load0:.1f} before, {load1:.1f} after"
    if args.json:
        print(json.dumps({"measured": stamp, "machine": where, "scenario": args.scenario, "rows": rows}))
    else:
        print(f"{TITLE} ({args.scenario}), {stamp}, {where}\n")
        print(markdown(rows))
    return 0


if __name__ == "__main__":
    if os.environ.get("PYTHONHASHSEED") != "0":  # as train.rllib: fixed string hashing, inherited by the workers
        os.execve(sys.executable, [sys.executable, "-m", "benchmarks.rllib_bench", *sys.argv[1:]],
                  {**os.environ, "PYTHONHASHSEED": "0"})  # fmt: skip
    sys.exit(main())
