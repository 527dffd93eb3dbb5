"""How fast a policy closes on the goal: ``python -m train.approach_profile --policy P [--policy Q ...]``.

Runs the suite's first episodes (seeds ``--seed`` .. ``--seed + --episodes - 1``, as ``evaluate``) and prints,
every ``--every`` seconds, the median over those episodes of the team's distance to its goal (m: the largest
agent distance to its goal position) and of its speed (m/s: the largest agent speed). An episode that has ended
keeps its last values. ``--policy`` takes what ``evaluate`` takes. docs/learning.md reads it: a policy that
slows down in proportion to its distance (an exponential approach) against one that travels at speed and
brakes late.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

import numpy as np

from agents.policy import load_policy
from agents.rollout import reset_paired
from formation_env.env.engine import Engine


def profile(engine: Engine, policy: str, seeds: Sequence[int], every: float, horizon: float) -> np.ndarray:
    """Rows (time s, median distance to goal m, median speed m/s), one per ``every`` seconds up to ``horizon``."""
    act = load_policy(policy, engine).act_engine
    state = reset_paired(engine, seeds)
    obs = engine.observe(state)
    live = np.ones(state.batch_size, bool)
    dist = np.linalg.norm(state.pos - state.goal, axis=-1).max(axis=1)
    speed = np.zeros(state.batch_size)
    stride = max(1, round(every / engine.dt))
    rows = []
    for k in range(1, round(horizon / engine.dt) + 1):
        state, obs, _r, term, trunc, _info = engine.step(state, act(engine, state, obs))
        dist = np.where(live, np.linalg.norm(state.pos - state.goal, axis=-1).max(axis=1), dist)
        speed = np.where(live, np.linalg.norm(state.vel, axis=-1).max(axis=1), speed)
        live &= ~(term | trunc)
        if k % stride == 0:
            rows.append((k * engine.dt, float(np.median(dist)), float(np.median(speed))))
    return np.array(rows)


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m train.approach_profile", description=__doc__.splitlines()[0])
    p.add_argument("--policy", action="append", required=True, help="analytic, random or a saved policy; repeatable")
    p.add_argument("--scenario", default="hold")
    p.add_argument("--episodes", type=int, default=100)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--every", type=float, default=0.5, help="seconds between rows")
    p.add_argument("--horizon", type=float, default=8.0, help="seconds")
    args = p.parse_args(argv)
    if args.episodes < 1 or args.every <= 0 or args.horizon < args.every:
        p.error("--episodes must be >= 1, --every > 0 and --horizon >= --every")
    engine = Engine(args.scenario)
    seeds = range(args.seed, args.seed + args.episodes)
    table = {pol: profile(engine, pol, seeds, args.every, args.horizon) for pol in args.policy}
    print("| t (s) | " + " | ".join(f"{pol}: distance (m), speed (m/s)" for pol in args.policy) + " |")
    print("|---|" + "---|" * len(args.policy))
    for i, t in enumerate(next(iter(table.values()))[:, 0]):
        print(f"| {t:.1f} | " + " | ".join(f"{rows[i, 1]:.2f}, {rows[i, 2]:.2f}" for rows in table.values()) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
