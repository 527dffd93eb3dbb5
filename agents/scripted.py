"""Scripted reference policies: simple, stateless, batched, used by the tests to show tasks are solvable.

They are not the tuned baselines (those are :mod:`agents.planner`); they are the plainest policies that
succeed on every episode of a scenario's suite.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from formation_env.env.scenarios._base import affine_batch

if TYPE_CHECKING:
    from formation_env.env.engine import Engine, EngineState

__all__ = ["crossing_action", "passage_action"]

Array = NDArray[np.float64]


def passage_action(engine: Engine, state: EngineState, margin: float = 0.1) -> Array:
    """Reference policy, stateless and batched: shrink at the gap, pass, restore, go to the goal.

    Per episode, with wall x_w, gap centre y_c and width w: the squeezed pose is
    Theta_s = diag(1, s), s = (w - 2 radius - 2 margin) / ptp(r_y), b_y centring the
    formation on the gap. Until every agent is past the wall (x > x_w + radius + margin)
    the leaders track the squeezed pose, holding b_x in front of the wall until every
    agent is within margin/2 of its squeezed y, then pushing b_x through; afterwards
    they track the goal pose. Leaders follow their targets with :func:`track_targets`.

    Returns:
        actions in [-1, 1], shape (B, n_l, p).
    """
    from formation_env.env.control import track_targets

    sc = engine.scenario
    r = sc.r
    rad = sc.agent_radius
    p = state.params
    pos = state.pos
    B = pos.shape[0]
    ry = r[:, 1]
    s = (p["gap_width"] - 2 * rad - 2 * margin) / np.ptp(ry)
    by = p["gap_center"] - s * (ry.max() + ry.min()) / 2
    ty = by[:, None] + s[:, None] * ry[None, :]  # squeezed y of every agent, (B, n)
    aligned = np.max(np.abs(pos[:, :, 1] - ty), axis=1) < margin / 2
    wall = p["wall_x"]
    passed = pos[:, :, 0].min(axis=1) > wall + rad + margin
    b_fit = engine.affine.fit(pos)[1]
    entering = pos[:, :, 0].max(axis=1) > wall - 0.4
    bx = np.where(
        aligned,
        wall - r[:, 0].min() + rad + 3 * margin,
        np.where(entering, b_fit[:, 0], wall - r[:, 0].max() - 0.6),
    )
    theta_s = np.zeros((B, 2, 2))
    theta_s[:, 0, 0] = 1.0
    theta_s[:, 1, 1] = s
    squeeze = affine_batch(r, theta_s, np.stack([bx, by], -1))
    goal = affine_batch(r, p["goal_theta"], p["goal_b"])
    targets = np.where(passed[:, None, None], goal, squeeze)
    return track_targets(engine, state, targets[:, engine.leaders])


def crossing_action(engine: Engine, state: EngineState) -> Array:
    """Reference policy for ``moving_obstacles``: :class:`agents.planner.CrossingPlanner` as tuned (shrink, wait
    for a window predicted clear of every disc, cross, restore, go to the goal)."""
    from .planner import CrossingPlanner

    return CrossingPlanner()(engine, state)
