"""``moving_obstacles``: cross lanes of discs moving at constant velocity, restore the shape, reach the goal (2D).

Geometry (metres and seconds, per episode drawn uniformly from the seed's generator; ranges are keyword
arguments):

* World box x in [-8, 8], y in [-5, 5]; an agent centre leaving it is a collision.
* ``n_moving`` = 3 discs (:class:`~formation_env.env.obstacles.MovingCircle`), disc j in the lane x_j =
  ``lanes``[j] + jitter, lanes evenly spaced over [-2, 2] (for 3 discs: -2, 0, 2), jitter in
  [-0.15, 0.15]; radius in ``moving_radius`` = [0.3, 0.5]; start y in [-4, 4]; velocity (0, v_y), the
  speed |v_y| in ``moving_speed`` = [0.5, 1.0] m/s with a random sign. A disc bounces elastically off the
  world box (its rim against the box's faces: it turns at y = +-(5 - radius)), so it sweeps its lane up and
  down for the whole episode with period 2 (10 - 2 radius) / |v_y|, 18-37 s.
* Agents are discs of radius ``agent_radius`` (default 0.1).
* Start pose: Theta0 = rotation(psi0), psi0 in [-pi/12, pi/12], b0 with x in [-5.5, -4.5], y in [-1, 1];
  leaders at Theta0 r_l + b0 at rest, followers there plus up to 0.1 m noise. With the default (paper)
  framework, r_x in [-2, 1], the start lies left of x = -3.3 and clear of every lane.
* Goal pose: Theta_g = rotation(psi_g), psi_g in [-pi/12, pi/12], b_g with x in [5, 5.5], y in [-1, 1]: the
  nominal shape, right of every lane (agents at x > 2.9).

The team, about 3 m long and 2 m wide, cannot slip between two lanes: it must time its crossing between
the discs' passes, shrinking (scaling) or rotating to narrow the band it sweeps, or wait for a gap.

Contact: an agent centre within ``agent_radius`` of a disc's rim, at a sample or along the step (relative to
the moving disc). Success as in ``narrow_passage``. ``agents.scripted.crossing_action`` (shrink, wait until the
crossing is predicted clear, cross, restore, go to the goal) shows in the tests that episodes are solvable. The
global state carries each disc's current centre, velocity and radius.

Task features (the optional ``task`` observation block, 2D, per leader; m, m/s). Per disc, in lane order: its
lane's x minus the leader's x, its centre's y minus the formation's fitted b_y, its velocity along y, then the
room it leaves the team's band now and ``FORECAST`` seconds ahead (on its bouncing path):
|y_c(t + tau) - b_y| minus its radius and the team's half-height with the agents' discs. Negative room: the disc
is in the band the team sweeps, so crossing its lane then would meet it.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from formation_env.core.errors import FormationError

from .._numba import jit
from ..kernel import team_half_height
from ..observations import observation_block
from ..obstacles import MovingCircle, bounce_axis
from ._base import Array, Draw, Scenario, check_range, rotation_2d

__all__ = ["FORECAST", "WINDOW_HORIZON", "MovingObstacles", "crossing_windows"]

#: Look-ahead times (s) of the ``task`` block's room entries (0: now).
FORECAST = (0.0, 1.0, 2.0, 3.0)
_FORECAST = np.array(FORECAST)
#: Entries per disc in the ``task`` block: lane x, centre y, velocity y, then the room at each look-ahead.
_PER_DISC = 3 + len(FORECAST)
#: Horizon H (s) of the ``crossing_windows`` block: a time it does not find within H reads H.
WINDOW_HORIZON = 6.0
#: Grid step (s) on which ``crossing_windows`` scans a disc's path (the crossing itself is interpolated on it).
_WINDOW_STEP = 0.1


@jit
def task_row(  # pragma: no cover
    b: int, out: Array, lo: int, leaders: NDArray[np.int64], pos: Array, bfit: Array, radius: float, now: Array,
    mov_p0: Array, bounds: Array,
) -> None:  # fmt: skip
    """The ``task`` block (the module docstring). mov_p0 (B, M, 5): each disc's start centre, velocity, radius."""
    half = team_half_height(pos[b], radius)
    for j in range(mov_p0.shape[1]):
        c0x, c0y, vx, vy, r = mov_p0[b, j]
        x = bounce_axis(c0x, vx, r, bounds[0, 0], bounds[1, 0], now[b])[0]
        y, v_y = bounce_axis(c0y, vy, r, bounds[0, 1], bounds[1, 1], now[b])
        k = lo + _PER_DISC * j
        for i, a in enumerate(leaders):
            out[i, k] = x - pos[b, a, 0]
            out[i, k + 1] = y - bfit[b, 1]
            out[i, k + 2] = v_y
        for q in range(_FORECAST.shape[0]):
            room = abs(bounce_axis(c0y, vy, r, bounds[0, 1], bounds[1, 1], now[b] + _FORECAST[q])[0] - bfit[b, 1])
            for i in range(leaders.shape[0]):
                out[i, k + 3 + q] = room - r - half


def _window_count(engine: Any) -> int:
    sc = engine.scenario
    if not isinstance(sc, MovingObstacles):
        raise FormationError(f"observation block 'crossing_windows' reads moving_obstacles' lanes of discs; the "
                             f"scenario is {sc.name!r}")  # fmt: skip
    return 4 * sc.n_moving


@observation_block(
    "crossing_windows", _window_count,
    lambda e: (np.zeros(_window_count(e)), np.full(_window_count(e), WINDOW_HORIZON)),
    "``moving_obstacles``, per disc in lane order (s, within H = 6 s; H: not within H): when it next enters and "
    "then leaves the band of y the team sweeps now (its fitted b_y +- its half-height with the agents' discs), "
    "and when the team, at its mean x-velocity now, reaches and leaves the disc's strip of x (0 once passed)",
    size_text="4 M", bounds_text="[0, H]",
)  # fmt: skip
def crossing_windows(  # pragma: no cover
    b: int, out: Array, lo: int, leaders: NDArray[np.int64], pos: Array, vel: Array, bfit: Array, radius: float,
    now: Array, mov_p0: Array, bounds: Array,
) -> None:  # fmt: skip
    """Per disc j: entries 4 j .. 4 j + 3 of every leader's row (they are the team's, the same for each leader).

    The disc blocks the band while its room, |y_c(t) - b_y| - r - half, is negative; the room is piecewise linear
    in t (a triangle wave), so the times are the grid's sign changes on a 0.1 s grid, interpolated. The team
    occupies x in [min x - radius, max x + radius]; at its mean x-velocity v_x > 0 it reaches the strip
    [x_j - r, x_j + r] after (x_j - r - front) / v_x and leaves it after (x_j + r - back) / v_x (0 if already
    reached or left; H if v_x <= 0.01 m/s and not yet in it)."""
    H = WINDOW_HORIZON
    dt = _WINDOW_STEP
    steps = round(H / dt)
    half = team_half_height(pos[b], radius)
    by = bfit[b, 1]
    front, back, vx = -np.inf, np.inf, 0.0
    n = pos.shape[1]
    for a in range(n):
        front = max(front, pos[b, a, 0] + radius)
        back = min(back, pos[b, a, 0] - radius)
        vx += vel[b, a, 0] / n
    for j in range(mov_p0.shape[1]):
        c0x, c0y, vdx, vdy, r = mov_p0[b, j]
        x = bounce_axis(c0x, vdx, r, bounds[0, 0], bounds[1, 0], now[b])[0]
        t_in, t_out = H, H
        prev = abs(bounce_axis(c0y, vdy, r, bounds[0, 1], bounds[1, 1], now[b])[0] - by) - r - half
        if prev < 0.0:
            t_in = 0.0
        for q in range(1, steps + 1):
            room = abs(bounce_axis(c0y, vdy, r, bounds[0, 1], bounds[1, 1], now[b] + q * dt)[0] - by) - r - half
            crossed = (room < 0.0) != (prev < 0.0)
            if crossed:
                t = (q - 1) * dt + dt * prev / (prev - room)
                if t_in == H and room < 0.0:
                    t_in = t
                elif t_in < H and room >= 0.0:
                    t_out = t
                    break
            prev = room
        if back >= x + r:  # passed
            reach, leave = 0.0, 0.0
        elif vx <= 0.01:
            reach, leave = (0.0 if front >= x - r else H), H
        else:
            reach, leave = max(0.0, (x - r - front) / vx), (x + r - back) / vx
        for i in range(leaders.shape[0]):
            out[i, lo + 4 * j] = t_in
            out[i, lo + 4 * j + 1] = t_out
            out[i, lo + 4 * j + 2] = min(reach, H)
            out[i, lo + 4 * j + 3] = min(leave, H)


class MovingObstacles(Scenario):
    """Cross lanes of moving discs (see the module docstring for geometry and success)."""

    name: ClassVar[str] = "moving_obstacles"
    half_size: ClassVar[tuple[float, ...]] = (8.0, 5.0)
    obstacle_types = (MovingCircle,)
    planner: ClassVar[str | None] = "agents.planner:CrossingPlanner"
    follower_noise: float = 0.1

    def _init(self, kw: dict[str, Any]) -> None:
        n_m = kw.pop("n_moving", 3)
        if isinstance(n_m, bool) or not isinstance(n_m, (int, np.integer)) or n_m < 1:
            raise FormationError(f"moving_obstacles: n_moving must be an integer >= 1, got {n_m!r}")
        self.n_moving = int(n_m)
        self.lane_span = check_range("lane_span", kw.pop("lane_span", (-2.0, 2.0)), -8.0, 8.0)
        self.lane_jitter = check_range("lane_jitter", kw.pop("lane_jitter", (-0.15, 0.15)))
        self.moving_radius = check_range("moving_radius", kw.pop("moving_radius", (0.3, 0.5)), lo=1e-6, hi=2.0)
        self.moving_speed = check_range("moving_speed", kw.pop("moving_speed", (0.5, 1.0)), 0.0, MovingCircle.max_speed)
        self.moving_y = check_range("moving_y", kw.pop("moving_y", (-4.0, 4.0)), -5.0, 5.0)
        self.start_x = check_range("start_x", kw.pop("start_x", (-5.5, -4.5)))
        self.start_y = check_range("start_y", kw.pop("start_y", (-1.0, 1.0)))
        self.goal_x = check_range("goal_x", kw.pop("goal_x", (5.0, 5.5)))
        self.goal_y = check_range("goal_y", kw.pop("goal_y", (-1.0, 1.0)))
        self.angle = check_range("angle", kw.pop("angle", (-np.pi / 12, np.pi / 12)))
        m = self.n_moving
        self.lanes = np.linspace(*self.lane_span, m) if m > 1 else np.array([np.mean(self.lane_span)])

    def draws(self) -> list[Draw]:
        m = self.n_moving
        return [
            Draw("lane_jitter", (m,), bounds=self.lane_jitter),
            Draw("moving_y", (m,), bounds=self.moving_y),
            Draw("moving_radius", (m,), bounds=self.moving_radius),
            Draw("moving_speed", (m,), bounds=self.moving_speed),
            Draw("moving_sign", (m,), "sign"),
            Draw("start_x", bounds=self.start_x),
            Draw("start_y", bounds=self.start_y),
            Draw("angle0", bounds=self.angle),
            Draw("goal_x", bounds=self.goal_x),
            Draw("goal_y", bounds=self.goal_y),
            Draw("angle_g", bounds=self.angle),
            *self.follower_draws(),
        ]

    def build(self, raw: dict[str, Array]) -> tuple[dict[str, Array], tuple[Array, Array] | None]:
        B, m = raw["moving_y"].shape
        discs = np.zeros((B, m, 5))  # c0 (2), v (2), radius
        discs[:, :, 0] = self.lanes + raw["lane_jitter"]
        discs[:, :, 1] = raw["moving_y"]
        discs[:, :, 3] = raw["moving_speed"] * raw["moving_sign"]
        discs[:, :, 4] = raw["moving_radius"]
        b0 = np.stack([raw["start_x"], raw["start_y"]], -1)
        bg = np.stack([raw["goal_x"], raw["goal_y"]], -1)
        params = {"goal_theta": rotation_2d(raw["angle_g"]), "goal_b": bg, "moving_circles": discs}
        return params, (rotation_2d(raw["angle0"]), b0)

    task_row = staticmethod(task_row)

    def task_feature_bounds(self) -> tuple[Array, Array]:
        ext = self.bounds[1] - self.bounds[0]
        v = MovingCircle.max_speed
        lo = np.array([-ext[0], -ext[1], -v] + [-ext[1]] * len(FORECAST))
        hi = np.array([ext[0], ext[1], v] + [ext[1]] * len(FORECAST))
        return np.tile(lo, self.n_moving), np.tile(hi, self.n_moving)
