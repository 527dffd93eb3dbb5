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

__all__ = ["ENDINGS", "ActFn", "reset_paired", "run_batch"]

#: How an episode ends (``run_batch``'s ``ending``): the success test held; a contact of two agents; a contact with
#: an obstacle (at a sample or along the step); an agent left the world box; none of these by the last sample.
ENDINGS = ("success", "agents", "obstacle", "world_box", "timeout")

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
    mean_formation_err, max_formation_err, min_clearance (m), control_effort, steps, and ``ending`` (str, one of
    :data:`ENDINGS`; a collision is ``world_box`` if an agent left the box, else ``agents`` if two agents touch at
    that sample, else ``obstacle``).
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
    err_max = np.zeros(B)  # from the first action on: the reset state's error is the scenario's, not the policy's
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
        err_sum += np.where(live, info["formation_error"], 0.0)
        err_max = np.where(live, np.maximum(err_max, info["formation_error"]), err_max)
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
        "max_formation_err": err_max,
        "min_clearance": clear,
        "control_effort": effort,
        "steps": n_samples,
        "ending": ending.astype(str),
        "frames": frames,
    }
