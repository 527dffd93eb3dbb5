"""The commander's ``maneuver`` action mode: actions are rates of a commanded affine pose, batched.

One action commands the whole team's pose Theta_c = R (I + H) diag(s), b_c (paper eq. 7); the leaders track
their targets Theta_c r_l + b_c with saturated commands (:func:`~formation_env.env.control.track_targets`) and
the followers run the stress law as always. The pose is a few arrays per environment (:class:`Pose`), advanced
by :meth:`PoseCommand.step`; the single commander env (B = 1) and ``FormationVecEnv`` (B envs) share this code.

Action (d (d + 1),) in [-1, 1]: [velocity of b_c (d) | log-scale rates of s per axis (d) | rotation rate (2D: 1,
angle; 3D: 3, rotation vector) | shear rates of the strictly upper triangle of H (d (d - 1) / 2)], scaled by
``pose_speed`` (m/s), ``scale_rate`` (1/s), ``rotation_rate`` (rad/s), ``shear_rate`` (1/s). s stays in
``scale_range``, H in [-1, 1], b_c in the world box. Every commanded pose is invertible, so no exploration can
collapse the leaders' affine span.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from formation_env.core.errors import FormationError
from formation_env.core.validation import as_array, check_real_scalar

from .control import track_targets
from .scenarios._base import affine_batch, rotation_2d, rotation_3d
from .state import EngineState

__all__ = ["Pose", "PoseCommand"]

Array = NDArray[np.float64]


class Pose(NamedTuple):
    """Commanded poses of B environments: R (B, d, d) rotation, s (B, d) scales, H (B, d, d) strictly upper
    shear, b (B, d) m; Theta_c = R (I + H) diag(s)."""

    R: Array
    s: Array
    H: Array
    b: Array

    def theta(self) -> Array:
        """Theta_c, (B, d, d)."""
        d = self.s.shape[-1]
        return self.R @ ((np.eye(d) + self.H) * self.s[:, None, :])

    def replace_rows(self, index: NDArray[np.int64], new: Pose) -> Pose:
        """These poses with rows ``index`` taken from ``new`` (auto-resets)."""
        out = [f.copy() for f in self]
        for f, g in zip(out, new, strict=True):
            f[index] = g
        return Pose(*out)


class PoseCommand:
    """Turns pose-rate actions into leader actions for one engine (see the module docstring).

    Args:
        engine: the :class:`~formation_env.env.engine.Engine` whose leaders track the pose.
        pose_speed: m/s of b_c at action 1. scale_rate: 1/s of log s. rotation_rate: rad/s. shear_rate: 1/s.
        scale_range: (lo, hi) of every scale, 0 < lo < 1 < hi.
    """

    def __init__(
        self,
        engine: Any,
        *,
        pose_speed: float = 1.0,
        scale_rate: float = 0.5,
        rotation_rate: float = 0.5,
        shear_rate: float = 0.5,
        scale_range: tuple[float, float] = (0.2, 2.0),
    ) -> None:
        self.engine = engine
        rates = {"pose_speed": pose_speed, "scale_rate": scale_rate, "rotation_rate": rotation_rate,
                 "shear_rate": shear_rate}  # fmt: skip
        self.rates = np.array([check_real_scalar(v, k, low=0.0) for k, v in rates.items()], dtype=np.float64)
        lo, hi = as_array(scale_range, "scale_range", shape=(2,))
        self.scale_range = (float(lo), float(hi))
        if not 0 < self.scale_range[0] < 1 < self.scale_range[1]:
            raise FormationError(f"scale_range must satisfy 0 < lo < 1 < hi, got {scale_range}")
        d = engine.d
        self._iu = np.triu_indices(d, 1)
        self.action_dim = d * (d + 1)
        #: Bounds of :meth:`observe`'s entries (d^2 + d,): Theta_c row-major in [-6, 6], then b_c in the world box.
        self.obs_low = np.concatenate([np.full(d * d, -6.0), engine.bounds[0]]).astype(np.float32)
        self.obs_high = np.concatenate([np.full(d * d, 6.0), engine.bounds[1]]).astype(np.float32)

    def reset(self, state: EngineState) -> Pose:
        """The poses of fresh episodes: the QR factors of each start's affine fit (scales clipped to range)."""
        theta, b = self.engine.affine.fit(state.pos)
        q, r = np.linalg.qr(theta)
        sign = np.sign(np.diagonal(r, axis1=-2, axis2=-1))
        sign[sign == 0] = 1.0
        q, r = q * sign[:, None, :], r * sign[:, :, None]
        diag = np.diagonal(r, axis1=-2, axis2=-1)
        H = np.clip(np.triu(r / diag[:, None, :], 1), -1.0, 1.0)
        return Pose(q, np.clip(diag, *self.scale_range), H, np.array(b, dtype=np.float64))

    def advance(self, pose: Pose, action: Array) -> Pose:
        """The poses one sample later under ``action`` (B, d (d + 1)) in [-1, 1]."""
        eng, rates = self.engine, self.rates
        d, dt = eng.d, eng.dt
        v, sc, rot, sh = np.split(action, [d, 2 * d, 2 * d + len(self._iu[0])], axis=-1)
        b = np.clip(pose.b + rates[0] * dt * v, *eng.bounds)
        s = np.clip(pose.s * np.exp(rates[1] * dt * sc), *self.scale_range)
        ang = rates[2] * dt * rot
        if d == 2:
            turn = rotation_2d(ang[:, 0])
        else:
            norm = np.linalg.norm(ang, axis=-1)
            turn = rotation_3d(np.where(norm[:, None] > 0, ang, np.array([0.0, 0.0, 1.0])), norm)
        H = pose.H.copy()
        i, j = self._iu
        H[:, i, j] = np.clip(H[:, i, j] + rates[3] * dt * sh, -1.0, 1.0)
        return Pose(turn @ pose.R, s, H, b)

    def step(self, state: EngineState, pose: Pose, action: Array) -> tuple[Pose, Array]:
        """Advance the poses by ``action`` (B, d (d + 1)) (clipped to [-1, 1]; NaN or inf raise ValueError) and
        return them with the leader actions (B, n_l, p) that track the new targets at their velocity."""
        a = np.asarray(action, dtype=np.float64)
        if not np.all(np.isfinite(a)):
            raise ValueError(f"maneuver action holds NaN or inf: {a.tolist()}; the state is unchanged")
        a = np.clip(a, -1.0, 1.0)
        eng = self.engine
        rl = eng.fw.positions[eng.leaders]
        before = affine_batch(rl, pose.theta(), pose.b)
        new = self.advance(pose, a)
        after = affine_batch(rl, new.theta(), new.b)
        return new, track_targets(eng, state, after, (after - before) / eng.dt)

    def observe(self, pose: Pose) -> Array:
        """Theta_c (row-major) and b_c of every environment, (B, d^2 + d), clipped to ``obs_low``/``obs_high``."""
        out = np.concatenate([pose.theta().reshape(pose.b.shape[0], -1), pose.b], axis=1)
        return np.clip(out, self.obs_low, self.obs_high)
