"""Rewards as registered terms: name, default weight, and a function of one step's context.

Leader i's reward is sum_t w_t term_t(ctx)_i over the registered terms (:data:`REWARD_TERMS`), with the
weights of :data:`DEFAULT_WEIGHTS`, then the scenario's (``Scenario.weights``), then the caller's
(``reward_weights=``). A term returns (B, n_l) (per leader) or (B,) (shared by the team); its sign is in
the term, so weights are magnitudes. A term of weight 0 is not computed. A new term is one
:func:`reward_term` decoration.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from .state import EngineState, StepContext

__all__ = ["DEFAULT_WEIGHTS", "REWARD_TERMS", "TERMS", "RewardTerm", "reward_table", "reward_term", "total_reward"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class RewardTerm:
    """A reward term: ``fn(ctx)`` (B, n_l) or (B,), its default weight, one line of meaning (with the sign)."""

    name: str
    weight: float
    fn: Callable[[StepContext], Array]
    meaning: str


#: Every registered term, by name.
TERMS: dict[str, RewardTerm] = {}


def reward_term(name: str, weight: float, meaning: str) -> Callable[[Callable[[StepContext], Array]], RewardTerm]:
    """Register the decorated function as reward term ``name`` with default ``weight``."""

    def add(fn: Callable[[StepContext], Array]) -> RewardTerm:
        if name in TERMS:
            raise ValueError(f"reward term {name!r} is registered already")
        TERMS[name] = term = RewardTerm(name, float(weight), fn, meaning)
        return term

    return add


@reward_term("progress", 1.0, "g_i(k) - g_i(k+1): the leader's approach to its goal position (m)")
def _progress(ctx: StepContext) -> Array:
    assert ctx.prev is not None
    return ctx.prev.goal_dist - ctx.state.goal_dist


@reward_term("distance", 0.0, "-T g_i(k+1): the leader's distance to its goal, per second (m s)")
def _distance(ctx: StepContext) -> Array:
    return -ctx.engine.dt * ctx.state.goal_dist


#: Scales of the ``approach`` term: velocity errors weigh as position errors TAU_APPROACH s long, and the
#: log's floor EPS_APPROACH (m) is the distance below which further approach earns little more.
TAU_APPROACH, EPS_APPROACH = 1.0, 0.02


def phase_distance(state: EngineState, engine: Any) -> Array:
    """Every agent's distance to its goal state in phase space, sqrt(g^2 + TAU^2 |v - v*|^2), (B, n), m: g the
    length of the scenario's route to the goal (``Scenario.route_distance``; straight by default)."""
    g = engine.scenario.route_distance(state.pos, state.goal, state.params)
    ev = state.vel - state.goal_vel
    return np.sqrt(g * g + TAU_APPROACH**2 * np.einsum("bnd,bnd->bn", ev, ev))


@reward_term(
    "approach",
    0.0,
    "mean over all agents (followers too) of log(eps + s_i(k)) - log(eps + s_i(k+1)), s_i the agent's "
    "phase-space distance to its goal state sqrt(g^2 + (1 s)^2 |v - v*|^2), g its route's length to the goal "
    "(the scenario's, round obstacles it knows; straight by default), eps = 0.02 m; shared by the team: "
    "potential shaping that rewards the whole team arriving and coming to rest, as much for the last "
    "centimetres as for the first metres",
)
def _approach(ctx: StepContext) -> Array:
    assert ctx.prev is not None
    before, after = phase_distance(ctx.prev, ctx.engine), phase_distance(ctx.state, ctx.engine)
    return np.mean(np.log(EPS_APPROACH + before) - np.log(EPS_APPROACH + after), axis=1)


@reward_term("formation", 1.0, "-T e(k+1): the affine-image formation error, per second (m s)")
def _formation(ctx: StepContext) -> Array:
    return -ctx.engine.dt * ctx.state.err


@reward_term("effort", 0.01, "-T |a_i|^2 / p: the squared clipped action, per input and second (s)")
def _effort(ctx: StepContext) -> Array:
    a = ctx.actions
    return -(ctx.engine.dt / a.shape[-1]) * np.einsum("blp,blp->bl", a, a)


@reward_term("collision", 10.0, "-1 on a collision (agents, obstacles, leaving the world box)")
def _collision(ctx: StepContext) -> Array:
    return -ctx.collision.astype(np.float64)


#: Clearance (m) below which the ``proximity`` term starts to cost.
PROXIMITY_MARGIN = 0.3


@reward_term(
    "proximity",
    0.0,
    "-T max(0, 1 - c / 0.3 m), c the smallest gap between surfaces (agents, obstacles): a warning that grows "
    "from 0 at 0.3 m clearance to 1 per second at contact, before the collision penalty",
)
def _proximity(ctx: StepContext) -> Array:
    return -ctx.engine.dt * np.clip(1.0 - ctx.clearance / PROXIMITY_MARGIN, 0.0, 1.0)


@reward_term("success", 10.0, "+1 on success")
def _success(ctx: StepContext) -> Array:
    return ctx.success.astype(np.float64)


@reward_term(
    "tolerance",
    0.0,
    "+T while the scenario's success test holds at this sample (every agent within "
    "goal_tol of its goal, formation error below formation_tol, no collision), per second (s)",
)
def _tolerance(ctx: StepContext) -> Array:
    return ctx.engine.dt * ctx.at_goal.astype(np.float64)


#: Names of the registered terms, in order.
REWARD_TERMS: tuple[str, ...] = tuple(TERMS)
#: Default weights of the registered terms.
DEFAULT_WEIGHTS: dict[str, float] = {t.name: t.weight for t in TERMS.values()}


def total_reward(ctx: StepContext, weights: dict[str, float]) -> Array:
    """sum_t w_t term_t for every leader, shape (B, n_l)."""
    B, nl = ctx.state.goal_dist.shape
    out = np.zeros((B, nl))
    for name, w in weights.items():
        if w != 0.0:
            val = TERMS[name].fn(ctx)
            out += w * (val if val.ndim == 2 else val[:, None])
    return out


def reward_table() -> str:
    """The Markdown table of every registered term (the env's docstring holds it; a test compares)."""
    rows = ["| term | default weight | value |", "|---|---|---|"]
    rows += [f"| ``{t.name}`` | {t.weight:g} | {t.meaning} |" for t in TERMS.values()]
    return "\n".join(rows)
