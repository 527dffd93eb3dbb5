"""Where and in what shape a policy's team fails: ``python -m train.failures --policy P [--scenario S]``.

Runs the suite (seeds ``--seed`` .. ``--seed + --episodes - 1``, as ``evaluate``) and prints, for every episode that
ends in a collision, its seed, its ending (``agents.rollout.ENDINGS``: ``obstacle``, ``agents``, ``world_box``), the
time of the contact (s), the team's centroid x (m) and mean x-velocity (m/s) at the last sample before it, and the
singular values of the fitted Theta there (the formation's largest and smallest scale: 1 is the nominal shape's, a small
one a flattened team). ``--policy`` takes what ``evaluate`` takes. docs/learning.md reads it.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from typing import Any

import numpy as np

from agents.policy import load_policy
from agents.rollout import run_batch
from formation_env.env.engine import Engine, EngineState


def failures(policy: str, seeds: Sequence[int], scenario: str | None = None) -> list[dict[str, Any]]:
    """One row per suite episode that ends in a collision: ``seed``, ``ending``, ``time`` (s), ``x`` (m, the
    centroid's), ``vx`` (m/s, the agents' mean), ``scales`` (the fitted Theta's singular values, largest first), all
    read at the last sample before the contact."""
    pol = load_policy(policy, scenario=scenario)
    engine = pol.engine
    last: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []

    def act(eng: Engine, state: EngineState, obs: Any) -> np.ndarray:
        scales = np.linalg.svd(eng.affine.fit(state.pos)[0], compute_uv=False)
        last.append((state.pos[:, :, 0].mean(axis=1), state.vel[:, :, 0].mean(axis=1), scales))
        return pol.act_engine(eng, state, obs)

    res = run_batch(engine, act, seeds)
    rows = []
    for i in np.flatnonzero(res["collision"]).tolist():
        x, vx, sv = (a[i] for a in last[int(res["steps"][i]) - 1])
        rows.append({"seed": int(seeds[i]), "ending": str(res["ending"][i]), "time": float(res["steps"][i]) * engine.dt,
                     "x": float(x), "vx": float(vx), "scales": sv.tolist()})  # fmt: skip
    return rows


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m train.failures", description=__doc__.splitlines()[0])
    p.add_argument("--policy", required=True, help="a saved policy, analytic or random")
    p.add_argument("--scenario", default=None, help="default: the policy's")
    p.add_argument("--episodes", type=int, default=100)
    p.add_argument("--seed", type=int, default=0)
    a = p.parse_args(argv)
    if a.episodes < 1:
        p.error(f"--episodes must be >= 1, got {a.episodes}")
    rows = failures(a.policy, list(range(a.seed, a.seed + a.episodes)), a.scenario)
    print(f"collisions: {len(rows)} of {a.episodes}")
    print("seed | ending | t (s) | centroid x (m) | x-velocity (m/s) | Theta's singular values")
    for r in rows:
        sv = " / ".join(f"{v:.2f}" for v in r["scales"])
        print(f"{r['seed']} | {r['ending']} | {r['time']:.1f} | {r['x']:.2f} | {r['vx']:.2f} | {sv}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
