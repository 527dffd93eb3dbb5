"""``hold``: reach a target affine image of the nominal configuration and hold it (2D or 3D).

Per episode (uniform draws from the seed's generator; ranges are keyword arguments):

* World box [-5, 5]^d.
* Start: Theta0 a rotation (2D angle in [-pi, pi]; 3D a random axis and angle), b0 in [-1, 1]^d;
  leaders on the start pose at rest, followers there plus up to ``follower_noise`` = 0.3 m.
* Goal: Theta_g = rotation . shear . diag(scale) with angle in [-pi/2, pi/2], shear of axis 0 by
  axis 1 in [-0.3, 0.3], each scale factor in [0.6, 1.4]; b_g in [-2, 2]^d.

``route="turn"`` (2D) makes the ``approach`` reward's route a turn instead of a straight line: each agent goes
with the team's centroid, and round it by the team's rotation (see :func:`turn_route`). Straight lines
through the centroid collapse the formation on large rotations; the turn keeps it apart.

``start="paper"`` reproduces the paper's simulation (Section 4.3) on its 5-agent framework:
leaders at r_1..r_3, followers at (-4, 3) and (-3, -2), goal the nominal pose (Theta = I, b = 0).

Success: every agent within ``goal_tol`` = 0.15 m of Theta_g r_i + b_g and the formation error
below ``formation_tol`` = 0.05 m for ``hold_steps`` = 10 consecutive samples; it terminates the episode.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import numpy as np

from formation_env.core.errors import FormationError

from .._numba import jit
from ..kernel import straight_route
from ._base import Array, Draw, Scenario, check_range, rotation_2d, rotation_3d

__all__ = ["Hold"]

PAPER_FOLLOWER_START = np.array([[-4.0, 3.0], [-3.0, -2.0]])


@jit
def turn_route(pvec: Array, radius: float, pos: Array, goal: Array, out: Array) -> None:  # pragma: no cover
    """``route="turn"``: the centroid's straight path |c_g - c|, then round the centroid: with p_i = x_i - c,
    q_i = x_i* - c_g, radius r_i = (|p_i| + |q_i|) / 2 and turn delta_i (from p_i to q_i, on the side of the
    team's least-squares rotation phi = atan2(sum p_i x q_i, sum p_i . q_i)), the spiral's length
    sqrt((|q_i| - |p_i|)^2 + (r_i delta_i)^2). pos, goal (n, 2) -> out (n,), m."""
    n = pos.shape[0]
    c, cg = pos.sum(axis=0) / n, goal.sum(axis=0) / n
    cross_sum = dot_sum = 0.0
    for i in range(n):
        px, py, qx, qy = pos[i, 0] - c[0], pos[i, 1] - c[1], goal[i, 0] - cg[0], goal[i, 1] - cg[1]
        cross_sum += px * qy - py * qx
        dot_sum += px * qx + py * qy
    phi = math.atan2(cross_sum, dot_sum)
    shift = math.hypot(cg[0] - c[0], cg[1] - c[1])
    for i in range(n):
        px, py, qx, qy = pos[i, 0] - c[0], pos[i, 1] - c[1], goal[i, 0] - cg[0], goal[i, 1] - cg[1]
        own = math.atan2(px * qy - py * qx, px * qx + py * qy)  # each agent's own turn, in (-pi, pi]
        x = own - phi + math.pi
        delta = phi + (x - 2.0 * math.pi * math.floor(x / (2.0 * math.pi))) - math.pi  # on the team's side
        rp, rq = math.hypot(px, py), math.hypot(qx, qy)
        out[i] = shift + math.hypot(rq - rp, 0.5 * (rp + rq) * delta)


class Hold(Scenario):
    """Reach and hold a random affine image of r (see the module docstring)."""

    name: ClassVar[str] = "hold"
    dims: ClassVar[tuple[int, ...]] = (2, 3)
    half_size: ClassVar[tuple[float, ...]] = (5.0, 5.0, 5.0)
    grows_world: ClassVar[bool] = True
    planner: ClassVar[str | None] = "agents.planner:HoldPlanner"
    follower_noise: float = 0.3
    weights: ClassVar[dict[str, float]] = {"distance": 0.1}
    goal_tol_default: ClassVar[float] = 0.15
    hold_steps_default: ClassVar[int] = 10

    def _init(self, kw: dict[str, Any]) -> None:
        self.start = str(kw.pop("start", "random"))
        if self.start not in ("random", "paper"):
            raise FormationError(f"hold: start must be 'random' or 'paper', got {self.start!r}")
        if self.start == "paper" and (self.fw.n, self.d, self.fw.leaders) != (5, 2, (0, 1, 2)):
            raise FormationError("hold: start='paper' needs the paper's 5-agent framework (framework='paper')")
        self.start_b = check_range("start_b", kw.pop("start_b", (-1.0, 1.0)))
        self.goal_b = check_range("goal_b", kw.pop("goal_b", (-2.0, 2.0)))
        self.goal_angle = check_range("goal_angle", kw.pop("goal_angle", (-np.pi / 2, np.pi / 2)))
        self.goal_scale = check_range("goal_scale", kw.pop("goal_scale", (0.6, 1.4)), lo=1e-9)
        self.goal_shear = check_range("goal_shear", kw.pop("goal_shear", (-0.3, 0.3)))
        self.route = kw.pop("route", "straight")
        if self.route not in ("straight", "turn") or (self.route == "turn" and self.d != 2):
            raise FormationError(f"hold: route must be 'straight', or 'turn' in 2D, got {self.route!r} (d = {self.d})")

    def draws(self) -> list[Draw]:
        d, pi = self.d, np.pi
        axis = self.d == 3
        out = [Draw("angle0", bounds=(-pi, pi))]
        out += [Draw("axis0", (3,), "normal")] if axis else []
        out += [
            Draw("b0", (d,), bounds=self.start_b),
            Draw("scale", (d,), bounds=self.goal_scale),
            Draw("shear", bounds=self.goal_shear),
            Draw("angle_g", bounds=self.goal_angle),
        ]
        out += [Draw("axis_g", (3,), "normal")] if axis else []
        out += [Draw("b_g", (d,), bounds=self.goal_b)]
        return out + (self.follower_draws() if self.start == "random" else [])

    @property
    def route_row(self) -> Any:
        """The ``approach`` potential's route: :func:`turn_route` for ``route="turn"``, else straight."""
        return turn_route if self.route == "turn" else straight_route

    def build(self, raw: dict[str, Array]) -> tuple[dict[str, Array], tuple[Array, Array] | None]:
        d = self.d
        B = raw["b0"].shape[0]
        if d == 2:
            th0, rot_g = rotation_2d(raw["angle0"]), rotation_2d(raw["angle_g"])
        else:
            th0, rot_g = rotation_3d(raw["axis0"], raw["angle0"]), rotation_3d(raw["axis_g"], raw["angle_g"])
        sh = np.broadcast_to(np.eye(d), (B, d, d)).copy()
        sh[:, 0, 1] = raw["shear"]
        thg = rot_g @ sh @ (raw["scale"][:, :, None] * np.eye(d))
        params = {"goal_theta": thg, "goal_b": raw["b_g"]}
        if self.start == "paper":
            start = np.broadcast_to(self.r, (B, 5, 2)).copy()
            start[:, 3:] = PAPER_FOLLOWER_START
            params.update(start=start, goal_theta=np.broadcast_to(np.eye(2), (B, 2, 2)).copy(), goal_b=np.zeros((B, 2)))
            return params, None
        return params, (th0, raw["b0"])
