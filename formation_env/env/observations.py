"""Observations as declared blocks: name, size, bounds, meaning and a function of one step's context.

A leader's observation is its blocks side by side (``Engine(observation=[...])`` picks and orders them;
:data:`DEFAULT_OBSERVATION` is ``formation_v0``'s). Every entry is clipped to its block's finite bounds,
and Gaussian noise of ``obs_noise`` (in each entry's own units) is added first to the blocks that are
measurements (``noisy``). A new block is one :func:`register_block` call; the env's docstring table is
:func:`observation_table` of the registry (``FormationEnv`` lists its symbols), so it cannot drift from the code.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from .obstacles import nearest_vectors, ray_ranges

if TYPE_CHECKING:
    from .state import StepContext

#: The engine a block reads its sizes and bounds from (``formation_env.env.engine.Engine``; typed loosely so that
#: this module needs nothing of the engine's).
Engine = Any

__all__ = ["DEFAULT_OBSERVATION", "OBS_BLOCKS", "ObsBlock", "observation_table", "register_block"]

Array = NDArray[np.float64]
Bounds = tuple[Array, Array]


@dataclass(frozen=True)
class ObsBlock:
    """One observation block.

    Attributes:
        name: registry key (and the key of ``Engine.obs_blocks``).
        size: entries per leader, a symbol of the table (``size_text``) and a function of the engine.
        bounds: (low, high) of its entries (size,) given the engine; finite.
        fn: the block of every leader from a step's context, shape (B, n_l, size).
        meaning: one line for the observation table, with units.
        noisy: observation noise applies (a measurement; not the clock or the agent's id).
    """

    name: str
    size_text: str
    size: Callable[[Engine], int]
    bounds: Callable[[Engine], Bounds]
    fn: Callable[[StepContext], Array]
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


def observation_table() -> str:
    """The Markdown table of every registered block (the env's docstring holds it; a test compares)."""
    rows = ["| block | size | meaning | bounds |", "|---|---|---|---|"]
    rows += [f"| ``{b.name}`` | {b.size_text} | {b.meaning} | {b.bounds_text} |" for b in OBS_BLOCKS.values()]
    return "\n".join(rows)


def _fill(size: int, lo: float, hi: float) -> Bounds:
    return np.full(size, lo), np.full(size, hi)


def _extent(eng: Engine) -> Array:
    return np.asarray(eng.bounds[1] - eng.bounds[0], dtype=np.float64)


def _leaders(ctx: StepContext, a: Array) -> Array:
    return a[:, ctx.engine.leaders]


# ---------------------------------------------------------------------------- the blocks
register_block(
    ObsBlock(
        "position", "d", lambda e: e.d, lambda e: (e.bounds[0], e.bounds[1]),
        lambda c: _leaders(c, c.state.pos), "own position p_i (m)", "W",
    )
)  # fmt: skip
register_block(
    ObsBlock(
        "velocity", "d", lambda e: e.d, lambda e: _fill(e.d, -e.v_bound, e.v_bound),
        lambda c: _leaders(c, c.state.vel), "own velocity (m/s)", "+-v",
    )
)  # fmt: skip


def _other_leaders(ctx: StepContext) -> Array:
    eng = ctx.engine
    pl = ctx.state.pos[:, eng.leaders]  # (B, n_l, d)
    rel = pl[:, eng.other_leaders] - pl[:, :, None, :]  # (B, n_l, n_l - 1, d)
    return rel.reshape(rel.shape[0], eng.n_l, -1)


register_block(
    ObsBlock(
        "other_leaders", "(n_l - 1) d", lambda e: (e.n_l - 1) * e.d,
        lambda e: (np.tile(-_extent(e), e.n_l - 1), np.tile(_extent(e), e.n_l - 1)),
        _other_leaders, "p_j - p_i for the other leaders, in leader order (m)", "+-E",
    )
)  # fmt: skip
register_block(
    ObsBlock(
        "goal", "d", lambda e: e.d, lambda e: (-_extent(e), _extent(e)),
        lambda c: _leaders(c, c.state.goal - c.state.pos), "own goal (reference) position minus p_i (m)", "+-E",
    )
)  # fmt: skip
register_block(
    ObsBlock(
        "goal_velocity", "d", lambda e: e.d, lambda e: _fill(e.d, -e.v_bound, e.v_bound),
        lambda c: _leaders(c, c.state.goal_vel), "velocity of the own goal position (m/s; 0 if static)", "+-v",
    )
)  # fmt: skip


def _per_leader(ctx: StepContext, a: Array) -> Array:
    """A per-env array (B, k) repeated for every leader, (B, n_l, k)."""
    return np.repeat(a.reshape(a.shape[0], 1, -1), ctx.engine.n_l, axis=1)


register_block(
    ObsBlock(
        "theta", "d^2", lambda e: e.d * e.d, lambda e: _fill(e.d * e.d, -e.theta_clip, e.theta_clip),
        lambda c: _per_leader(c, c.theta), "Theta of the least-squares affine fit of all agents, row-major", "+-3",
    )
)  # fmt: skip
register_block(
    ObsBlock(
        "time", "1", lambda e: 1, lambda e: _fill(1, 0.0, 1.0),
        lambda c: _per_leader(c, c.state.k * (1.0 / c.engine.max_cycles)), "k / max_cycles", "[0, 1]", noisy=False,
    )
)  # fmt: skip
register_block(
    ObsBlock(
        "formation_error", "1", lambda e: 1, lambda e: _fill(1, 0.0, float(np.linalg.norm(_extent(e)))),
        lambda c: _per_leader(c, c.state.err), "RMS distance of all agents from their affine fit (m)", "[0, \\|E\\|]",
    )
)  # fmt: skip


def _obstacle_size(eng: Engine) -> int:
    return eng.n_rays if eng.d == 2 else eng.n_nearest * eng.d


def _obstacles(ctx: StepContext) -> Array:
    eng = ctx.engine
    o = ctx.state.pos[:, eng.leaders]
    rng_ = eng.obstacle_range
    if eng.d == 2:
        return ray_ranges(o, eng.ray_dirs, ctx.capsules, rng_) * (1.0 / rng_)
    return nearest_vectors(o, ctx.capsules, eng.n_nearest, rng_).reshape(o.shape[0], eng.n_l, -1)


register_block(
    ObsBlock(
        "obstacles", "2D: R; 3D: N d", _obstacle_size,
        lambda e: _fill(_obstacle_size(e), 0.0 if e.d == 2 else -1.0, 1.0), _obstacles,
        "2D: range to the first obstacle along world rays at angles 2 pi j / R, divided by the sensing range; "
        "3D: per nearest obstacle, unit direction times (1 - surface distance / range)^+", "[0, 1]; 3D [-1, 1]",
    )
)  # fmt: skip


def _nearest_agents(ctx: StepContext) -> Array:
    """The k nearest other agents (followers included) of each leader within the sensing radius: relative
    position (d) and a visibility flag (1) each, nearest first; unseen slots are zero."""
    eng = ctx.engine
    pos = ctx.state.pos
    B, n, d = pos.shape
    k = eng.k_nearest
    rel = pos[:, None, :, :] - pos[:, eng.leaders, None, :]  # (B, n_l, n, d)
    dist = np.sqrt(np.einsum("blnd,blnd->bln", rel, rel))
    dist[:, np.arange(eng.n_l), eng.leaders] = np.inf  # not oneself
    kk = min(k, n - 1)
    idx = np.argsort(dist, axis=-1, kind="stable")[..., :kk]
    near = np.take_along_axis(rel, idx[..., None], axis=2)
    seen = np.take_along_axis(dist, idx, axis=2) <= eng.sense_radius
    out = np.zeros((B, eng.n_l, k, d + 1))
    out[:, :, :kk, :d] = near * seen[..., None]
    out[:, :, :kk, d] = seen
    return out.reshape(B, eng.n_l, -1)


def _nearest_bounds(eng: Engine) -> Bounds:
    one_lo = np.concatenate([-_extent(eng), [0.0]])
    one_hi = np.concatenate([_extent(eng), [1.0]])
    return np.tile(one_lo, eng.k_nearest), np.tile(one_hi, eng.k_nearest)


register_block(
    ObsBlock(
        "nearest_agents", "k (d + 1)", lambda e: e.k_nearest * (e.d + 1), _nearest_bounds, _nearest_agents,
        "the k nearest other agents (followers too) within ``sense_radius``, nearest first: p_j - p_i (m) and "
        "1 if seen (an unseen slot is all 0)", "+-E, [0, 1]",
    )
)  # fmt: skip
register_block(
    ObsBlock(
        "agent_id", "n_l", lambda e: e.n_l, lambda e: _fill(e.n_l, 0.0, 1.0),
        lambda c: np.broadcast_to(np.eye(c.engine.n_l), (c.state.pos.shape[0], c.engine.n_l, c.engine.n_l)),
        "one-hot of the leader's index", "{0, 1}", noisy=False,
    )
)  # fmt: skip


register_block(
    ObsBlock(
        "task", "scenario's", lambda e: len(e.scenario.task_feature_bounds()[0]),
        lambda e: e.scenario.task_feature_bounds(), lambda c: c.engine.scenario.task_features(c),
        "what the scenario says the task needs, relative to the formation (``Scenario.task_features``; e.g. "
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

    def __call__(self, ctx: StepContext) -> NDArray[np.float32]:
        """Every leader's observation, (B, n_l, obs_dim) float32, clipped to the bounds."""
        obs = np.concatenate([blk.fn(ctx) for blk in self.blocks], axis=-1, dtype=np.float64)
        if self.noise > 0.0 and ctx.rng is not None:
            if isinstance(ctx.rng, np.random.Generator):
                noise = ctx.rng.normal(0.0, self.noise, obs.shape)
            else:  # one generator per environment (the vectorised env): env b draws as the single env would
                noise = np.stack([g.normal(0.0, self.noise, obs.shape[1:]) for g in ctx.rng])
            obs = obs + noise * self.noise_mask
        np.clip(obs, self.low, self.high, out=obs)
        return obs.astype(np.float32)
