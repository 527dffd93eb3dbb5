"""``maneuver``: track a time-varying affine image Theta(t) r + b(t) (2D or 3D).

The reference pose (uniform draws per episode; H = max_cycles * dt is the horizon, s):

* Start Theta0 a rotation (2D angle in [-pi, pi]; 3D random axis and angle), b0 in [-1, 1]^d.
* Theta(t) = Sh(t) S(t) R(t) Theta0 and b(t) = b0 + ramp(t) offset, where each factor moves
  from I to its final value along a smoothstep ramp over its window:
  translation ``offset`` (random direction, length in [2, 5] m) over [0.05 H, 0.95 H];
  rotation R by an angle of magnitude in [pi/4, pi/2] (random sign; 3D about a random axis)
  over [0.1 H, 0.4 H]; scaling S = diag(f), each f in [0.6, 1.4], over [0.35 H, 0.65 H];
  shear Sh = I + h e_0 e_1^T, h in [-0.5, 0.5], over [0.6 H, 0.9 H].
  This is ``translate(offset) @ hold(b=b0) @ shear(h) @ scale(f) @ rotate(angle) @ hold(Theta0)``
  of :mod:`formation_env.core.affine`, batched.
* World box [-10, 10]^d. Agents start on the reference at t = 0 (followers with 0.05 m noise).

The analytic answer is known: the leaders command exactly x_l*((k+1) T) (single integrators:
u = (x*((k+1) T) - x(k)) / T); with the ``dynamic`` law the followers then track too.
Observation "goal" entries are the reference x_i*(t) and its velocity (x_i*(t + T) - x_i*(t)) / T.

Reward: ``distance`` (tracking) replaces ``progress``. Success (judged every sample, reported in
``info``; the episode does not end on it): every agent within ``goal_tol`` = 0.3 m of its
reference and the formation error below 0.05 m; the last sample's value is the episode's.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import numpy as np

from .._numba import jit
from ._base import Array, Draw, Scenario, check_range, rotation_2d, rotation_3d

__all__ = ["WINDOWS", "Maneuver", "smoothstep"]

#: Ramp windows as fractions of the horizon: translate, rotate, scale, shear.
WINDOWS: dict[str, tuple[float, float]] = {
    "translate": (0.05, 0.95),
    "rotate": (0.1, 0.4),
    "scale": (0.35, 0.65),
    "shear": (0.6, 0.9),
}


@jit
def smoothstep(t: float, start: float, stop: float) -> float:
    """0 before start, 1 after stop, 3 s^2 - 2 s^3 between (as ``core.affine._ramp``)."""
    s = min(max((t - start) / (stop - start), 0.0), 1.0)
    return s * s * (3.0 - 2.0 * s)


@jit
def pose_row(gp: Array, t: float, out: Array) -> None:  # pragma: no cover
    """The reference pose [Theta(t), b(t)] (d, d + 1) of one episode at time t (s) from its ``goal_p`` (w,):
    Theta0 (d^2, row-major), b0 (d), offset (d), angle, scale (d), shear, axis (3, in 3D), then the
    windows' (start, stop) of translate, rotate, scale, shear (s). Theta = Sh S R Theta0, b = b0 + offset
    ramp (the module docstring)."""
    d = out.shape[0]
    i = d * d
    b0, offset = gp[i : i + d], gp[i + d : i + 2 * d]
    angle, scale, shear = gp[i + 2 * d], gp[i + 2 * d + 1 : i + 3 * d + 1], gp[i + 3 * d + 1]
    win = gp[gp.size - 8 :]
    a = angle * smoothstep(t, win[2], win[3])
    co, si = math.cos(a), math.sin(a)
    rot = np.empty((d, d))
    if d == 2:
        rot[0, 0], rot[0, 1], rot[1, 0], rot[1, 1] = co, -si, si, co
    else:
        ax = gp[i + 3 * d + 2 : i + 3 * d + 5]
        k = ax / math.sqrt(np.sum(ax * ax))
        kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
        rot[:] = np.eye(3) + si * kx + (1.0 - co) * (kx @ kx)
    theta = rot @ gp[:i].reshape(d, d)
    fs = smoothstep(t, win[4], win[5])
    for r in range(d):
        theta[r] *= 1.0 + fs * (scale[r] - 1.0)
    theta[0] += shear * smoothstep(t, win[6], win[7]) * theta[1]
    out[:, :d] = theta
    out[:, d] = b0 + smoothstep(t, win[0], win[1]) * offset


@jit
def _pose_rows(gp: Array, t: Array, out: Array) -> None:  # pragma: no cover
    for b in range(gp.shape[0]):
        pose_row(gp[b], t[b], out[b])


class Maneuver(Scenario):
    """Track a randomised translate-rotate-scale-shear manoeuvre (see the module docstring)."""

    name: ClassVar[str] = "maneuver"
    dims: ClassVar[tuple[int, ...]] = (2, 3)
    moving_goal: ClassVar[bool] = True
    terminate_on_success: ClassVar[bool] = False
    half_size: ClassVar[tuple[float, ...]] = (10.0, 10.0, 10.0)
    grows_world: ClassVar[bool] = True
    planner: ClassVar[str | None] = "agents.planner:ManeuverPlanner"
    follower_noise: float = 0.05
    weights: ClassVar[dict[str, float]] = {"progress": 0.0, "distance": 1.0, "success": 0.0}
    goal_tol_default: ClassVar[float] = 0.3

    def _init(self, kw: dict[str, Any]) -> None:
        self.offset_length = check_range("offset_length", kw.pop("offset_length", (2.0, 5.0)))
        self.rotation = check_range("rotation", kw.pop("rotation", (np.pi / 4, np.pi / 2)))
        self.scale = check_range("scale", kw.pop("scale", (0.6, 1.4)), lo=1e-9)
        self.shear = check_range("shear", kw.pop("shear", (-0.5, 0.5)))
        self.start_b = check_range("start_b", kw.pop("start_b", (-1.0, 1.0)))
        self._win = {k: (a * self.horizon, b * self.horizon) for k, (a, b) in WINDOWS.items()}

    def draws(self) -> list[Draw]:
        d = self.d
        out = [
            Draw("direction", (d,), "normal"),
            Draw("angle0", bounds=(-np.pi, np.pi)),
            Draw("b0", (d,), bounds=self.start_b),
            Draw("offset_length", bounds=self.offset_length),
            Draw("rotation", bounds=self.rotation),
            Draw("sign", kind="sign"),
            Draw("scale", (d,), bounds=self.scale),
            Draw("shear", bounds=self.shear),
        ]
        if d == 3:
            out += [Draw("axis0", (3,), "normal"), Draw("axis", (3,), "normal")]
        return out + self.follower_draws()

    def build(self, raw: dict[str, Array]) -> tuple[dict[str, Array], tuple[Array, Array] | None]:
        direction = raw["direction"] / np.linalg.norm(raw["direction"], axis=-1, keepdims=True)
        B = direction.shape[0]
        params = {
            "b0": raw["b0"],
            "offset": direction * raw["offset_length"][:, None],
            "angle": raw["rotation"] * raw["sign"],
            "scale": raw["scale"],
            "shear": raw["shear"],
        }
        if self.d == 2:
            params["theta0"] = rotation_2d(raw["angle0"])
        else:
            params["theta0"] = rotation_3d(raw["axis0"], raw["angle0"])
            params["axis"] = raw["axis"]
        pose = self.reference(params, np.zeros(B))
        return params, pose

    pose_row = staticmethod(pose_row)

    def goal_vector(self, params: dict[str, Array]) -> Array:
        """The ``goal_p`` of :func:`pose_row` (B, w)."""
        B = params["b0"].shape[0]
        parts = [params["theta0"].reshape(B, -1), params["b0"], params["offset"], params["angle"][:, None]]
        parts += [params["scale"], params["shear"][:, None]]
        parts += [params["axis"]] if self.d == 3 else []
        parts.append(np.broadcast_to(np.array([v for key in WINDOWS for v in self._win[key]]), (B, 8)))
        return np.ascontiguousarray(np.concatenate(parts, axis=1), dtype=np.float64)

    def reference(self, params: dict[str, Array], t: Array) -> tuple[Array, Array]:
        out = np.empty((t.shape[0], self.d, self.d + 1))
        _pose_rows(self.goal_vector(params), np.asarray(t, dtype=np.float64), out)
        return out[:, :, : self.d], out[:, :, self.d]
