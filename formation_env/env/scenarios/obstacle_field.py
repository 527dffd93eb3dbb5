"""``obstacle_field``: cross a field of scattered circular (3D: spherical) obstacles to a goal pose.

Per episode (uniform draws; ranges are keyword arguments):

* World box x in [-7, 7], other axes in [-5, 5].
* ``n_obstacles`` = 6 obstacles, centres with x in [-1.5, 1.0] and the other coordinates in
  [-4, 4] (``obstacle_y``), radii in [0.3, 0.6] m; they may overlap. Start and goal regions are clear of them.
* Start pose: rotation by psi0 in [-pi/12, pi/12] (3D: about z), b0 with x in [-4.5, -4], the rest
  in [-1.5, 1.5]; goal pose: rotation by psi_g in the same range, b_g with x in [4, 4.5].

Gaps between obstacles are often narrower than the nominal formation: rotating, shearing or scaling it helps.
Contact: an agent's path within ``agent_radius`` of an obstacle. Success (and its end) as in ``narrow_passage``.

Task features (the optional ``task`` observation block, 2D, per leader, m). The discs' shadows on the y axis,
[y_c - r, y_c + r], leave free lanes in the world's height, straight corridors along x that cross the field
without meeting a disc. The block holds the field's near and far x (min x_c - r and max x_c + r) minus the
leader's x, then, for ``N_LANES`` lanes, its centre's y minus the formation's fitted b_y and the room left in it:
half its width minus the team's half-height with the discs (negative: the formation must shrink to pass). The
first lane is the route's (below), the others the widest, widest first. A missing lane reads centre 0 and room
-2 H (H the world's height).

The route's lane: of the lanes at least ``LANE_WIDTH`` wide, the one whose routes sum least over the team, each
agent's route running straight to the lane, along it across the field (its disc ``ROUTE_MARGIN`` from the lane's
edges), then straight to its goal (:func:`route_lanes`). ``route="lane"`` (2D) makes the ``approach`` reward's
route go that way instead of straight to the goal (:func:`lane_route`); with no such lane it stays straight.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from formation_env.core.errors import FormationError

from .._numba import jit
from ..kernel import straight_route, team_half_height
from ..obstacles import Circle
from ._base import Array, Draw, EpisodeParam, Scenario, check_range, rotation_2d, rotation_3d

__all__ = ["HALF_HEIGHT", "LANE_WIDTH", "N_LANES", "ROUTE_MARGIN", "ObstacleField"]

#: Lanes in the ``task`` block (the route's lane, then the widest, widest first).
N_LANES = 3


#: Room (m) the ``approach`` reward's route keeps between an agent's disc and a lane's edges.
ROUTE_MARGIN = 0.05
#: Narrowest lane (m) the route takes: the passage's narrowest gap, which the team passes at half its height.
LANE_WIDTH = 1.0
#: Half the world's height (m, y in [-HALF_HEIGHT, HALF_HEIGHT]; the scenario's ``half_size``): the route's lanes lie
#: inside it.
HALF_HEIGHT = 5.0


@jit
def _order(key: Array, m: int) -> NDArray[np.int64]:  # pragma: no cover
    """Indices that sort key[:m] ascending, ties in index order (an insertion sort: m is a handful)."""
    idx = np.arange(m)
    for i in range(1, m):
        j, k = i, idx[i]
        while j > 0 and key[idx[j - 1]] > key[k]:
            idx[j] = idx[j - 1]
            j -= 1
        idx[j] = k
    return idx


@jit
def field_lanes(circles: Array, y_lo: float, y_hi: float) -> tuple[float, float, Array, Array]:  # pragma: no cover
    """The field of circles (C * 3,) as (x, y, r): its near and far x (min x - r, max x + r; 0 without
    circles) and its free lanes in [y_lo, y_hi], the parts outside every circle's shadow [y - r, y + r]
    (m), as (lane_lo, lane_hi) (m,) each, widest first."""
    c = circles.shape[0] // 3
    x_near, x_far = (np.inf, -np.inf) if c else (0.0, 0.0)
    shadow_lo, shadow_hi = np.empty(c), np.empty(c)
    for j in range(c):
        x, y, r = circles[3 * j], circles[3 * j + 1], circles[3 * j + 2]
        x_near, x_far = min(x_near, x - r), max(x_far, x + r)
        shadow_lo[j], shadow_hi[j] = y - r, y + r
    lane_lo, lane_hi = np.empty(c + 1), np.empty(c + 1)
    m, top = 0, y_lo  # swept bottom to top
    for j in _order(shadow_lo, c):
        if shadow_lo[j] > top:
            lane_lo[m], lane_hi[m] = top, shadow_lo[j]
            m += 1
        top = max(top, shadow_hi[j])
    if y_hi > top:
        lane_lo[m], lane_hi[m] = top, y_hi
        m += 1
    order = _order(lane_lo - lane_hi, m)
    return x_near, x_far, lane_lo[order], lane_hi[order]


@jit
def task_row(  # pragma: no cover
    b: int, out: Array, lo: int, leaders: NDArray[np.int64], pos: Array, goal: Array, pvec: Array, bfit: Array,
    radius: float, bounds: Array,
) -> None:  # fmt: skip
    """The ``task`` block (the module docstring): field's near and far x minus x_i, then per lane of
    ``N_LANES``, the route's lane first, its centre minus b_y and the room left (m). pvec = circles (C * 3,) as
    (x, y, r)."""
    half = team_half_height(pos[b], radius)
    x_near, x_far, lane_lo, lane_hi = route_lanes(pvec[b], radius, pos[b], goal[b], bounds[0, 1], bounds[1, 1])
    no_room = -2.0 * (bounds[1, 1] - bounds[0, 1])
    for i, a in enumerate(leaders):
        out[i, lo] = x_near - pos[b, a, 0]
        out[i, lo + 1] = x_far - pos[b, a, 0]
        for q in range(N_LANES):
            there = q < lane_lo.shape[0]
            out[i, lo + 2 + 2 * q] = 0.5 * (lane_lo[q] + lane_hi[q]) - bfit[b, 1] if there else 0.0
            out[i, lo + 3 + 2 * q] = 0.5 * (lane_hi[q] - lane_lo[q]) - half if there else no_room


@jit
def _lane_route(x_near: float, x_far: float, y_lo: float, y_hi: float, p: Array, g: Array) -> float:  # pragma: no cover
    """One agent's route length (m) from p to g (2,) through the lane whose disc-centre room is [y_lo, y_hi]:
    before the field straight to (x_near, y*), y* the straight line's crossing clipped to the room, along the
    lane to (x_far, y*), then straight to g; in the field across to y*, along, then to g; beyond, straight."""
    if p[0] > x_far:
        return math.hypot(g[0] - p[0], g[1] - p[1])
    if p[0] < x_near:
        frac = min(max((x_near - p[0]) / max(g[0] - p[0], 1e-9), 0.0), 1.0)
        ys = min(max(p[1] + frac * (g[1] - p[1]), y_lo), y_hi)
        return math.hypot(x_near - p[0], ys - p[1]) + (x_far - x_near) + math.hypot(g[0] - x_far, g[1] - ys)
    ys = min(max(p[1], y_lo), y_hi)
    return abs(ys - p[1]) + (x_far - p[0]) + math.hypot(g[0] - x_far, g[1] - ys)


@jit
def _team_routes(  # pragma: no cover
    x_near: float, x_far: float, lane_lo: float, lane_hi: float, radius: float, pos: Array, goal: Array, out: Array
) -> float:
    """Every agent's route (:func:`_lane_route`) from ``pos`` to ``goal`` (n, 2) through the lane [lane_lo, lane_hi]
    (its disc ``ROUTE_MARGIN`` from the edges) into ``out`` (n,), m; returns their sum."""
    room_lo, room_hi = lane_lo + radius + ROUTE_MARGIN, lane_hi - radius - ROUTE_MARGIN
    total = 0.0
    for i in range(pos.shape[0]):
        out[i] = _lane_route(x_near, x_far, room_lo, room_hi, pos[i], goal[i])
        total += out[i]
    return total


@jit
def route_lanes(  # pragma: no cover
    pvec: Array, radius: float, pos: Array, goal: Array, y_lo: float, y_hi: float
) -> tuple[float, float, Array, Array]:
    """The field's near and far x and its free lanes in [y_lo, y_hi] (:func:`field_lanes`), the route's lane
    first: of the lanes at least ``LANE_WIDTH`` wide, the one whose routes (:func:`_team_routes`) from ``pos`` to
    ``goal`` (n, 2) sum least over the team; then the others, widest first (all widest first when no lane is
    that wide). pvec = circles (C * 3,)."""
    x_near, x_far, lane_lo, lane_hi = field_lanes(pvec, y_lo, y_hi)
    best, pick = np.inf, -1
    scratch = np.empty(pos.shape[0])
    for q in range(lane_lo.shape[0]):
        if lane_hi[q] - lane_lo[q] >= LANE_WIDTH:
            total = _team_routes(x_near, x_far, lane_lo[q], lane_hi[q], radius, pos, goal, scratch)
            if total < best:
                best, pick = total, q
    if pick > 0:
        first_lo, first_hi = lane_lo[pick], lane_hi[pick]
        lane_lo[1 : pick + 1], lane_hi[1 : pick + 1] = lane_lo[:pick].copy(), lane_hi[:pick].copy()
        lane_lo[0], lane_hi[0] = first_lo, first_hi
    return x_near, x_far, lane_lo, lane_hi


@jit
def lane_route(pvec: Array, radius: float, pos: Array, goal: Array, out: Array) -> None:  # pragma: no cover
    """``route="lane"`` (2D): through the route's lane of :func:`route_lanes` (lanes in the world's height,
    y in [-HALF_HEIGHT, HALF_HEIGHT]); straight without circles or without a lane ``LANE_WIDTH`` wide.
    pvec = circles (C * 3,), pos, goal (n, 2) -> out (n,), m."""
    if pvec.shape[0] == 0:
        straight_route(pvec, radius, pos, goal, out)
        return
    x_near, x_far, lane_lo, lane_hi = route_lanes(pvec, radius, pos, goal, -HALF_HEIGHT, HALF_HEIGHT)
    if lane_lo.shape[0] == 0 or lane_hi[0] - lane_lo[0] < LANE_WIDTH:
        straight_route(pvec, radius, pos, goal, out)
    else:
        _team_routes(x_near, x_far, lane_lo[0], lane_hi[0], radius, pos, goal, out)


class ObstacleField(Scenario):
    """Reach the goal pose through scattered obstacles (see the module docstring)."""

    name: ClassVar[str] = "obstacle_field"
    dims: ClassVar[tuple[int, ...]] = (2, 3)
    half_size: ClassVar[tuple[float, ...]] = (7.0, HALF_HEIGHT, HALF_HEIGHT)
    obstacle_types = (Circle,)
    planner: ClassVar[str | None] = "agents.planner:FieldPlanner"
    follower_noise: float = 0.1

    def _init(self, kw: dict[str, Any]) -> None:
        n_obs = kw.pop("n_obstacles", 6)
        if isinstance(n_obs, bool) or not isinstance(n_obs, (int, np.integer)) or n_obs < 0:
            raise FormationError(f"obstacle_field: n_obstacles must be an integer >= 0, got {n_obs!r}")
        self.n_obstacles = int(n_obs)
        self.obstacle_x = check_range("obstacle_x", kw.pop("obstacle_x", (-1.5, 1.0)))
        self.obstacle_y = check_range("obstacle_y", kw.pop("obstacle_y", (-4.0, 4.0)))
        self.obstacle_radius = check_range("obstacle_radius", kw.pop("obstacle_radius", (0.3, 0.6)), lo=0.0)
        self.start_x = check_range("start_x", kw.pop("start_x", (-4.5, -4.0)))
        self.goal_x = check_range("goal_x", kw.pop("goal_x", (4.0, 4.5)))
        self.lateral = check_range("lateral", kw.pop("lateral", (-1.5, 1.5)))
        self.angle = check_range("angle", kw.pop("angle", (-np.pi / 12, np.pi / 12)))
        self.route = kw.pop("route", "straight")
        if self.route not in ("straight", "lane") or (self.route == "lane" and self.d != 2):
            raise FormationError(
                f"obstacle_field: route must be 'straight', or 'lane' in 2D, got {self.route!r} (d = {self.d})"
            )

    def draws(self) -> list[Draw]:
        d, c = self.d, self.n_obstacles
        return [
            Draw("obstacle_x", (c, 1), bounds=self.obstacle_x),
            Draw("obstacle_y", (c, d - 1), bounds=self.obstacle_y),
            Draw("obstacle_radius", (c, 1), bounds=self.obstacle_radius),
            Draw("angle0", bounds=self.angle),
            Draw("start_x", (1,), bounds=self.start_x),
            Draw("start_lateral", (d - 1,), bounds=self.lateral),
            Draw("angle_g", bounds=self.angle),
            Draw("goal_x", (1,), bounds=self.goal_x),
            Draw("goal_lateral", (d - 1,), bounds=self.lateral),
            *self.follower_draws(),
        ]

    def _rotation(self, angle: Array) -> Array:
        if self.d == 2:
            return rotation_2d(angle)
        return rotation_3d(np.tile([0.0, 0.0, 1.0], (angle.shape[0], 1)), angle)

    def build(self, raw: dict[str, Array]) -> tuple[dict[str, Array], tuple[Array, Array] | None]:
        circles = np.concatenate([raw["obstacle_x"], raw["obstacle_y"], raw["obstacle_radius"]], -1)
        b0 = np.concatenate([raw["start_x"], raw["start_lateral"]], -1)
        bg = np.concatenate([raw["goal_x"], raw["goal_lateral"]], -1)
        params = {
            "goal_theta": self._rotation(raw["angle_g"]),
            "goal_b": bg,
            "circles": circles,
        }
        return params, (self._rotation(raw["angle0"]), b0)

    task_row = staticmethod(task_row)

    @property
    def route_row(self) -> Any:
        """The ``approach`` potential's route: :func:`lane_route` for ``route="lane"``, else straight."""
        return lane_route if self.route == "lane" else straight_route

    def task_feature_bounds(self) -> tuple[Array, Array]:
        if self.d != 2:
            raise FormationError("obstacle_field: the task observation block is defined in 2D only")
        ext = self.bounds[1] - self.bounds[0]
        lane_lo, lane_hi = np.array([-ext[1], -2.0 * ext[1]]), np.array([ext[1], ext[1]])
        lo = np.concatenate([-ext[[0, 0]], np.tile(lane_lo, N_LANES)])
        hi = np.concatenate([ext[[0, 0]], np.tile(lane_hi, N_LANES)])
        return lo, hi

    def episode_params(self) -> list[EpisodeParam]:
        d = self.d
        low = [self.obstacle_x[0]] + [self.obstacle_y[0]] * (d - 1) + [self.obstacle_radius[0]]
        high = [self.obstacle_x[1]] + [self.obstacle_y[1]] * (d - 1) + [self.obstacle_radius[1]]
        return [EpisodeParam("circles", (self.n_obstacles, d + 1), low, high)]
