"""``narrow_passage``: shrink through a gap in a wall, restore the shape, reach the goal pose (2D).

Geometry (metres, per episode drawn uniformly from the seed's generator; ranges are keyword arguments):

* World box x in [-7, 7], y in [-5, 5]; an agent centre leaving it is a collision.
* A wall on the line x = ``wall_x`` in [-0.5, 0.5] spanning the world's height, with one gap
  centred at y = ``gap_center`` in [-1, 1] of width ``gap_width`` in [1.0, 1.6]; the wall is
  two zero-thickness segments (x_w, -5)-(x_w, y_c - w/2) and (x_w, y_c + w/2)-(x_w, 5).
* Agents are discs of radius ``agent_radius`` (default 0.1). The default framework (the
  paper's, nominal y-extent 2 m, so 2.2 m wide with the discs) is wider than any gap: the team
  must scale down along y (Theta = diag(1, s), s <= (w - 2 radius) / 2) to pass.
* Start pose: Theta0 = rotation(psi0), psi0 in [-pi/12, pi/12], b0 with x in [-4.5, -3.5],
  y in [-1.5, 1.5]; leaders at Theta0 r_l + b0 at rest, followers there plus up to 0.1 m noise.
* Goal pose: Theta_g = rotation(psi_g), psi_g in [-pi/12, pi/12], b_g with x in [3.5, 4.5],
  y in [-1.5, 1.5]: beyond the wall, the nominal shape (restored).

Contact: an agent centre within ``agent_radius`` of a segment, or a step crossing one. Success (it terminates
the episode): no contact and every agent within ``goal_tol`` = 0.2 m of its goal position Theta_g r_i + b_g, the
formation error below ``formation_tol`` = 0.05 m. ``agents.scripted.passage_action`` (move to the gap, shrink,
pass, restore, go to the goal) shows in the tests that every episode is solvable.

Task features (the optional ``task`` observation block, per leader, m): the wall's x minus the leader's
x, the gap centre's y minus the formation's fitted b_y, and the gap's half-width minus the formation's
half-extent along y with the discs (the room left; negative: the formation must shrink to pass).
"""

from __future__ import annotations

import math
import warnings
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from .._numba import jit
from ..kernel import team_half_height
from ..obstacles import Segment
from ._base import Array, Draw, EpisodeParam, Scenario, check_range, rotation_2d

__all__ = ["ROUTE_MARGIN", "NarrowPassage"]

#: Room (m) the ``approach`` reward's route keeps between an agent's disc and the gap's edges.
ROUTE_MARGIN = 0.05


@jit
def task_row(  # pragma: no cover
    b: int, out: Array, lo: int, leaders: NDArray[np.int64], pos: Array, pvec: Array, bfit: Array, radius: float
) -> None:
    """The ``task`` block: wall_x - x_i, gap_center - b_y (b the affine fit's translation), and the room left
    in the gap, gap_width / 2 minus the team's half-height with the discs (m)."""
    half = team_half_height(pos[b], radius)
    for i, a in enumerate(leaders):
        out[i, lo] = pvec[b, 0] - pos[b, a, 0]
        out[i, lo + 1] = pvec[b, 1] - bfit[b, 1]
        out[i, lo + 2] = 0.5 * pvec[b, 2] - half


@jit
def route_row(pvec: Array, radius: float, pos: Array, goal: Array, out: Array) -> None:  # pragma: no cover
    """Through the gap: an agent before the wall goes straight to the crossing point (x_w, y*), y* the
    straight line's crossing clipped to the part of the gap its disc fits through with ``ROUTE_MARGIN`` m
    to spare, then straight to its goal; beyond the wall, straight. pvec = (wall_x, gap_center, gap_width),
    pos, goal (n, 2) -> out (n,), m."""
    xw, yc, w = pvec[0], pvec[1], pvec[2]
    room = max(0.5 * w - radius - ROUTE_MARGIN, 0.0)
    for i in range(pos.shape[0]):
        px, py, gx, gy = pos[i, 0], pos[i, 1], goal[i, 0], goal[i, 1]
        if px < xw:
            frac = min(max((xw - px) / max(gx - px, 1e-9), 0.0), 1.0)
            ys = min(max(py + frac * (gy - py), yc - room), yc + room)
            out[i] = math.hypot(xw - px, ys - py) + math.hypot(gx - xw, gy - ys)
        else:
            out[i] = math.hypot(gx - px, gy - py)


class NarrowPassage(Scenario):
    """Pass a gap narrower than the formation (see the module docstring for geometry and success)."""

    name: ClassVar[str] = "narrow_passage"
    half_size: ClassVar[tuple[float, ...]] = (7.0, 5.0)
    obstacle_types = (Segment,)
    planner: ClassVar[str | None] = "agents.planner:PassagePlanner"
    follower_noise: float = 0.1

    def _init(self, kw: dict[str, Any]) -> None:
        self.wall_x = check_range("wall_x", kw.pop("wall_x", (-0.5, 0.5)))
        self.gap_center = check_range("gap_center", kw.pop("gap_center", (-1.0, 1.0)))
        self.gap_width = check_range("gap_width", kw.pop("gap_width", (1.0, 1.6)), lo=1e-9)
        self.start_x = check_range("start_x", kw.pop("start_x", (-4.5, -3.5)))
        self.start_y = check_range("start_y", kw.pop("start_y", (-1.5, 1.5)))
        self.goal_x = check_range("goal_x", kw.pop("goal_x", (3.5, 4.5)))
        self.goal_y = check_range("goal_y", kw.pop("goal_y", (-1.5, 1.5)))
        self.angle = check_range("angle", kw.pop("angle", (-np.pi / 12, np.pi / 12)))
        width = float(np.ptp(self.r[:, 1])) + 2 * self.agent_radius
        if width <= self.gap_width[1]:
            warnings.warn(
                f"narrow_passage: the nominal formation ({width:.3g} m wide with the discs) fits through gaps up to "
                f"{self.gap_width[1]:.3g} m without shrinking",
                stacklevel=3,
            )

    def draws(self) -> list[Draw]:
        return [
            Draw("wall_x", bounds=self.wall_x),
            Draw("gap_center", bounds=self.gap_center),
            Draw("gap_width", bounds=self.gap_width),
            Draw("start_x", bounds=self.start_x),
            Draw("start_y", bounds=self.start_y),
            Draw("angle0", bounds=self.angle),
            Draw("goal_x", bounds=self.goal_x),
            Draw("goal_y", bounds=self.goal_y),
            Draw("angle_g", bounds=self.angle),
            *self.follower_draws(),
        ]

    def build(self, raw: dict[str, Array]) -> tuple[dict[str, Array], tuple[Array, Array] | None]:
        wall, yc, w = raw["wall_x"], raw["gap_center"], raw["gap_width"]
        B = wall.shape[0]
        b0 = np.stack([raw["start_x"], raw["start_y"]], -1)
        bg = np.stack([raw["goal_x"], raw["goal_y"]], -1)
        lo, hi = self.bounds[0, 1], self.bounds[1, 1]
        seg = np.empty((B, 2, 2, 2))
        seg[:, :, :, 0] = wall[:, None, None]
        seg[:, 0, 0, 1], seg[:, 0, 1, 1] = lo, yc - w / 2
        seg[:, 1, 0, 1], seg[:, 1, 1, 1] = yc + w / 2, hi
        params = {
            "goal_theta": rotation_2d(raw["angle_g"]),
            "goal_b": bg,
            "segments": seg,
            "wall_x": wall,
            "gap_center": yc,
            "gap_width": w,
        }
        return params, (rotation_2d(raw["angle0"]), b0)

    def episode_params(self) -> list[EpisodeParam]:
        return [EpisodeParam(nm, (), *getattr(self, nm)) for nm in ("wall_x", "gap_center", "gap_width")]

    task_row = staticmethod(task_row)
    route_row = staticmethod(route_row)

    def task_feature_bounds(self) -> tuple[Array, Array]:
        ext = self.bounds[1] - self.bounds[0]
        return -ext[[0, 1, 1]], ext[[0, 1, 1]]
