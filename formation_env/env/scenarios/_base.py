"""The scenario interface and shared batched pose helpers.

A scenario is a small class in its own file (MPE2 ``scenarios/``, VMAS ``BaseScenario``) that supplies the task;
the engine owns the dynamics, the follower law, contacts, observations and rewards, and knows no scenario. The
hooks of :class:`Scenario`: ``_init`` reads its own keyword arguments (unknown ones are refused); ``draws`` and
``build`` give the episode's random draws in stream order (:class:`Draw`) and the draw-free, batched map from
them to the per-episode arrays (obstacles under their types' keys), from which the base class makes
``reset(rng, B)`` and ``reset_each(rngs)`` (the vectorised env's auto-reset); ``reference`` and ``goal_vector``
(moving goals); ``episode_params`` (the task in the global state: :class:`EpisodeParam`, from which
``param_vector``, ``decode_params``, ``param_low`` and ``param_high`` follow). Three compiled rows
(:mod:`~formation_env.env.kernel`) run inside the step: ``pose_row`` (a moving goal's pose), ``route_row`` (the
``approach`` potential's route) and ``task_row`` (the ``task`` observation block). Success at a sample: every
agent within ``goal_tol`` of its goal and the formation error below ``formation_tol``, for ``hold_steps``
samples in a row.

Goal poses are affine images x_i* = Theta r_i + b (paper eq. 7) of the nominal configuration r; every pose
array is batched: Theta (B, d, d), b (B, d).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from typing import Any, ClassVar, NamedTuple

import numpy as np
from numpy.typing import NDArray

from formation_env.core.errors import FormationError
from formation_env.core.framework import Framework
from formation_env.core.validation import check_int, check_kwargs_consumed, check_real_scalar

from ..kernel import straight_route
from ..obstacles import Obstacle

__all__ = [
    "Draw",
    "DrawPlan",
    "EpisodeParam",
    "Scenario",
    "affine_batch",
    "rotation_2d",
    "rotation_3d",
    "uniform",
]

Array = NDArray[np.float64]

#: Reach of a pose beyond the nominal framework in the growing worlds: |Theta| <= 1.4 (scale) x 1.5 (shear).
REACH = 2.2
#: Up to this many agents the start-gap test checks all pairs; above, a k-d tree.
ALL_PAIRS_GAP_UP_TO = 512


def uniform(rng: np.random.Generator, bounds: tuple[float, float], size: int | tuple[int, ...]) -> Array:
    """Uniform draws in [lo, hi] (a degenerate range gives the constant)."""
    lo, hi = bounds
    return rng.uniform(lo, hi, size=size) if hi > lo else np.full(size, float(lo))


def rotation_2d(angle: Array) -> Array:
    """Batched 2D rotations by ``angle`` (rad, counter-clockwise), (B,) -> (B, 2, 2)."""
    c, s = np.cos(angle), np.sin(angle)
    out = np.empty((*np.shape(angle), 2, 2))
    out[..., 0, 0] = out[..., 1, 1] = c
    out[..., 1, 0] = s
    out[..., 0, 1] = -s
    return out


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
    """x_i = Theta r_i + b for every agent (eq. 7): r (n, d), theta (B, d, d), b (B, d) -> (B, n, d), C-contiguous.

    Made as (B, d, n), with r transposed to (d, n): einsum's inner loop then runs over the agents, several times
    faster at small d than over the d terms of each sum."""
    x = np.einsum("bij,jn->bin", theta, np.ascontiguousarray(np.transpose(r)))
    x += b[:, :, None]
    return np.ascontiguousarray(x.transpose(0, 2, 1))


class Scenario:
    """Base class of the scenarios (the module docstring lists the hooks).

    Class attributes:
        name: registry key.
        dims: spatial dimensions the scenario supports.
        default_framework: framework used when none is given (a ``NAMED_FRAMEWORKS`` key).
        moving_goal: the goal pose is time-varying (``reference``).
        terminate_on_success: success ends the episode (else it is judged every step, for the last).
        half_size: half-width (m) of the world box centred on the origin, per axis.
        obstacle_types: its obstacle components (:mod:`formation_env.env.obstacles`).
        grows_world: the world box grows to hold a large framework (:meth:`fit_world`).
        planner: ``"module:Class"`` of its analytic planner (under ``agents/``), or None.
        weights: its reward weights over the defaults (:mod:`formation_env.env.rewards`).

    Instance attributes set by ``__init__``: ``fw``, ``d``, ``r``, ``bounds`` (2, d), ``goal_tol`` (m, every
    agent within it of its goal), ``formation_tol`` (m, formation error below it), ``hold_steps``
    (consecutive successful samples needed).
    """

    name: ClassVar[str] = ""
    dims: ClassVar[tuple[int, ...]] = (2,)
    default_framework: ClassVar[str] = "paper"
    moving_goal: ClassVar[bool] = False
    terminate_on_success: ClassVar[bool] = True
    half_size: ClassVar[tuple[float, ...]] = (5.0, 5.0)
    obstacle_types: ClassVar[tuple[type[Obstacle], ...]] = ()
    grows_world: ClassVar[bool] = False
    planner: ClassVar[str | None] = None
    weights: ClassVar[dict[str, float]] = {}
    goal_tol_default: ClassVar[float] = 0.2
    formation_tol_default: ClassVar[float] = 0.05
    hold_steps_default: ClassVar[int] = 1
    start_tries: ClassVar[int] = 20
    follower_noise: float = 0.0

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
        self.goal_tol = float(check_number("goal_tol", kwargs.pop("goal_tol", self.goal_tol_default)))
        self.formation_tol = float(
            check_number("formation_tol", kwargs.pop("formation_tol", self.formation_tol_default))
        )
        self.hold_steps = int(
            check_number("hold_steps", kwargs.pop("hold_steps", self.hold_steps_default), integer=True)
        )
        half = np.asarray(self.half_size[: self.d], dtype=np.float64)
        self.bounds: Array = np.stack([-half, half]).astype(np.float64)
        self.obstacles: list[Obstacle] = [cls() for cls in self.obstacle_types]
        for ob in self.obstacles:
            if self.d not in ob.dims:
                raise FormationError(f"scenario {self.name!r}: {type(ob).__name__} obstacles are {ob.dims}D only")
        self._init(kwargs)
        self.follower_noise = float(
            check_number("follower_noise", kwargs.pop("follower_noise", self.follower_noise), positive=False)
        )
        check_kwargs_consumed(kwargs, f"scenario {self.name!r}")
        self.fit_world()

    def _init(self, kw: dict[str, Any]) -> None:
        """Read scenario-specific keyword arguments (pop them from ``kw``)."""

    # ---------------------------------------------------------------- hooks
    def draws(self) -> list[Draw]:
        """The random draws of one episode, in stream order (the last two are :meth:`follower_draws` where
        the start positions are noisy)."""
        raise NotImplementedError

    def build(self, raw: dict[str, Array]) -> tuple[dict[str, Array], tuple[Array, Array] | None]:
        """Per-episode arrays from the draws (``raw[name]`` of shape (B, *shape)), batched and draw-free.

        Returns (params, pose): params with ``goal_theta`` (B, d, d) and ``goal_b`` (B, d) (static goals),
        each obstacle type's parameters under its key and the scenario's own; and the start pose (Theta0
        (B, d, d), b0 (B, d)) on which the agents are placed, or None when params hold ``start`` (B, n, d).
        """
        raise NotImplementedError

    def reference(self, params: dict[str, Array], t: Array) -> tuple[Array, Array]:
        """Goal pose at times t (B,) s: Theta (B, d, d), b (B, d). Static goals return the reset pose."""
        return params["goal_theta"], params["goal_b"]

    #: Compiled hooks of the step (:mod:`formation_env.env.kernel`): the moving goal's pose (None: static),
    #: the ``approach`` potential's route, the ``task`` observation block (None: no entries).
    pose_row: Any = None
    route_row: Any = staticmethod(straight_route)
    task_row: Any = None

    def goal_vector(self, params: dict[str, Array]) -> Array:
        """What ``pose_row`` reads of each episode's moving goal, (B, w); none for a static goal."""
        return np.zeros((next(iter(params.values())).shape[0], 0))

    def episode_params(self) -> list[EpisodeParam]:
        """The episode's parameters the global state carries (and a planner reads back), in order, each with its
        shape per episode and bounds; none by default. :meth:`param_vector`, :meth:`decode_params`,
        :attr:`param_low` and :attr:`param_high` follow from them."""
        return []

    @functools.cached_property
    def _episode_params(self) -> list[EpisodeParam]:
        return self.episode_params()

    def param_vector(self, params: dict[str, Array]) -> Array:
        """Scenario parameters for the global state, shape (B, k) (k = len(param_low)): the
        :meth:`episode_params`, each flattened, side by side."""
        B = next(iter(params.values())).shape[0]
        parts = [np.asarray(params[p.name], dtype=np.float64).reshape(B, p.size) for p in self._episode_params]
        return np.concatenate(parts, axis=1) if parts else np.zeros((B, 0))

    @property
    def param_low(self) -> Array:
        """Lower bounds of ``param_vector``, shape (k,)."""
        return np.concatenate([p.bound(0) for p in self._episode_params] + [np.zeros(0)])

    @property
    def param_high(self) -> Array:
        """Upper bounds of ``param_vector``, shape (k,)."""
        return np.concatenate([p.bound(1) for p in self._episode_params] + [np.zeros(0)])

    def decode_params(self, pvec: Array) -> dict[str, Array]:
        """The :meth:`episode_params` from ``param_vector`` values (B, k) read back out of the global state."""
        out, at = {}, 0
        for p in self._episode_params:
            out[p.name] = pvec[:, at : at + p.size].reshape(pvec.shape[0], *p.shape)
            at += p.size
        return out

    def task_feature_bounds(self) -> tuple[Array, Array]:
        """(low, high) of the ``task_row`` entries, each (k,)."""
        return np.zeros(0), np.zeros(0)

    def fit_world(self) -> None:
        """Fit the world box to a large framework, or refuse the framework (FormationError).

        With R = max_i |r_i| (m): a ``grows_world`` scenario whose box half-width h is below REACH R gets
        h' = REACH R + h per axis (every pose it draws stays inside); the others have obstacles sized for
        formations of a few metres and refuse a framework wider than half their box.
        """
        reach = float(np.max(np.linalg.norm(self.r, axis=1)))
        half = self.bounds[1]
        if self.grows_world:
            if REACH * reach > float(np.min(half)):
                grown = REACH * reach + half
                self.bounds = np.stack([-grown, grown]).astype(np.float64)
            return
        span = np.ptp(self.r, axis=0)
        if np.any(span > half):
            raise FormationError(
                f"scenario {self.name!r} has obstacles in a world of {' x '.join(f'{2 * h:g}' for h in half)} m, "
                f"sized for formations of a few metres; the framework {self.fw.name or '(custom)'} spans "
                f"{' x '.join(f'{s:.3g}' for s in span)} m: scale its positions (Framework(fw.positions * s, "
                "fw.edges, fw.leaders): the stress stays valid), or use a scenario whose world grows"
            )

    # ---------------------------------------------------------------- resets
    def reset(self, rng: np.random.Generator, B: int) -> dict[str, Array]:
        """B episodes from one generator: the params of :meth:`build` with ``start`` (B, n, d). Each draw of
        :meth:`draws` is one generator call for all B episodes, in order; then the followers' noise is redrawn
        (for the episodes whose agents start too close) one draw per episode a round."""
        return self._episodes(self._plan.draw(rng, B), lambda todo: self._noise_plan.draw(rng, todo.size))

    def reset_each(self, rngs: Sequence[np.random.Generator]) -> dict[str, Array]:
        """One episode per generator, batched: entry b equals ``reset(rngs[b], 1)`` (the same draws; the
        geometry runs once for all episodes). The generators must be distinct objects."""
        redraw = lambda todo: self._noise_plan.draw_each([rngs[b] for b in todo.tolist()])  # noqa: E731
        return self._episodes(self._plan.draw_each(rngs), redraw)

    # ---------------------------------------------------------------- helpers
    def follower_draws(self) -> list[Draw]:
        """The followers' start noise, the last draws of an episode: directions ``_dirs`` (n_f, d)
        standard normal, radii ``_u`` (n_f,) uniform in [0, 1]; none without followers or noise."""
        if self.follower_noise <= 0 or len(self.fw.followers) == 0:
            return []
        return list(self._noise_plan.draws)

    @functools.cached_property
    def _pairs(self) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
        """Every pair of agents i < j, as two index arrays (n (n - 1) / 2,)."""
        return np.triu_indices(self.fw.n, 1)

    @functools.cached_property
    def _plan(self) -> DrawPlan:
        return DrawPlan(self.draws())

    @functools.cached_property
    def _noise_plan(self) -> DrawPlan:
        nf = len(self.fw.followers)
        return DrawPlan([Draw("_dirs", (nf, self.d), "normal"), Draw("_u", (nf,))])

    def _noisy(self, out: Array, base: Array, todo: NDArray[np.intp], noise: dict[str, Array]) -> NDArray[np.bool_]:
        """Move the followers of episodes ``todo`` (m,) from ``base`` (B, n, d) along their noise directions
        ``noise["_dirs"]`` (m, n_f, d) by ``follower_noise`` u^(1/d) (u = ``noise["_u"]`` (m, n_f)): uniform in
        a ball. The episodes whose agents are then no two closer than 3 radii get these positions in ``out``;
        returns that test (m,)."""
        dirs = noise["_dirs"]
        dirs = dirs / np.sqrt(np.sum(dirs * dirs, axis=-1, keepdims=True))
        u = noise["_u"]
        rad = self.follower_noise * (np.sqrt(u) if self.d == 2 else np.power(u, 1.0 / self.d))  # uniform in a ball
        trial = base[todo]
        trial[:, list(self.fw.followers)] += dirs * rad[:, :, None]
        gap3 = 3.0 * self.agent_radius
        if self.fw.n > ALL_PAIRS_GAP_UP_TO:  # large swarms: a k-d tree finds the close pairs in O(n log n)
            from scipy.spatial import cKDTree

            ok = np.array([not cKDTree(t).query_pairs(gap3, output_type="ndarray").size for t in trial], dtype=bool)
        else:
            iu, ju = self._pairs
            diff = trial[:, iu] - trial[:, ju]
            ok = np.sqrt(np.sum(diff * diff, axis=-1).min(axis=1, initial=np.inf)) >= gap3
        out[todo[ok]] = trial[ok]
        return ok

    def _episodes(
        self, raw: dict[str, Array], redraw: Callable[[NDArray[np.intp]], dict[str, Array]]
    ) -> dict[str, Array]:
        """The params of :meth:`build` from the draws ``raw``, with ``start`` (B, n, d) where ``build`` gives a pose:
        leaders on it at rest, followers there moved by the noise draws ``_dirs``, ``_u`` of ``raw`` (none: no
        noise). Episodes whose agents would start closer than 3 radii draw again (``redraw(episodes)``),
        ``start_tries`` draws in all; those still too close keep zero noise."""
        params, pose = self.build(raw)
        if pose is None:
            return params
        params["start"] = base = affine_batch(self.r, *pose)
        if "_u" in raw:
            params["start"] = out = base.copy()
            todo, noise = np.arange(base.shape[0]), raw
            for _ in range(self.start_tries):
                todo = todo[~self._noisy(out, base, todo, noise)]
                if todo.size == 0:
                    break
                noise = redraw(todo)
        return params


def check_number(name: str, value: Any, *, positive: bool = True, integer: bool = False) -> Any:
    """``value``, checked by the core's validation helpers: a real number (an integer if ``integer``; TypeError
    otherwise), finite and positive (``positive``) or >= 0 (FormationError otherwise)."""
    sign = "positive" if positive else ">= 0"
    if integer:
        return check_int(value, name, low=1 if positive else 0, what=f"a {sign} integer")
    return check_real_scalar(value, name, low=0.0, low_open=positive, what=f"{sign} and finite")


def check_range(name: str, value: Any, lo: float = -math.inf, hi: float = math.inf) -> tuple[float, float]:
    """A scenario's (low, high) keyword range as floats: finite, low <= high, within [lo, hi]."""
    try:
        a, b = (float(v) for v in value)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be a (low, high) pair of numbers, got {value!r}") from None
    if not (math.isfinite(a) and math.isfinite(b)):
        raise FormationError(f"{name} must be finite, got ({a}, {b})")
    if a > b:
        raise FormationError(f"{name} must have low <= high, got ({a}, {b})")
    if a < lo or b > hi:
        raise FormationError(f"{name} must lie in [{lo}, {hi}], got ({a}, {b})")
    return a, b


class EpisodeParam(NamedTuple):
    """One parameter of an episode that the global state carries: ``params[name]`` of shape (B, *shape), each
    entry in [low, high] (numbers or arrays broadcast to ``shape``)."""

    name: str
    shape: tuple[int, ...] = ()
    low: Any = 0.0
    high: Any = 0.0

    @property
    def size(self) -> int:
        """Entries per episode."""
        return int(np.prod(self.shape, dtype=np.int64))

    def bound(self, which: int) -> Array:
        """The low (0) or high (1) bounds, flattened (size,)."""
        return np.broadcast_to(np.asarray((self.low, self.high)[which], dtype=np.float64), self.shape).reshape(-1)


class Draw(NamedTuple):
    """One random draw of an episode: ``shape`` numbers of ``kind`` "uniform" (in ``bounds``, as
    :func:`uniform`: a degenerate range draws nothing), "normal" (standard) or "sign" (-1 or +1,
    as ``rng.choice([-1.0, 1.0])``)."""

    name: str
    shape: tuple[int, ...] = ()
    kind: str = "uniform"
    bounds: tuple[float, float] = (0.0, 1.0)


class DrawPlan:
    """The draws of one episode: ``draw(rng, B)`` makes one generator call per draw for B episodes (the batched
    stream); ``draw_each(rngs)`` one episode per generator, entry b equal to ``draw(rngs[b], 1)``."""

    def __init__(self, draws: Sequence[Draw]) -> None:
        names = [dr.name for dr in draws]
        if len(set(names)) != len(names):
            raise FormationError(f"draw names must be unique, got {names}")
        for dr in draws:
            if dr.kind not in ("uniform", "normal", "sign"):
                raise FormationError(f"draw {dr.name!r}: kind must be uniform, normal or sign, got {dr.kind!r}")
        self.draws = list(draws)

    def draw(self, rng: np.random.Generator, B: int) -> dict[str, Array]:
        """One generator call per draw, each for all B episodes."""
        return {dr.name: _sample(rng, dr, (B, *dr.shape)) for dr in self.draws}

    def draw_each(self, rngs: Sequence[np.random.Generator]) -> dict[str, Array]:
        """One episode per generator (its own stream, as a single reset draws it), stacked along B. A run of
        consecutive uniform draws is one ``random`` call per generator, scaled as ``Generator.uniform`` scales its
        doubles (lo + (hi - lo) u), so every entry equals ``draw(rngs[b], 1)``'s bit for bit."""
        B = len(rngs)
        out = {dr.name: np.full((B, *dr.shape), float(dr.bounds[0])) for dr in self.draws if not _draws_numbers(dr)}
        for run, cols in self._runs:
            if run[0].kind == "uniform":
                u = np.empty((B, cols[-1].stop))
                for b, g in enumerate(rngs):
                    g.random(out=u[b])
                for dr, col in zip(run, cols, strict=True):
                    lo, hi = dr.bounds
                    out[dr.name] = lo + (hi - lo) * u[:, col].reshape(B, *dr.shape)
            else:
                (dr,) = run
                out[dr.name] = np.stack([_sample(g, dr, dr.shape) for g in rngs])
        return {dr.name: out[dr.name] for dr in self.draws}

    @functools.cached_property
    def _runs(self) -> list[tuple[list[Draw], list[slice]]]:
        """The draws that take numbers from the generator, in order, with each one's columns among its run's numbers:
        consecutive uniform draws joined into one run (a degenerate range draws nothing, so it does not break a
        run), every other draw a run of its own."""
        runs: list[tuple[list[Draw], list[slice]]] = []
        for dr in filter(_draws_numbers, self.draws):
            size = int(np.prod(dr.shape, dtype=np.int64))
            if dr.kind == "uniform" and runs and runs[-1][0][0].kind == "uniform":
                run, cols = runs[-1]
                run.append(dr)
                cols.append(slice(cols[-1].stop, cols[-1].stop + size))
            else:
                runs.append(([dr], [slice(0, size)]))
        return runs


def _draws_numbers(dr: Draw) -> bool:
    """Whether ``dr`` takes numbers from the generator (a uniform draw of a degenerate range does not, as
    :func:`uniform`)."""
    return dr.kind != "uniform" or dr.bounds[1] > dr.bounds[0]


def _sample(rng: np.random.Generator, dr: Draw, size: tuple[int, ...]) -> Array:
    """The numbers of draw ``dr`` in an array of shape ``size``, from ``rng`` (the one rule of :class:`Draw`)."""
    if dr.kind == "uniform":
        return uniform(rng, dr.bounds, size)
    if dr.kind == "normal":
        return rng.normal(size=size)
    return rng.choice([-1.0, 1.0], size=size)
