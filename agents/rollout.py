"""Batched rollouts of a policy on a seeded suite, for evaluation and tuning (no training code here).

Episode i of a suite with base seed S is drawn from ``np.random.default_rng(S + i)``
(``Engine.reset_each``), so every policy meets the same episodes (paired by seed).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from formation_env.env.engine import Engine, EngineState

__all__ = ["ENDINGS", "FORMED_FRACTION", "ActFn", "reset_paired", "run_batch"]

#: How an episode ends (``run_batch``'s ``ending``): the success test held; a contact of two agents; a contact with
#: an obstacle (at a sample or along the step); an agent left the world box; none of these by the last sample.
ENDINGS = ("success", "agents", "obstacle", "world_box", "timeout")

#: The team is *formed* from the first sample whose formation error is at most this fraction of the scenario's
#: success tolerance ``formation_tol`` (0.05 m by default: 5 mm): the followers' start noise (up to a few cm, below
#: the tolerance already at the reset) has decayed by an order of magnitude.
FORMED_FRACTION = 0.1

Array = NDArray[np.float64]

ActFn = Callable[[Engine, EngineState, Any], Array]


def reset_paired(engine: Engine, seeds: Sequence[int]) -> EngineState:
    """One episode per seed, batched: episode i equals ``Engine.reset(default_rng(seeds[i]), 1)``."""
    return engine.reset_each([np.random.default_rng(int(s)) for s in seeds])


def run_batch(
    engine: Engine,
    act: ActFn,
    seeds: Sequence[int],
    record: int | None = None,
    max_steps: int | None = None,
    on_step: Callable[[], Any] | None = None,
) -> dict[str, Any]:
    """Roll out one episode per seed, batched; ``act(engine, state, obs) -> (B, n_l, p)``.

    Finished episodes keep stepping (their results are frozen at their end). ``record``: index of an
    episode whose renderer frames (``engine.frame`` dicts) are kept under ``"frames"``. ``on_step()`` is called
    after every batched step (a progress bar's ``update``).

    Returns per-episode arrays (B,): success, collision (bool), time_to_goal (s, nan if none),
    mean_formation_err (m, over the episode's samples), formed_time (s: the first sample at which the team is
    formed, the formation error at most :data:`FORMED_FRACTION` times the scenario's ``formation_tol``; 0 if formed
    at the reset, nan if never), max_formation_err (m: the largest error from that sample to the episode's end;
    nan if never formed), tracking_err (m: the largest distance of an agent to its reference position, the goal
    of that sample, averaged over the episode's samples), min_clearance (m), control_effort, steps, and
    ``ending`` (str, one of :data:`ENDINGS`; a collision is ``world_box`` if an agent left the box, else ``agents``
    if two agents touch at that sample, else ``obstacle``).
    """
    state = reset_paired(engine, seeds)
    B = state.batch_size
    obs = engine.observe(state)
    steps = engine.max_cycles if max_steps is None else int(max_steps)
    done = np.zeros(B, bool)
    success = np.zeros(B, bool)
    collision = np.zeros(B, bool)
    t_goal = np.full(B, np.nan)
    err_sum = np.zeros(B)
    formed_tol = FORMED_FRACTION * engine.scenario.formation_tol
    formed = np.asarray(state.err, dtype=np.float64) <= formed_tol  # the reset's error is the scenario's noise
    t_formed = np.where(formed, 0.0, np.nan)
    err_max = np.where(formed, np.asarray(state.err, dtype=np.float64), np.nan)
    track_sum = np.zeros(B)
    n_samples = np.zeros(B)
    clear = np.full(B, np.inf)
    effort = np.zeros(B)
    ending = np.full(B, "timeout", dtype=object)
    frames: list[dict[str, Any]] = []
    trail: list[Array] = []
    if record is not None:
        trail.append(state.pos[record].copy())
        frames.append(engine.frame(state, record, np.array(trail)))
    for _ in range(steps):
        a = act(engine, state, obs)
        was = state
        state, obs, _r, term, trunc, info = engine.step(state, a)
        live = ~done
        err = info["formation_error"]
        err_sum += np.where(live, err, 0.0)
        now = live & ~formed & (err <= formed_tol)
        t_formed[now] = info["time"][now]
        formed |= now
        err_max = np.where(live & formed, np.fmax(err_max, err), err_max)  # nan until formed
        track_sum += np.where(live, info["goal_distance"], 0.0)
        n_samples += live
        clear = np.where(live, np.minimum(clear, info["min_clearance"]), clear)
        effort += np.where(live, info["control_effort"].sum(axis=1) * engine.dt, 0.0)
        newly = live & info["success"]
        t_goal[newly & np.isnan(t_goal)] = info["time"][newly & np.isnan(t_goal)]
        success |= newly
        hit = live & info["collision"]
        if hit.any():
            gaps = np.linalg.norm(state.pos[:, engine.pair_i] - state.pos[:, engine.pair_j], axis=-1)
            touch = gaps.min(axis=1, initial=np.inf) < 2.0 * engine.agent_radius
            ending[hit] = np.where(info["out_of_bounds"], "world_box", np.where(touch, "agents", "obstacle"))[hit]
        collision |= hit
        if record is not None and not done[record]:
            trail.append(state.pos[record].copy())
            frames.append(engine.frame(state, record, np.array(trail[-60:])))
        done |= term | trunc
        del was
        if on_step is not None:
            on_step()
        if done.all():
            break
    if not engine.scenario.terminate_on_success:  # judged at the last sample (e.g. maneuver)
        success = success & info["success"]
    ending[success & ~collision] = "success"
    return {
        "success": success & ~collision,
        "collision": collision,
        "time_to_goal": np.where(success & ~collision, t_goal, np.nan),
        "mean_formation_err": err_sum / np.maximum(n_samples, 1),
        "formed_time": t_formed,
        "max_formation_err": err_max,
        "tracking_err": track_sum / np.maximum(n_samples, 1),
        "min_clearance": clear,
        "control_effort": effort,
        "steps": n_samples,
        "ending": ending.astype(str),
        "frames": frames,
    }
