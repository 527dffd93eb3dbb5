"""Observations as declared blocks: name, size, bounds, meaning and a function of one step's context.

A leader's observation is its blocks side by side (``Engine(observation=[...])`` picks and orders them;
:data:`DEFAULT_OBSERVATION` is ``formation_v0``'s). Every entry is clipped to its block's finite bounds,
and Gaussian noise of ``obs_noise`` (in each entry's own units) is added first to the blocks that are
measurements (``noisy``). A block's ``row(b, out, lo, ...)`` is a compiled function that writes env b's
entries of every leader i into ``out[i, lo:lo + size]``; its other parameters are named after the step's
arrays it reads (:data:`formation_env.env.kernel.ARRAYS`: ``pos``, ``leaders``, ``theta``, ...). A new block is
one :func:`observation_block` decoration (or a :func:`register_block` call); the env's docstring table is
:func:`observation_table` of the registry (``FormationEnv`` lists its symbols), so it cannot drift from the code.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ._numba import jit
from .obstacles import ray_range, toward_axis

#: The engine a block reads its sizes and bounds from (``formation_env.env.engine.Engine``; typed loosely so that
#: this module needs nothing of the engine's).
Engine = Any

__all__ = ["DEFAULT_OBSERVATION", "OBS_BLOCKS", "ObsBlock", "observation_block", "observation_table", "register_block"]

Array = NDArray[np.float64]
Ints = NDArray[np.int64]
Bounds = tuple[Array, Array]


@dataclass(frozen=True)
class ObsBlock:
    """One observation block.

    Attributes:
        name: registry key (and the key of ``Engine.obs_blocks``).
        size: entries per leader, a symbol of the table (``size_text``) and a function of the engine.
        bounds: (low, high) of its entries (size,) given the engine; finite.
        row: the compiled ``row(b, out, lo, ...)`` (the module docstring); None: the scenario's ``task_row``.
        meaning: one line for the observation table, with units.
        noisy: observation noise applies (a measurement; not the clock or the agent's id).
    """

    name: str
    size_text: str
    size: Callable[[Engine], int]
    bounds: Callable[[Engine], Bounds]
    row: Any
    meaning: str
    bounds_text: str
    noisy: bool = True


#: Every registered block, by name.
OBS_BLOCKS: dict[str, ObsBlock] = {}

#: The blocks of ``formation_v0``, in order.
DEFAULT_OBSERVATION: tuple[str, ...] = (
    "position",
    "velocity",
    "other_leaders",
    "goal",
    "goal_velocity",
    "theta",
    "time",
    "formation_error",
    "obstacles",
)


def register_block(block: ObsBlock) -> ObsBlock:
    """Add ``block`` to :data:`OBS_BLOCKS` (a name may be registered once)."""
    if block.name in OBS_BLOCKS:
        raise ValueError(f"observation block {block.name!r} is registered already")
    OBS_BLOCKS[block.name] = block
    return block


def observation_block(
    name: str,
    size: Callable[[Engine], int],
    bounds: Callable[[Engine], Bounds],
    meaning: str,
    *,
    size_text: str,
    bounds_text: str,
    noisy: bool = True,
) -> Callable[[Callable[..., None]], Any]:
    """Register the decorated ``row(b, out, lo, ...)`` as observation block ``name`` (the fields of
    :class:`ObsBlock`); the function becomes its compiled row."""

    def add(fn: Callable[..., None]) -> Any:
        row = jit(fn)
        register_block(ObsBlock(name, size_text, size, bounds, row, meaning, bounds_text, noisy))
        return row

    return add


def observation_table() -> str:
    """The Markdown table of every registered block (the env's docstring holds it; a test compares)."""
    rows = ["| block | size | meaning | bounds |", "|---|---|---|---|"]
    rows += [f"| ``{b.name}`` | {b.size_text} | {b.meaning} | {b.bounds_text} |" for b in OBS_BLOCKS.values()]
    return "\n".join(rows)


def _fill(size: int, lo: float, hi: float) -> Bounds:
    return np.full(size, lo), np.full(size, hi)


def _extent(eng: Engine) -> Array:
    return np.asarray(eng.bounds[1] - eng.bounds[0], dtype=np.float64)


# ---------------------------------------------------------------------------- the blocks
def _obstacle_size(eng: Engine) -> int:
    return eng.n_rays if eng.d == 2 else eng.n_nearest * eng.d


def _nearest_bounds(eng: Engine) -> Bounds:
    one_lo = np.concatenate([-_extent(eng), [0.0]])
    one_hi = np.concatenate([_extent(eng), [1.0]])
    return np.tile(one_lo, eng.k_nearest), np.tile(one_hi, eng.k_nearest)


@observation_block("position", lambda e: e.d, lambda e: (e.bounds[0], e.bounds[1]), "own position p_i (m)",
                   size_text="d", bounds_text="W")  # fmt: skip
def position(b: int, out: Array, lo: int, leaders: Ints, pos: Array) -> None:  # pragma: no cover
    for i, a in enumerate(leaders):
        for k in range(pos.shape[2]):
            out[i, lo + k] = pos[b, a, k]


@observation_block("velocity", lambda e: e.d, lambda e: _fill(e.d, -e.v_bound, e.v_bound), "own velocity (m/s)",
                   size_text="d", bounds_text="+-v")  # fmt: skip
def velocity(b: int, out: Array, lo: int, leaders: Ints, vel: Array) -> None:  # pragma: no cover
    for i, a in enumerate(leaders):
        for k in range(vel.shape[2]):
            out[i, lo + k] = vel[b, a, k]


@observation_block(
    "other_leaders", lambda e: (e.n_l - 1) * e.d,
    lambda e: (np.tile(-_extent(e), e.n_l - 1), np.tile(_extent(e), e.n_l - 1)),
    "p_j - p_i for the other leaders, in leader order (m)", size_text="(n_l - 1) d", bounds_text="+-E",
)  # fmt: skip
def other_leaders(b: int, out: Array, lo: int, leaders: Ints, others: Ints, pos: Array) -> None:  # pragma: no cover
    d = pos.shape[2]
    for i in range(leaders.shape[0]):
        for j in range(others.shape[1]):
            for k in range(d):
                out[i, lo + j * d + k] = pos[b, leaders[others[i, j]], k] - pos[b, leaders[i], k]


@observation_block("goal", lambda e: e.d, lambda e: (-_extent(e), _extent(e)),
                   "own goal (reference) position minus p_i (m)", size_text="d", bounds_text="+-E")  # fmt: skip
def goal(b: int, out: Array, lo: int, leaders: Ints, pos: Array, goal: Array) -> None:  # pragma: no cover
    for i, a in enumerate(leaders):
        for k in range(pos.shape[2]):
            out[i, lo + k] = goal[b, a, k] - pos[b, a, k]


@observation_block("goal_velocity", lambda e: e.d, lambda e: _fill(e.d, -e.v_bound, e.v_bound),
                   "velocity of the own goal position (m/s; 0 if static)", size_text="d",
                   bounds_text="+-v")  # fmt: skip
def goal_velocity(b: int, out: Array, lo: int, leaders: Ints, gvel: Array) -> None:  # pragma: no cover
    for i, a in enumerate(leaders):
        for k in range(gvel.shape[2]):
            out[i, lo + k] = gvel[b, a, k]


@observation_block("theta", lambda e: e.d * e.d, lambda e: _fill(e.d * e.d, -e.theta_clip, e.theta_clip),
                   "Theta of the least-squares affine fit of all agents, row-major", size_text="d^2",
                   bounds_text="+-3")  # fmt: skip
def theta(b: int, out: Array, lo: int, theta: Array) -> None:  # pragma: no cover
    d = theta.shape[1]
    for i in range(out.shape[0]):
        for r in range(d):
            for k in range(d):
                out[i, lo + r * d + k] = theta[b, r, k]


@observation_block("time", lambda e: 1, lambda e: _fill(1, 0.0, 1.0), "k / max_cycles", size_text="1",
                   bounds_text="[0, 1]", noisy=False)  # fmt: skip
def time(b: int, out: Array, lo: int, k: Ints, max_cycles: int) -> None:  # pragma: no cover
    for i in range(out.shape[0]):
        out[i, lo] = k[b] / max_cycles


@observation_block("formation_error", lambda e: 1, lambda e: _fill(1, 0.0, float(np.linalg.norm(_extent(e)))),
                   "RMS distance of all agents from their affine fit (m)", size_text="1",
                   bounds_text="[0, \\|E\\|]")  # fmt: skip
def formation_error(b: int, out: Array, lo: int, err: Array) -> None:  # pragma: no cover
    for i in range(out.shape[0]):
        out[i, lo] = err[b]


@observation_block(
    "obstacles", _obstacle_size, lambda e: _fill(_obstacle_size(e), 0.0 if e.d == 2 else -1.0, 1.0),
    "2D: range to the first obstacle along world rays at angles 2 pi j / R, divided by the sensing range; "
    "3D: per nearest obstacle, unit direction times (1 - surface distance / range)^+",
    size_text="2D: R; 3D: N d", bounds_text="[0, 1]; 3D [-1, 1]",
)  # fmt: skip
def obstacles(  # pragma: no cover
    b: int, out: Array, lo: int, leaders: Ints, pos: Array, cur_a: Array, cur_e: Array, cur_r: Array,
    obstacle_range: float, ray_dirs: Array, n_nearest: int
) -> None:  # fmt: skip
    a, e, rad, rng = cur_a[b], cur_e[b], cur_r[b], obstacle_range
    d = pos.shape[2]
    for i, ag in enumerate(leaders):
        ox = pos[b, ag, 0]
        oy = pos[b, ag, 1]
        if d == 2:
            for q in range(ray_dirs.shape[0]):
                out[i, lo + q] = ray_range(ox, oy, ray_dirs[q, 0], ray_dirs[q, 1], a, e, rad, rng) / rng
            continue
        m = rad.shape[0]
        surf = np.empty(m)
        toward = np.empty((m, d))
        for j in range(m):
            surf[j] = toward_axis(pos[b, ag], a, e, j, toward[j]) - rad[j]
        order = np.argsort(surf, kind="mergesort")
        for q in range(n_nearest):
            for k in range(d):
                out[i, lo + q * d + k] = 0.0
            if q < m:
                j = order[q]
                norm = max(math.sqrt(np.sum(toward[j] ** 2)), 1e-12)
                mag = min(max(1.0 - surf[j] / rng, 0.0), 1.0)
                for k in range(d):
                    out[i, lo + q * d + k] = toward[j, k] / norm * mag


def _clearance_bounds(eng: Engine) -> Bounds:
    one_lo = np.concatenate([[-eng.agent_radius], np.full(eng.d, -1.0)])
    one_hi = np.concatenate([[eng.obstacle_range], np.full(eng.d, 1.0)])
    return np.tile(one_lo, eng.n), np.tile(one_hi, eng.n)


@observation_block(
    "agent_clearance", lambda e: e.n * (e.d + 1), _clearance_bounds,
    "per agent (followers too, in index order; the team's, the same in every leader's row): the gap between its disc "
    "and the nearest obstacle's surface (m, at most ``obstacle_range``), then the unit direction toward that "
    "surface (0 beyond the range)", size_text="n (d + 1)", bounds_text="[-radius, range], [-1, 1]",
)  # fmt: skip
def agent_clearance(  # pragma: no cover
    b: int, out: Array, lo: int, leaders: Ints, pos: Array, cur_a: Array, cur_e: Array, cur_r: Array, radius: float,
    obstacle_range: float,
) -> None:  # fmt: skip
    """Agent g's entries lo + g (d + 1) .. lo + g (d + 1) + d: min over capsules j of |p_g - c_j| - r_j - radius,
    c_j the nearest point of capsule j's axis a_j + t e_j (t in [0, 1]) to p_g (pos (B, n, d), cur_a and cur_e
    (B, m, d), cur_r (B, m), m); then (c_j - p_g) / |c_j - p_g| of that capsule if the gap is within
    ``obstacle_range``, else obstacle_range and 0."""
    a, e, rad = cur_a[b], cur_e[b], cur_r[b]
    n, d = pos.shape[1], pos.shape[2]
    vec = np.empty(d)
    toward = np.empty(d)
    for g in range(n):
        k0 = lo + g * (d + 1)
        best, norm = obstacle_range, 0.0
        toward[:] = 0.0
        for j in range(rad.shape[0]):
            dist = toward_axis(pos[b, g], a, e, j, vec)
            if dist - rad[j] - radius < best:
                best, norm = dist - rad[j] - radius, dist
                toward[:] = vec
        for i in range(leaders.shape[0]):
            out[i, k0] = max(best, -radius)
            for k in range(d):
                out[i, k0 + 1 + k] = toward[k] / norm if norm > 0.0 else 0.0


@observation_block(
    "nearest_agents", lambda e: e.k_nearest * (e.d + 1), _nearest_bounds,
    "the k nearest other agents (followers too) within ``sense_radius``, nearest first: p_j - p_i (m) and "
    "1 if seen (an unseen slot is all 0)", size_text="k (d + 1)", bounds_text="+-E, [0, 1]",
)  # fmt: skip
def nearest_agents(  # pragma: no cover
    b: int, out: Array, lo: int, leaders: Ints, pos: Array, k_nearest: int, sense_radius: float
) -> None:
    n, d = pos.shape[1], pos.shape[2]
    w = d + 1
    for i, me in enumerate(leaders):
        dist = np.empty(n)
        for j in range(n):
            dd = 0.0
            for k in range(d):
                dd += (pos[b, j, k] - pos[b, me, k]) ** 2
            dist[j] = math.sqrt(dd) if j != me else np.inf
        order = np.argsort(dist, kind="mergesort")
        for q in range(k_nearest):
            for k in range(w):
                out[i, lo + q * w + k] = 0.0
            if q < n - 1 and dist[order[q]] <= sense_radius:
                for k in range(d):
                    out[i, lo + q * w + k] = pos[b, order[q], k] - pos[b, me, k]
                out[i, lo + q * w + d] = 1.0


@observation_block("agent_id", lambda e: e.n_l, lambda e: _fill(e.n_l, 0.0, 1.0), "one-hot of the leader's index",
                   size_text="n_l", bounds_text="{0, 1}", noisy=False)  # fmt: skip
def agent_id(b: int, out: Array, lo: int) -> None:  # pragma: no cover
    n_l = out.shape[0]
    for i in range(n_l):
        for j in range(n_l):
            out[i, lo + j] = 1.0 if i == j else 0.0


register_block(
    ObsBlock(
        "task", "scenario's", lambda e: len(e.scenario.task_feature_bounds()[0]),
        lambda e: e.scenario.task_feature_bounds(), None,
        "what the scenario says the task needs, relative to the formation (``Scenario.task_row``; e.g. "
        "the gap's position and the room left in it)", "scenario's",
    )
)  # fmt: skip


class Observer:
    """The engine's chosen blocks, laid out: ``slices`` by name, ``low`` / ``high`` (obs_dim,) float64."""

    def __init__(self, engine: Engine, names: tuple[str, ...], noise: float, arg: str = "observation") -> None:
        unknown = [nm for nm in names if nm not in OBS_BLOCKS]
        if unknown or not names or len(set(names)) != len(names):
            raise ValueError(f"{arg} must name distinct registered blocks ({sorted(OBS_BLOCKS)}), got {list(names)}")
        self.blocks = [OBS_BLOCKS[nm] for nm in names]
        self.slices: dict[str, slice] = {}
        lows, highs, noisy = [], [], []
        off = 0
        for blk in self.blocks:
            size = blk.size(engine)
            lo, hi = (np.asarray(v, dtype=np.float64).reshape(-1) for v in blk.bounds(engine))
            if lo.shape != (size,) or hi.shape != (size,) or not (np.all(np.isfinite(lo)) and np.all(lo <= hi)):
                raise ValueError(f"observation block {blk.name!r}: bounds must be finite, low <= high, size {size}")
            self.slices[blk.name] = slice(off, off + size)
            lows.append(lo)
            highs.append(hi)
            noisy.append(np.full(size, blk.noisy))
            off += size
        self.dim = off
        self.low, self.high = np.concatenate(lows), np.concatenate(highs)
        self.noise = float(noise)
        self.noise_mask = np.concatenate(noisy).astype(np.float64)

    def __getstate__(self) -> dict[str, Any]:
        """Blocks by name (their functions are looked up again on unpickling: registered blocks pickle by name)."""
        return {**self.__dict__, "blocks": [blk.name for blk in self.blocks]}

    def __setstate__(self, d: dict[str, Any]) -> None:
        self.__dict__.update(d, blocks=[OBS_BLOCKS[nm] for nm in d["blocks"]])
