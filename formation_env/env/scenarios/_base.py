"""The scenario interface, shared batched pose helpers, and the env's named frameworks.

A scenario is a small class in its own file (MPE2 ``scenarios/``, VMAS
``BaseScenario``). The engine owns the dynamics, the follower law, the
observation and the reward formula; a scenario supplies the task:

* ``__init__(fw, *, agent_radius, horizon, **kwargs)`` ("make"): reads its own
  keyword arguments and refuses unknown ones.
* ``draws()`` and ``build(raw)``: the episode's random draws in stream order
  (:class:`Draw`: uniform in a range, standard normal, or a sign), and the
  draw-free, batched map from them to the per-episode arrays. From these the base
  class makes ``reset(rng, B)`` (B episodes from one generator: start positions,
  goal pose, obstacles, and any parameters of its own) and ``reset_each(rngs)``
  (one episode per generator, equal to ``reset(rngs[b], 1)``, with only the draws
  run per generator: the vectorised env's auto-reset).
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

import functools
import itertools
import math
from collections.abc import Callable, Sequence
from typing import Any, ClassVar, NamedTuple

import numpy as np
from numpy.typing import NDArray

from formation_env.core.errors import FormationError
from formation_env.core.framework import Framework
from formation_env.core.validation import check_kwargs_consumed

from .. import _kernel

__all__ = [
    "NAMED_FRAMEWORKS",
    "Draw",
    "DrawPlan",
    "Scenario",
    "affine_batch",
    "bipyramid_3d",
    "gram_stress",
    "rotation_2d",
    "rotation_3d",
    "uniform",
]

Array = NDArray[np.float64]


def _root(u: Array, d: int) -> Array:
    """u^(1/d) elementwise, with the bits of the compiled redraws (``_kernel.settle_starts``) on every machine:
    ``np.sqrt`` for d = 2 (correctly rounded everywhere), else C's ``pow`` (``math.pow``) value by value, since
    numpy's own power may run a SIMD kernel (AVX-512) that differs from ``pow`` in the last bit."""
    if d == 2:
        return np.sqrt(u)
    if d == 1:
        return np.array(u, dtype=np.float64)
    e = 1.0 / d
    return np.fromiter(map(math.pow, u.ravel(), itertools.repeat(e)), np.float64, u.size).reshape(u.shape)


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
    def draws(self) -> list[Draw]:
        """The random draws of one episode, in stream order (the last two are :meth:`follower_draws` where
        the start positions are noisy). :meth:`reset` and :meth:`reset_each` take them from here."""
        raise NotImplementedError

    def build(self, raw: dict[str, Array]) -> tuple[dict[str, Array], tuple[Array, Array] | None]:
        """Per-episode arrays from the draws (``raw[name]`` of shape (B, *shape)), batched and draw-free.

        Returns (params, pose): params as :meth:`reset` (without ``start`` when pose is given), and the
        start pose (Theta0 (B, d, d), b0 (B, d)) on which :meth:`reset` places the agents, or None when
        params hold ``start``.
        """
        raise NotImplementedError

    def reset(self, rng: np.random.Generator, B: int) -> dict[str, Array]:
        """Per-episode arrays: ``start`` (B, n, d), ``goal_theta`` (B, d, d), ``goal_b`` (B, d),
        ``segments`` (B, S, 2, d), ``circles`` (B, C, d + 1), plus the scenario's own.

        Each draw of :meth:`draws` is one generator call for all B episodes, in order; then the
        followers' noise is redrawn (for the offending episodes) as in :meth:`start_positions`."""
        raw = self._plan.draw(rng, B)
        params, pose = self.build(raw)
        if pose is not None:
            params["start"] = self._place_start(pose, raw, lambda todo: self._noise_plan.draw(rng, todo.size))
        return params

    def reset_each(
        self,
        rngs: Sequence[np.random.Generator],
        bits: tuple[NDArray[np.int64], NDArray[np.int64]] | None = None,
    ) -> dict[str, Array]:
        """One episode per generator, batched: entry b equals ``reset(rngs[b], 1)`` (the same draws; the
        geometry runs once for all episodes, so values agree to rounding).

        Per generator only the draws run, one call per run of same-kind draws (:class:`DrawPlan`), and
        the followers' redraws one at a time, as ``reset(rngs[b], 1)`` makes them. The generators must be
        distinct objects. A scenario without :meth:`draws` (one that overrides :meth:`reset` only) resets
        per generator. ``bits``: ``_kernel.bit_generators(rngs)``, where the caller keeps them (and the generators
        alive) across calls; else they are looked up here.
        """
        if type(self).draws is Scenario.draws:
            eps = [self.reset(g, 1) for g in rngs]
            return {key: np.concatenate([ep[key] for ep in eps]) for key in eps[0]}
        if self._plan.runs is None:
            bits = None
        elif bits is None:
            bits = _kernel.bit_generators(list(rngs))
        raw = self._plan.draw_each(rngs, bits)
        params, pose = self.build(raw)
        if pose is None:
            return params
        if bits is not None and "_u" in raw and self.fw.n <= ALL_PAIRS_GAP_UP_TO:  # the redraws compiled too
            base = affine_batch(self.r, *pose)
            params["start"] = start = base.copy()
            dirs, u = (np.ascontiguousarray(raw[key]) for key in ("_dirs", "_u"))
            gap3 = 3.0 * self.agent_radius
            f = (start, base, dirs, u, self._follower_index, gap3, self.follower_noise, 1.0 / self.d)
            _kernel.settle_starts(*f, self.start_tries, *bits)
        else:
            params["start"] = self._place_start(
                pose, raw, lambda todo: self._noise_plan.draw_each([rngs[b] for b in todo.tolist()])
            )
        return params

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

    def follower_draws(self) -> list[Draw]:
        """The followers' start noise, the last draws of an episode: directions ``_dirs`` (n_f, d)
        standard normal, radii ``_u`` (n_f,) uniform in [0, 1]; none without followers or noise."""
        if self.follower_noise <= 0 or len(self.fw.followers) == 0:
            return []
        return list(self._noise_plan.draws)

    @property
    def compiled_draws(self) -> bool:
        """Whether :meth:`reset_each` makes every draw in compiled code (numba, a plan without sign draws): then
        it is also the quicker way to draw one episode, with the numbers of ``reset(rng, 1)`` (tests)."""
        return _kernel.DRAWS and type(self).draws is not Scenario.draws and self._plan.runs is not None

    @functools.cached_property
    def _plan(self) -> DrawPlan:
        """The layout of :meth:`draws` (built once)."""
        return DrawPlan(self.draws())

    @functools.cached_property
    def _noise_plan(self) -> DrawPlan:
        """The followers' noise draws (:meth:`follower_draws`, whatever ``follower_noise``), for the redraws."""
        nf = len(self.fw.followers)
        return DrawPlan([Draw("_dirs", (nf, self.d), "normal"), Draw("_u", (nf,))])

    @functools.cached_property
    def _pairs(self) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
        """All agent pairs (i < j) as index arrays."""
        iu, ju = np.triu_indices(self.fw.n, 1)
        return iu, ju

    @functools.cached_property
    def _followers(self) -> NDArray[np.intp] | slice:
        """The followers' indices: a slice when they are consecutive (a view, cheaper than fancy indexing)."""
        f = np.asarray(self.fw.followers, dtype=np.intp)
        if f.size and np.array_equal(f, np.arange(f[0], f[0] + f.size)):
            return slice(int(f[0]), int(f[0]) + f.size)
        return f

    @functools.cached_property
    def _follower_index(self) -> NDArray[np.int64]:
        """The followers' indices as an int64 array (for :func:`_kernel.noisy_starts`)."""
        return np.asarray(self.fw.followers, dtype=np.int64)

    def _noisy(
        self, out: Array, base: Array, todo: NDArray[np.intp], noise: dict[str, Array], follower_noise: float
    ) -> NDArray[np.bool_]:
        """Move the followers of episodes ``todo`` (m,) from ``base`` (B, n, d) by their noise draws
        ``noise["_dirs"]`` (m, n_f, d) and ``noise["_u"]`` (m, n_f) (:meth:`follower_draws`), within a ball of
        ``follower_noise`` m: each along its direction, by ``follower_noise`` u^(1/d). The episodes whose agents
        are then no two closer than 3 radii get these positions in ``out`` (B, n, d); returns that test (m,).

        Compiled per episode (``_kernel.noisy_starts``, the same operations) up to ``ALL_PAIRS_GAP_UP_TO``
        agents when numba is there; numpy otherwise, and a k-d tree for larger swarms."""
        dirs = noise["_dirs"]
        rad = follower_noise * _root(noise["_u"], self.d)
        gap3 = 3.0 * self.agent_radius
        if _kernel.AVAILABLE and self.fw.n <= ALL_PAIRS_GAP_UP_TO:
            return _kernel.noisy_starts(
                out, base, todo, np.ascontiguousarray(dirs), np.ascontiguousarray(rad), self._follower_index, gap3
            )
        # norms as np.linalg.norm computes them, without its overhead
        dirs = dirs / np.sqrt(np.add.reduce(dirs * dirs, axis=-1, keepdims=True))
        trial = base[todo]
        trial[:, self._followers] += dirs * rad[:, :, None]
        if self.fw.n > ALL_PAIRS_GAP_UP_TO:  # large swarms: a k-d tree finds the close pairs in O(n log n)
            from scipy.spatial import cKDTree

            ok = np.array([not cKDTree(t).query_pairs(gap3, output_type="ndarray").size for t in trial], dtype=bool)
        else:
            iu, ju = self._pairs
            diff = trial[:, iu] - trial[:, ju]
            ok = np.sqrt(np.add.reduce(diff * diff, axis=-1).min(axis=1)) >= gap3
        out[todo[ok]] = trial[ok]
        return ok

    def _settle(
        self,
        base: Array,
        noise: dict[str, Array],
        redraw: Callable[[NDArray[np.intp]], dict[str, Array]],
        follower_noise: float,
        tries: int,
    ) -> Array:
        """Start positions (B, n, d): ``base`` with the followers moved by the noise draws ``noise`` of all B
        episodes (:meth:`_noisy`). Episodes whose agents would start closer than 3 radii draw again, one draw per
        episode a round (``redraw(episodes)``: the noise draws of those episodes), ``tries`` draws in all; those
        still too close keep zero noise."""
        out = base.copy()
        todo = np.arange(base.shape[0])
        todo = todo[~self._noisy(out, base, todo, noise, follower_noise)]
        for _ in range(tries - 1):
            if todo.size == 0:
                break
            todo = todo[~self._noisy(out, base, todo, redraw(todo), follower_noise)]
        return out

    def _place_start(
        self,
        pose: tuple[Array, Array],
        raw: dict[str, Array],
        redraw: Callable[[NDArray[np.intp]], dict[str, Array]],
    ) -> Array:
        """Start positions (B, n, d) on ``pose`` = (Theta0, b0), followers moved by the noise of the draws
        ``_dirs``, ``_u`` (:meth:`follower_draws`; none: no noise) and, where agents start closer than 3 radii,
        of ``redraw`` (:meth:`_settle`, ``start_tries`` draws in all)."""
        base = affine_batch(self.r, *pose)
        if "_u" not in raw:
            return base
        return self._settle(base, raw, redraw, self.follower_noise, self.start_tries)

    def start_positions(
        self, rng: np.random.Generator, theta: Array, b: Array, follower_noise: float, tries: int = 20
    ) -> Array:
        """Leaders on the pose (theta, b), followers there plus uniform noise in a ball of ``follower_noise`` m.

        Draws again (for the offending episodes only) while two agents would start
        closer than 3 agent radii; after ``tries`` draws those keep zero noise.
        Returns shape (B, n, d).
        """
        base = affine_batch(self.r, theta, b)
        if follower_noise <= 0 or len(self.fw.followers) == 0 or tries < 1:
            return base
        plan = self._noise_plan
        return self._settle(
            base, plan.draw(rng, base.shape[0]), lambda todo: plan.draw(rng, todo.size), follower_noise, tries
        )


class Draw(NamedTuple):
    """One random draw of an episode: ``shape`` numbers of ``kind`` "uniform" (in ``bounds``, as
    :func:`uniform`: a degenerate range draws nothing), "normal" (standard) or "sign" (-1 or +1,
    as ``rng.choice([-1.0, 1.0])``)."""

    name: str
    shape: tuple[int, ...] = ()
    kind: str = "uniform"
    bounds: tuple[float, float] = (0.0, 1.0)


class DrawPlan:
    """The draws of one episode laid out as columns of a (B, K) array, and the generator calls that fill it.

    ``draw(rng, B)`` makes one call per draw for B episodes (the scenarios' batched stream);
    ``draw_each(rngs)`` makes, per generator, one call per run of same-kind draws (``rng.random`` for
    consecutive uniform draws, ``rng.standard_normal`` for normal ones), which consumes the stream
    exactly as ``draw(rng, 1)`` does: uniform(lo, hi) is lo + (hi - lo) u, as numpy computes it.
    """

    def __init__(self, draws: Sequence[Draw]) -> None:
        names = [dr.name for dr in draws]
        if len(set(names)) != len(names):
            raise FormationError(f"draw names must be unique, got {names}")
        for dr in draws:
            if dr.kind not in ("uniform", "normal", "sign"):
                raise FormationError(f"draw {dr.name!r}: kind must be uniform, normal or sign, got {dr.kind!r}")
        self.draws = list(draws)
        self.cols: dict[str, slice] = {}
        lo: list[float] = []
        span: list[float] = []
        calls: list[list[Any]] = []  # [kind, start, stop] runs of the per-generator path
        k = 0
        for dr in self.draws:
            size = int(np.prod(dr.shape, dtype=np.int64))
            self.cols[dr.name] = slice(k, k + size)
            a, b = (float(dr.bounds[0]), float(dr.bounds[1])) if dr.kind == "uniform" else (0.0, 1.0)
            drawn = size > 0 and (dr.kind != "uniform" or b > a)
            lo += [a] * size
            span += [b - a if b > a else 0.0] * size
            if drawn:
                merge = calls and calls[-1][0] == dr.kind != "sign" and calls[-1][2] == k
                if merge:
                    calls[-1][2] = k + size
                else:
                    calls.append([dr.kind, k, k + size])
            k += size
        self.K = k
        self.calls = [(str(c[0]), int(c[1]), int(c[2])) for c in calls]
        #: the calls as rows [kind (0 uniform, 1 normal), start, stop] for ``_kernel.draw_runs``; None with sign draws
        self.runs: NDArray[np.int64] | None = None
        if all(c[0] != "sign" for c in self.calls):
            code = {"uniform": 0, "normal": 1}
            self.runs = np.array([(code[c[0]], c[1], c[2]) for c in self.calls], dtype=np.int64).reshape(-1, 3)
        lo_a, span_a = np.array(lo), np.array(span)
        kinds = np.array(
            [dr.kind for dr in self.draws for _ in range(self.cols[dr.name].start, self.cols[dr.name].stop)]
        )
        # draw_each maps u to lo + (hi - lo) u on the runs of uniform columns other than [0, 1]
        scaled = np.concatenate([[0], (kinds == "uniform") & ((lo_a != 0.0) | (span_a != 1.0)), [0]])
        edges = np.flatnonzero(np.diff(scaled.astype(np.int8)))
        self._scaled = [(slice(a, b), lo_a[a:b], span_a[a:b]) for a, b in zip(edges[::2], edges[1::2], strict=True)]
        self._sign = np.flatnonzero(kinds == "sign")
        self._shapes = [(dr.name, self.cols[dr.name], dr.shape) for dr in self.draws]

    def draw(self, rng: np.random.Generator, B: int) -> dict[str, Array]:
        """One generator call per draw, each for all B episodes (the scenarios' ``reset(rng, B)`` stream)."""
        out: dict[str, Array] = {}
        for dr in self.draws:
            size = (B, *dr.shape)
            if dr.kind == "uniform":
                out[dr.name] = uniform(rng, dr.bounds, size)
            elif dr.kind == "normal":
                out[dr.name] = rng.normal(size=size)
            else:
                out[dr.name] = rng.choice([-1.0, 1.0], size=size)
        return out

    def draw_each(
        self, rngs: Sequence[np.random.Generator], bits: tuple[NDArray[np.int64], NDArray[np.int64]] | None = None
    ) -> dict[str, Array]:
        """One episode per generator: entry b equals ``draw(rngs[b], 1)``. With ``bits`` (``_kernel.bit_generators``
        of ``rngs``, for plans without sign draws) every call is compiled (``_kernel.draw_runs``); else the Python
        work per generator is one call per run of same-kind draws, each run drawn from every generator in turn
        (distinct generators: each still makes its calls in the plan's order)."""
        B = len(rngs)
        raw = np.zeros((B, self.K))
        if bits is not None and self.runs is not None:
            _kernel.draw_runs(raw, *bits, self.runs)
        else:
            for kind, a, b in self.calls:
                rows = raw[:, a:b]
                if kind == "uniform":
                    for g, row in zip(rngs, rows, strict=True):
                        g.random(out=row)
                elif kind == "normal":
                    for g, row in zip(rngs, rows, strict=True):
                        g.standard_normal(out=row)
                else:
                    for g, row in zip(rngs, rows, strict=True):
                        row[:] = g.integers(0, 2, size=b - a)
        if self._sign.size:
            raw[:, self._sign] = 2.0 * raw[:, self._sign] - 1.0  # choice([-1, 1]) picks index integers(0, 2)
        for cols, lo, span in self._scaled:
            raw[:, cols] = lo + span * raw[:, cols]
        return {name: raw[:, cols].reshape(B, *shape) for name, cols, shape in self._shapes}
