"""``obstacle_field``: cross a field of scattered circular (3D: spherical) obstacles to a goal pose.

Per episode (uniform draws; ranges are keyword arguments):

* World box x in [-7, 7], other axes in [-5, 5].
* ``n_obstacles`` = 6 obstacles, centres with x in [-1.5, 1.0] and the other coordinates in
  [-4, 4], radii in [0.3, 0.6] m; they may overlap. Start and goal regions are clear of them.
* Start pose: rotation by psi0 in [-pi/12, pi/12] (3D: about z), b0 with x in [-4.5, -4], the rest
  in [-1.5, 1.5]; goal pose: rotation by psi_g in the same range, b_g with x in [4, 4.5].

Gaps between obstacles are often narrower than the nominal formation: rotating, shearing or scaling it helps.
Contact: an agent's path within ``agent_radius`` of an obstacle. Success (and its end) as in ``narrow_passage``.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from formation_env.core.errors import FormationError

from ..obstacles import Circle
from ._base import Array, Draw, EpisodeParam, Scenario, check_range, rotation_2d, rotation_3d

__all__ = ["ObstacleField"]


class ObstacleField(Scenario):
    """Reach the goal pose through scattered obstacles (see the module docstring)."""

    name: ClassVar[str] = "obstacle_field"
    dims: ClassVar[tuple[int, ...]] = (2, 3)
    half_size: ClassVar[tuple[float, ...]] = (7.0, 5.0, 5.0)
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

    def episode_params(self) -> list[EpisodeParam]:
        d = self.d
        low = [self.obstacle_x[0]] + [self.obstacle_y[0]] * (d - 1) + [self.obstacle_radius[0]]
        high = [self.obstacle_x[1]] + [self.obstacle_y[1]] * (d - 1) + [self.obstacle_radius[1]]
        return [EpisodeParam("circles", (self.n_obstacles, d + 1), low, high)]
