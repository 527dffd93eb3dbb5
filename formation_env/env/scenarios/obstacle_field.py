"""``obstacle_field``: cross a field of scattered circular (3D: spherical) obstacles to a goal pose.

Per episode (uniform draws; ranges are keyword arguments):

* World box x in [-7, 7], other axes in [-5, 5].
* ``n_obstacles`` = 6 obstacles, centres with x in [-1.5, 1.0] and the other coordinates in
  [-4, 4], radii in [0.3, 0.6] m; they may overlap. Start and goal regions are clear of them.
* Start pose: rotation by psi0 in [-pi/12, pi/12] (3D: about z), b0 with x in [-4.5, -4], the rest
  in [-1.5, 1.5]; goal pose: rotation by psi_g in the same range, b_g with x in [4, 4.5].

Gaps between obstacles are often narrower than the nominal formation: rotating, shearing or
scaling it helps. Contact: an agent's path within ``agent_radius`` of an obstacle. Success as
in ``narrow_passage``: every agent within 0.2 m of its goal position and formation error below
0.05 m, with no contact; it terminates the episode.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from ._base import Array, Draw, Scenario, rotation_2d, rotation_3d

__all__ = ["ObstacleField", "make"]


class ObstacleField(Scenario):
    """Reach the goal pose through scattered obstacles (see the module docstring)."""

    name: ClassVar[str] = "obstacle_field"
    dims: ClassVar[tuple[int, ...]] = (2, 3)
    half_size: ClassVar[tuple[float, ...]] = (7.0, 5.0, 5.0)

    def _init(self, kw: dict[str, Any]) -> None:
        self.n_obstacles = int(kw.pop("n_obstacles", 6))
        self.obstacle_x = tuple(kw.pop("obstacle_x", (-1.5, 1.0)))
        self.obstacle_y = tuple(kw.pop("obstacle_y", (-4.0, 4.0)))
        self.obstacle_radius = tuple(kw.pop("obstacle_radius", (0.3, 0.6)))
        self.start_x = tuple(kw.pop("start_x", (-4.5, -4.0)))
        self.goal_x = tuple(kw.pop("goal_x", (4.0, 4.5)))
        self.lateral = tuple(kw.pop("lateral", (-1.5, 1.5)))
        self.angle = tuple(kw.pop("angle", (-np.pi / 12, np.pi / 12)))
        self.follower_noise = float(kw.pop("follower_noise", 0.1))

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
            "segments": np.zeros((circles.shape[0], 0, 2, self.d)),
            "circles": circles,
        }
        return params, (self._rotation(raw["angle0"]), b0)

    def param_vector(self, params: dict[str, Array]) -> Array:
        return params["circles"].reshape(params["circles"].shape[0], -1)

    @property
    def param_low(self) -> Array:
        lo = [self.obstacle_x[0]] + [self.obstacle_y[0]] * (self.d - 1) + [self.obstacle_radius[0]]
        return np.tile(lo, self.n_obstacles).astype(np.float64)

    @property
    def param_high(self) -> Array:
        hi = [self.obstacle_x[1]] + [self.obstacle_y[1]] * (self.d - 1) + [self.obstacle_radius[1]]
        return np.tile(hi, self.n_obstacles).astype(np.float64)


def make(fw: Any, **kwargs: Any) -> ObstacleField:
    """Build the scenario for framework ``fw`` (keyword arguments: see :class:`ObstacleField`)."""
    return ObstacleField(fw, **kwargs)
