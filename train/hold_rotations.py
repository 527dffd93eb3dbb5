"""When and on which goals a policy collides on ``hold``: ``python -m train.hold_rotations --policy P``.

Runs the suite (seeds ``--seed`` .. ``--seed + --episodes - 1``, as ``evaluate``) and prints, for the episodes that
end in a collision, the time of the contact (s) and the rotation between the start pose and the goal pose
(degrees: the angle of the polar factor of Theta_g Theta_0^-1, Theta_0 the least-squares fit of the start); for
the others the 10th, 50th and 90th percentile of that rotation. ``--policy`` takes what ``evaluate`` takes, or
``zero`` (every leader's action 0). docs/learning.md reads it.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

import numpy as np

from agents.policy import load_policy
from agents.rollout import ActFn, reset_paired, run_batch
from formation_env.env.engine import Engine


def rotations(engine: Engine, seeds: Sequence[int]) -> np.ndarray:
    """The start-to-goal rotation (degrees, in [0, 180]) of each suite episode of a 2D ``hold`` engine, (B,)."""
    s0 = reset_paired(engine, seeds)
    th0, _ = engine.affine.fit(s0.pos)
    rel = s0.params["goal_theta"] @ np.linalg.inv(th0)
    return np.degrees(np.abs(np.arctan2(rel[:, 1, 0] - rel[:, 0, 1], rel[:, 0, 0] + rel[:, 1, 1])))


def collision_times(engine: Engine, policy: str, seeds: Sequence[int]) -> np.ndarray:
    """The time (s) of each suite episode's collision, NaN where it ends otherwise, (B,)."""
    if policy == "zero":
        act: ActFn = lambda eng, st, obs: np.zeros((st.batch_size, eng.n_l, eng.p))  # noqa: E731
    else:
        act = load_policy(policy, engine).act_engine
    res = run_batch(engine, act, seeds)
    return np.where(res["collision"], res["steps"] * engine.dt, np.nan)


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m train.hold_rotations", description=__doc__.splitlines()[0])
    p.add_argument("--policy", required=True, help="a saved policy, analytic, random or zero")
    p.add_argument("--episodes", type=int, default=100)
    p.add_argument("--seed", type=int, default=0)
    a = p.parse_args(argv)
    engine = Engine("hold")
    seeds = list(range(a.seed, a.seed + a.episodes))
    when, angle = collision_times(engine, a.policy, seeds), rotations(engine, seeds)
    hit = np.isfinite(when)
    print(f"collisions: {int(hit.sum())} of {len(seeds)}")
    print("  at t (s):", np.sort(when[hit]).round(1).tolist())
    print("  rotation (deg):", np.sort(angle[hit]).round(0).tolist())
    print("others, rotation (deg) p10 / p50 / p90:", np.percentile(angle[~hit], [10, 50, 90]).round(0).tolist())
    return 0


if __name__ == "__main__":
    sys.exit(main())
