"""Saturated leader tracking: actions in [-1, 1] that steer each leader to a target position.

Used by the commander env's ``maneuver`` action mode and by the scripted reference
policies; batched like the engine.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from formation_env.core.dynamics import riccati_gain

from .engine import Engine, EngineState

__all__ = ["track_targets"]

Array = NDArray[np.float64]


def track_targets(
    engine: Engine,
    state: EngineState,
    targets: Array,
    target_vel: Array | None = None,
    kp: float = 2.0,
    kd: float | None = None,
) -> Array:
    """Leader actions that track ``targets`` (B, n_l, d) moving at ``target_vel`` (B, n_l, d), m/s.

    * single integrator: u = kp (target - p) + target_vel  (kp in 1/s);
    * double integrator: u = kp (target - p) + kd (target_vel - v), kd = 2 sqrt(kp) (critically damped);
    * other dynamics: u = K (x_l - x_ref), K the Riccati gain of the sampled model, x_ref at rest on target.

    Returns:
        u / u_max clipped to [-1, 1], shape (B, n_l, p).
    """
    L = engine.leaders
    tv = 0.0 if target_vel is None else target_vel
    if engine.kind == "single_integrator":
        u = kp * (targets - state.pos[:, L]) + tv
    elif engine.kind == "double_integrator":
        kd_ = 2.0 * np.sqrt(kp) if kd is None else kd
        u = kp * (targets - state.pos[:, L]) + kd_ * (tv - state.vel[:, L])
    else:
        ad, bd = engine.dynamics.zoh(engine.dt)
        K = riccati_gain(ad, bd)
        xref = engine.dynamics.state_from_position(targets)
        u = (state.x[:, L] - xref) @ K.T
    return np.clip(u * (1.0 / engine.u_max), -1.0, 1.0)
