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

Contact: an agent touches the wall when its centre comes within ``agent_radius`` of a
segment or its step crosses one. Success: no contact so far and, at one sample, every agent
within ``goal_tol`` = 0.2 m of its goal position Theta_g r_i + b_g and the affine-image
formation error below ``formation_tol`` = 0.05 m. The episode then terminates.

:func:`scripted_action` is a reference policy (move to the gap, shrink, pass, restore, go
to the goal) used by the tests to show every episode is solvable.
"""

from __future__ import annotations

import warnings
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from ._base import Array, Draw, Scenario, affine_batch, rotation_2d

if TYPE_CHECKING:
    from ..engine import Engine, EngineState

__all__ = ["NarrowPassage", "make", "scripted_action"]


class NarrowPassage(Scenario):
    """Pass a gap narrower than the formation (see the module docstring for geometry and success)."""

    name: ClassVar[str] = "narrow_passage"
    half_size: ClassVar[tuple[float, ...]] = (7.0, 5.0)

    def _init(self, kw: dict[str, Any]) -> None:
        self.wall_x = tuple(kw.pop("wall_x", (-0.5, 0.5)))
        self.gap_center = tuple(kw.pop("gap_center", (-1.0, 1.0)))
        self.gap_width = tuple(kw.pop("gap_width", (1.0, 1.6)))
        self.start_x = tuple(kw.pop("start_x", (-4.5, -3.5)))
        self.start_y = tuple(kw.pop("start_y", (-1.5, 1.5)))
        self.goal_x = tuple(kw.pop("goal_x", (3.5, 4.5)))
        self.goal_y = tuple(kw.pop("goal_y", (-1.5, 1.5)))
        self.angle = tuple(kw.pop("angle", (-np.pi / 12, np.pi / 12)))
        self.follower_noise = float(kw.pop("follower_noise", 0.1))
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
            "circles": np.zeros((B, 0, 3)),
            "wall_x": wall,
            "gap_center": yc,
            "gap_width": w,
        }
        return params, (rotation_2d(raw["angle0"]), b0)

    def param_vector(self, params: dict[str, Array]) -> Array:
        return np.stack([params["wall_x"], params["gap_center"], params["gap_width"]], -1)

    @property
    def param_low(self) -> Array:
        return np.array([self.wall_x[0], self.gap_center[0], self.gap_width[0]])

    @property
    def param_high(self) -> Array:
        return np.array([self.wall_x[1], self.gap_center[1], self.gap_width[1]])


def make(fw: Any, **kwargs: Any) -> NarrowPassage:
    """Build the scenario for framework ``fw`` (keyword arguments: see :class:`NarrowPassage`)."""
    return NarrowPassage(fw, **kwargs)


def scripted_action(engine: Engine, state: EngineState, margin: float = 0.1) -> Array:
    """Reference policy, stateless and batched: shrink at the gap, pass, restore, go to the goal.

    Per episode, with wall x_w, gap centre y_c and width w: the squeezed pose is
    Theta_s = diag(1, s), s = (w - 2 radius - 2 margin) / ptp(r_y), b_y centring the
    formation on the gap. Until every agent is past the wall (x > x_w + radius + margin)
    the leaders track the squeezed pose, holding b_x in front of the wall until every
    agent is within margin/2 of its squeezed y, then pushing b_x through; afterwards
    they track the goal pose. Leaders follow their targets with :func:`track_targets`.

    Returns:
        actions in [-1, 1], shape (B, n_l, p).
    """
    from ..control import track_targets

    sc = engine.scenario
    r = sc.r
    rad = sc.agent_radius
    p = state.params
    pos = state.pos
    B = pos.shape[0]
    ry = r[:, 1]
    s = (p["gap_width"] - 2 * rad - 2 * margin) / np.ptp(ry)
    by = p["gap_center"] - s * (ry.max() + ry.min()) / 2
    ty = by[:, None] + s[:, None] * ry[None, :]  # squeezed y of every agent, (B, n)
    aligned = np.max(np.abs(pos[:, :, 1] - ty), axis=1) < margin / 2
    wall = p["wall_x"]
    passed = pos[:, :, 0].min(axis=1) > wall + rad + margin
    b_fit = engine.affine.fit(pos)[1]
    entering = pos[:, :, 0].max(axis=1) > wall - 0.4
    bx = np.where(
        aligned,
        wall - r[:, 0].min() + rad + 3 * margin,
        np.where(entering, b_fit[:, 0], wall - r[:, 0].max() - 0.6),
    )
    theta_s = np.zeros((B, 2, 2))
    theta_s[:, 0, 0] = 1.0
    theta_s[:, 1, 1] = s
    squeeze = affine_batch(r, theta_s, np.stack([bx, by], -1))
    goal = affine_batch(r, p["goal_theta"], p["goal_b"])
    targets = np.where(passed[:, None, None], goal, squeeze)
    return track_targets(engine, state, targets[:, engine.leaders])
