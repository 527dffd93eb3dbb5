"""Where and in what shape a policy's team fails: ``python -m train.failures --policy P [--scenario S]``.

Runs the suite (seeds ``--seed`` .. ``--seed + --episodes - 1``, as ``evaluate``) and prints, for every episode that
ends in a collision, its seed, its ending (``agents.rollout.ENDINGS``: ``obstacle``, ``agents``, ``world_box``), the
time of the contact (s), the team's centroid x (m) and mean x-velocity (m/s) at the last sample before it, the
singular values of the fitted Theta there and a second earlier (the formation's largest and smallest scale: 1 is the
nominal shape's, a small one a flattened team; a growing one a team restoring its shape), and the agents in contact
at that sample: for an ``obstacle`` ending the agent nearest an obstacle's surface, for an ``agents`` ending the nearest
pair (index, L for a leader or F for a follower, nominal position r_i). ``--policy`` takes what ``evaluate`` takes,
``--env-kwargs`` the engine's arguments (e.g. a follower law and a network). docs/learning.md and docs/networks.md read
it.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from typing import Any

import numpy as np

from agents.policy import load_policy
from agents.rollout import run_batch
from formation_env.env.engine import Engine, EngineState
from formation_env.env.obstacles import point_clearance


def nearest_agent(engine: Engine, state: EngineState, i: int) -> int:
    """Index of the agent of copy ``i`` whose disc is nearest an obstacle's surface in ``state``."""
    caps = engine.capsules(state.params, state.k)
    gaps = [point_clearance(state.pos[i, a : a + 1], caps.a[i], caps.e[i], caps.rad[i]) for a in range(engine.n)]
    return int(np.argmin(gaps))


def nearest_pair(engine: Engine, state: EngineState, i: int) -> tuple[int, int]:
    """Of the pairs the engine checks for contact (``pair_i``, ``pair_j``), the one of copy ``i`` nearest each other
    in ``state`` (lower index first)."""
    gaps = np.linalg.norm(state.pos[i, engine.pair_i] - state.pos[i, engine.pair_j], axis=-1)
    k = int(np.argmin(gaps))
    a, b = int(engine.pair_i[k]), int(engine.pair_j[k])
    return min(a, b), max(a, b)


def failures(
    policy: str, seeds: Sequence[int], scenario: str | None = None, env_kwargs: dict[str, Any] | None = None
) -> list[dict[str, Any]]:
    """One row per suite episode that ends in a collision: ``seed``, ``ending``, ``time`` (s), ``x`` (m, the
    centroid's), ``vx`` (m/s, the agents' mean), ``scales`` (the fitted Theta's singular values, largest first), all
    read at the last sample before the contact; ``scales_before`` the same one second (or the episode's start)
    earlier; ``agents`` (indices: for an ``obstacle`` ending the agent nearest an obstacle's surface at that sample,
    for an ``agents`` ending the nearest pair, else none), ``leader`` (a bool each) and ``r`` (their nominal positions
    r_i, m). ``env_kwargs``: as :func:`train.evaluate.evaluate`'s."""
    pol = load_policy(policy, scenario=scenario, env_kwargs=env_kwargs)
    engine = pol.engine
    states: list[EngineState] = []

    def act(eng: Engine, state: EngineState, obs: Any) -> np.ndarray:
        states.append(state)
        return pol.act_engine(eng, state, obs)

    def scales(state: EngineState, i: int) -> list[float]:
        return np.linalg.svd(engine.affine.fit(state.pos[i : i + 1])[0][0], compute_uv=False).tolist()

    res = run_batch(engine, act, seeds)
    lag = round(1.0 / engine.dt)
    leaders = set(np.asarray(engine.leaders).tolist())
    rows = []
    for i in np.flatnonzero(res["collision"]).tolist():
        k = int(res["steps"][i]) - 1
        state = states[k]
        ending = str(res["ending"][i])
        who = [nearest_agent(engine, state, i)] if ending == "obstacle" else []
        who = list(nearest_pair(engine, state, i)) if ending == "agents" else who
        rows.append({"seed": int(seeds[i]), "ending": ending, "time": float(res["steps"][i]) * engine.dt,
                     "x": float(state.pos[i, :, 0].mean()), "vx": float(state.vel[i, :, 0].mean()),
                     "scales": scales(state, i), "scales_before": scales(states[max(k - lag, 0)], i),
                     "agents": who, "leader": [a in leaders for a in who],
                     "r": [engine.fw.positions[a].tolist() for a in who]})  # fmt: skip
    return rows


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m train.failures", description=__doc__.splitlines()[0])
    p.add_argument("--policy", required=True, help="a saved policy, analytic or random")
    p.add_argument("--scenario", default=None, help="default: the policy's")
    p.add_argument("--episodes", type=int, default=100)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--env-kwargs", default=None, help='JSON engine arguments, e.g. {"follower_law": "linear"}')
    a = p.parse_args(argv)
    if a.episodes < 1:
        p.error(f"--episodes must be >= 1, got {a.episodes}")
    try:
        env_kwargs = None if a.env_kwargs is None else json.loads(a.env_kwargs)
    except json.JSONDecodeError as e:
        p.error(f"--env-kwargs is not JSON: {e}")
    if env_kwargs is not None and not isinstance(env_kwargs, dict):
        p.error(f"--env-kwargs must be a JSON object, got {a.env_kwargs!r}")
    rows = failures(a.policy, list(range(a.seed, a.seed + a.episodes)), a.scenario, env_kwargs)
    print(f"collisions: {len(rows)} of {a.episodes}")
    print("seed | ending | t (s) | centroid x (m) | x-velocity (m/s) | Theta's singular values | a second earlier | "
          "agents in contact (L/F, r_i)")  # fmt: skip
    for r in rows:
        sv, sv0 = (" / ".join(f"{v:.2f}" for v in r[key]) for key in ("scales", "scales_before"))
        who = "; ".join(f"{a} {'L' if lead else 'F'} ({', '.join(f'{v:g}' for v in ri)})"
                        for a, lead, ri in zip(r["agents"], r["leader"], r["r"], strict=True)) or "-"  # fmt: skip
        print(f"{r['seed']} | {r['ending']} | {r['time']:.1f} | {r['x']:.2f} | {r['vx']:.2f} | {sv} | {sv0} | {who}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
