"""Components the contract tests add the way a contributor would: a bar spinning about its centre (an obstacle
type whose axis turns, unlike ``MovingCircle``), and scenarios with it alone and beside moving discs.

The bar's numpy capsules here are its analytic geometry (cos, sin), written apart from its compiled row, so the
oracle (which reads ``Engine.capsules``) checks the step's capsules against it.
"""

from __future__ import annotations

import math

import numpy as np

from formation_env.env.kernel import jit
from formation_env.env.obstacles import Capsules, MovingCircle, Obstacle
from formation_env.env.scenarios._base import Draw, Scenario, rotation_2d


@jit
def spin_row(p, t, bounds, a, e, rad):  # pragma: no cover
    """Bars p (K, 5) = centre (2), half-length, angular speed (rad/s), angle at t = 0 (rad), at time t (s):
    start a, axis e (K, 2), radius 0."""
    for j in range(p.shape[0]):
        ang = p[j, 4] + p[j, 3] * t
        hx, hy = p[j, 2] * math.cos(ang), p[j, 2] * math.sin(ang)
        a[j, 0], a[j, 1] = p[j, 0] - hx, p[j, 1] - hy
        e[j, 0], e[j, 1] = 2.0 * hx, 2.0 * hy
        rad[j] = 0.0


def bar_capsules(p: np.ndarray, t: np.ndarray) -> Capsules:
    """The analytic capsules of bars p (B, K, 5) at times t (B,) s."""
    ang = p[..., 4] + p[..., 3] * np.asarray(t, dtype=float)[:, None]
    half = p[..., 2:3] * np.stack([np.cos(ang), np.sin(ang)], -1)
    return Capsules(p[..., :2] - half, 2.0 * half, np.zeros(p.shape[:2]))


class SpinningBar(Obstacle):
    """Zero-thickness bars spinning about their centres: ``spinning_bars`` (B, K, 5)."""

    key = "spinning_bars"
    dims = (2,)
    row = staticmethod(spin_row)

    def moves(self) -> bool:
        return True

    def capsules(self, p, t, bounds):
        return bar_capsules(p, t)


class SpinningBars(Scenario):
    """Two bars spinning near the start (x = -2.2 and 1.0), world x in [-7, 7], y in [-5, 5]."""

    name = "spinning_bars_test"
    half_size = (7.0, 5.0)
    obstacle_types: tuple = (SpinningBar,)
    follower_noise = 0.1

    def draws(self):
        return [
            Draw("bar_y", (2,), bounds=(-1.5, 1.5)),
            Draw("speed", (2,), bounds=(0.6, 1.2)),
            Draw("angle", (2,), bounds=(0.0, math.pi)),
            Draw("disc_y", (2,), bounds=(-3.0, 3.0)),
            Draw("start_y", bounds=(-1.0, 1.0)),
            *self.follower_draws(),
        ]

    def build(self, raw):
        B = raw["bar_y"].shape[0]
        bars = np.zeros((B, 2, 5))
        bars[:, :, 0] = [-2.2, 1.0]
        bars[:, :, 1] = raw["bar_y"]
        bars[:, :, 2] = 0.9
        bars[:, :, 3] = raw["speed"]
        bars[:, :, 4] = raw["angle"]
        params = {
            "goal_theta": rotation_2d(np.zeros(B)),
            "goal_b": np.stack([np.full(B, 4.5), raw["start_y"]], -1),
            "spinning_bars": bars,
        }
        if MovingCircle in self.obstacle_types:
            discs = np.zeros((B, 2, 5))
            discs[:, :, 0] = [-1.0, 2.5]
            discs[:, :, 1] = raw["disc_y"]
            discs[:, :, 3] = [0.8, -0.6]
            discs[:, :, 4] = 0.4
            params["moving_circles"] = discs
        return params, (rotation_2d(np.zeros(B)), np.stack([np.full(B, -4.0), raw["start_y"]], -1))


class BarsAndDiscs(SpinningBars):
    """The spinning bars and two discs moving along y (two moving obstacle types)."""

    name = "bars_and_discs_test"
    obstacle_types: tuple = (MovingCircle, SpinningBar)
