"""The scenario interface, shared batched pose helpers, and the env's named frameworks.

A scenario is a small class in its own file (MPE2 ``scenarios/``, VMAS
``BaseScenario``). The engine owns the dynamics, the follower law, the
observation and the reward formula; a scenario supplies the task:

* ``__init__(fw, *, agent_radius, horizon, **kwargs)`` ("make"): reads its own
  keyword arguments and refuses unknown ones.
* ``reset(rng, B)``: per-episode arrays with a leading batch dim B: start
  positions, goal pose, obstacles, and any parameters of its own.
* ``reference(params, t)``: the goal pose (Theta(t), b(t)) at time t for
  scenarios whose goal moves (``moving_goal``); static goals are ``goal_theta``
  and ``goal_b`` from ``reset``.
* ``param_vector(params)``: the scenario's parameters for the global state.
* ``is_success(goal_distance, formation_error)``: the success test (``is_terminal``
  is success, when ``terminate_on_success``, or a collision, judged by the engine).
* ``reward_weights``: the weights of the engine's reward terms for this task.

Goal poses are affine images x_i* = Theta r_i + b (paper eq. 7) of the nominal
configuration r; every pose array is batched: Theta (B, d, d), b (B, d).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from formation_env.core.errors import FormationError
from formation_env.core.framework import Framework
from formation_env.core.validation import check_kwargs_consumed

__all__ = [
    "NAMED_FRAMEWORKS",
    "Scenario",
    "affine_batch",
    "bipyramid_3d",
    "gram_stress",
    "rotation_2d",
    "rotation_3d",
    "uniform",
]

Array = NDArray[np.float64]

#: Weights of the engine's reward terms (see ``FormationEnv``'s Rewards section).
DEFAULT_WEIGHTS: dict[str, float] = {
    "progress": 1.0,
    "distance": 0.0,
    "formation": 1.0,
    "collision": 10.0,
    "effort": 0.01,
    "success": 10.0,
}


def uniform(rng: np.random.Generator, bounds: tuple[float, float], size: int | tuple[int, ...]) -> Array:
    """Uniform draws in [lo, hi] (a degenerate range gives the constant)."""
    lo, hi = bounds
    return rng.uniform(lo, hi, size=size) if hi > lo else np.full(size, float(lo))


def rotation_2d(angle: Array) -> Array:
    """Batched 2D rotations by ``angle`` (rad, counter-clockwise), (B,) -> (B, 2, 2)."""
    c, s = np.cos(angle), np.sin(angle)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


def rotation_3d(axis: Array, angle: Array) -> Array:
    """Batched Rodrigues rotations about unit ``axis`` (B, 3) by ``angle`` (B,) rad, shape (B, 3, 3)."""
    k = axis / np.linalg.norm(axis, axis=-1, keepdims=True)
    kx = np.zeros(axis.shape[:-1] + (3, 3))
    kx[..., 0, 1], kx[..., 0, 2] = -k[..., 2], k[..., 1]
    kx[..., 1, 0], kx[..., 1, 2] = k[..., 2], -k[..., 0]
    kx[..., 2, 0], kx[..., 2, 1] = -k[..., 1], k[..., 0]
    s, c = np.sin(angle)[..., None, None], np.cos(angle)[..., None, None]
    return np.eye(3) + s * kx + (1.0 - c) * (kx @ kx)


def affine_batch(r: Array, theta: Array, b: Array) -> Array:
    """x_i = Theta r_i + b for every agent (eq. 7): r (n, d), theta (B, d, d), b (B, d) -> (B, n, d)."""
    return np.einsum("bij,nj->bni", theta, r) + b[:, None, :]


def gram_stress(fw: Framework) -> Array:
    """The complete-graph stress N N^T, N an orthonormal basis of the affine dependencies of r.

    PSD with rank n - d - 1, zero row sums and Omega r = 0 by construction; it is
    supported on every pair of agents, so it is a valid stress only for a
    complete graph. Scaled so that the largest eigenvalue of Omega_ff is 1.
    """
    import scipy.linalg as sla

    h = np.hstack([fw.positions, np.ones((fw.n, 1))])
    nb = sla.null_space(h.T)
    om = nb @ nb.T
    om = (om + om.T) / 2
    f = list(fw.followers)
    return om / float(np.linalg.eigvalsh(om[np.ix_(f, f)])[-1])


def bipyramid_3d() -> Framework:
    """A 6-agent 3D framework: 4 leaders (triangle plus apex) and 2 followers (lower apex, tail).

    Leaders (1, 0, 0), (-0.5, 0.9, 0), (-0.5, -0.9, 0), (0, 0, 1); followers
    (0, 0, -1), (-1.5, 0, 0.2); complete graph (its stress is :func:`gram_stress`).
    """
    r = np.array(
        [[1.0, 0.0, 0.0], [-0.5, 0.9, 0.0], [-0.5, -0.9, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, -1.0], [-1.5, 0.0, 0.2]]
    )
    edges = [(i, j) for i in range(6) for j in range(i + 1, 6)]
    return Framework(r, edges, leaders=[0, 1, 2, 3], name="bipyramid_3d")


def _paper() -> tuple[Framework, Array]:
    from formation_env.core.frameworks import paper_example, paper_omega

    return paper_example(), paper_omega()


def _bipyramid() -> tuple[Framework, Array]:
    fw = bipyramid_3d()
    return fw, gram_stress(fw)


#: Frameworks the env knows by name, with their stress matrices: name -> () -> (Framework, omega).
#: Other names are looked up in ``formation_env.core.frameworks`` (stress from ``design_stress``).
NAMED_FRAMEWORKS: dict[str, Callable[[], tuple[Framework, Array]]] = {
    "paper": _paper,
    "bipyramid_3d": _bipyramid,
}


#: Up to this many agents ``Scenario.start_positions`` checks all pairs; above, a k-d tree.
ALL_PAIRS_GAP_UP_TO = 512


class Scenario:
    """Base class of the scenarios (see the module docstring for the hooks).

    Class attributes:
        name: registry key.
        dims: spatial dimensions the scenario supports.
        default_framework: framework used when none is given (a ``NAMED_FRAMEWORKS`` key).
        moving_goal: the goal pose is time-varying (``reference``).
        terminate_on_success: success ends the episode (else it is judged every step, for the last).
        half_size: half-width (m) of the world box centred on the origin, per axis.

    Instance attributes set by ``__init__``: ``fw``, ``d``, ``bounds`` (2, d),
    ``goal_tol`` (m, every agent within it of its goal), ``formation_tol`` (m,
    formation error below it), ``hold_steps`` (consecutive successful samples
    needed), ``reward_weights``.
    """

    name: ClassVar[str] = ""
    dims: ClassVar[tuple[int, ...]] = (2,)
    default_framework: ClassVar[str] = "paper"
    moving_goal: ClassVar[bool] = False
    terminate_on_success: ClassVar[bool] = True
    half_size: ClassVar[tuple[float, ...]] = (5.0, 5.0)
    weights: ClassVar[dict[str, float]] = {}
    goal_tol_default: ClassVar[float] = 0.2
    formation_tol_default: ClassVar[float] = 0.05
    hold_steps_default: ClassVar[int] = 1

    def __init__(self, fw: Framework, *, agent_radius: float, horizon: float, **kwargs: Any) -> None:
        if fw.d not in self.dims:
            raise FormationError(
                f"scenario {self.name!r} supports d in {list(self.dims)}, got a {fw.d}D framework {fw.name!r}"
            )
        self.fw = fw
        self.d = fw.d
        self.r = fw.positions
        self.agent_radius = float(agent_radius)
        self.horizon = float(horizon)
        self.goal_tol = float(kwargs.pop("goal_tol", self.goal_tol_default))
        self.formation_tol = float(kwargs.pop("formation_tol", self.formation_tol_default))
        self.hold_steps = int(kwargs.pop("hold_steps", self.hold_steps_default))
        if not (self.goal_tol > 0 and self.formation_tol > 0 and self.hold_steps >= 1):
            raise FormationError(
                f"goal_tol and formation_tol must be positive and hold_steps >= 1, got "
                f"{self.goal_tol}, {self.formation_tol}, {self.hold_steps}"
            )
        half = np.asarray(self.half_size[: self.d], dtype=np.float64)
        self.bounds: Array = np.stack([-half, half]).astype(np.float64)
        self.reward_weights = {**DEFAULT_WEIGHTS, **self.weights}
        self._init(kwargs)
        check_kwargs_consumed(kwargs, f"scenario {self.name!r}")

    def _init(self, kw: dict[str, Any]) -> None:
        """Read scenario-specific keyword arguments (pop them from ``kwargs``)."""

    # ---------------------------------------------------------------- hooks
    def reset(self, rng: np.random.Generator, B: int) -> dict[str, Array]:
        """Per-episode arrays: ``start`` (B, n, d), ``goal_theta`` (B, d, d), ``goal_b`` (B, d),
        ``segments`` (B, S, 2, d), ``circles`` (B, C, d + 1), plus the scenario's own."""
        raise NotImplementedError

    def reference(self, params: dict[str, Array], t: Array) -> tuple[Array, Array]:
        """Goal pose at times t (B,) s: Theta (B, d, d), b (B, d). Static goals return the reset pose."""
        return params["goal_theta"], params["goal_b"]

    def param_vector(self, params: dict[str, Array]) -> Array:
        """Scenario parameters for the global state, shape (B, k) (k = len(param_low))."""
        return np.zeros((params["segments"].shape[0], 0))

    @property
    def param_low(self) -> Array:
        """Lower bounds of ``param_vector``, shape (k,)."""
        return np.zeros(0)

    @property
    def param_high(self) -> Array:
        """Upper bounds of ``param_vector``, shape (k,)."""
        return np.zeros(0)

    def is_success(self, goal_distance: Array, formation_error: Array) -> NDArray[np.bool_]:
        """Success at one sample: every agent within ``goal_tol`` of its goal and formation error below
        ``formation_tol``. goal_distance (B,) is the largest agent distance (m); returns (B,) bool."""
        return (goal_distance < self.goal_tol) & (formation_error < self.formation_tol)

    # ---------------------------------------------------------------- helpers
    def empty_obstacles(self, B: int) -> dict[str, Array]:
        """Zero-size obstacle arrays of the right shapes."""
        return {"segments": np.zeros((B, 0, 2, self.d)), "circles": np.zeros((B, 0, self.d + 1))}

    def start_positions(
        self, rng: np.random.Generator, theta: Array, b: Array, follower_noise: float, tries: int = 20
    ) -> Array:
        """Leaders on the pose (theta, b), followers there plus uniform noise in a ball of ``follower_noise`` m.

        Draws again (for the offending episodes only) while two agents would start
        closer than 3 agent radii; after ``tries`` draws those keep zero noise.
        Returns shape (B, n, d).
        """
        base = affine_batch(self.r, theta, b)
        B = base.shape[0]
        out = base.copy()
        f = np.asarray(self.fw.followers)
        if follower_noise <= 0 or f.size == 0:
            return out
        iu, ju = np.triu_indices(self.fw.n, 1) if self.fw.n <= ALL_PAIRS_GAP_UP_TO else (None, None)
        todo = np.arange(B)
        for _ in range(tries):
            dirs = rng.normal(size=(todo.size, f.size, self.d))
            dirs /= np.linalg.norm(dirs, axis=-1, keepdims=True)
            rad = follower_noise * rng.uniform(size=(todo.size, f.size, 1)) ** (1.0 / self.d)
            trial = base[todo].copy()
            trial[:, f] += dirs * rad
            if iu is not None:
                gap = np.linalg.norm(trial[:, iu] - trial[:, ju], axis=-1).min(axis=1)
                ok = gap >= 3.0 * self.agent_radius
            else:  # large swarms: a k-d tree finds the close pairs in O(n log n), not n^2 / 2 pairs
                from scipy.spatial import cKDTree

                gap3 = 3.0 * self.agent_radius
                ok = np.array([not cKDTree(t).query_pairs(gap3, eps=0.0, output_type="ndarray").size for t in trial])
            out[todo[ok]] = trial[ok]
            todo = todo[~ok]
            if todo.size == 0:
                break
        return out
