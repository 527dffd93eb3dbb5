"""Rewards as registered terms: name, default weight, and a function of one step's context.

Leader i's reward is sum_t w_t term_t_i over the registered terms (:data:`REWARD_TERMS`), with the
weights of :data:`DEFAULT_WEIGHTS`, then the scenario's (``Scenario.weights``), then the caller's
(``reward_weights=``). A term is a compiled ``row(b, out, w, ...)`` that adds w times env b's value of every
leader to ``out`` (n_l,) (a team term adds the same to all); its other parameters are named after the step's
arrays it reads (:func:`formation_env.env.kernel.call`). Its sign is in the term, so weights are magnitudes. A term of
weight 0 is not computed. A new term is one :func:`reward_term` decoration.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ._numba import jit
from .kernel import FLAG_AT_GOAL, FLAG_COLLISION, FLAG_SUCCESS

Array = NDArray[np.float64]
Bools = NDArray[np.bool_]

__all__ = ["DEFAULT_WEIGHTS", "REWARD_TERMS", "TERMS", "RewardTerm", "reward_table", "reward_term"]


@dataclass(frozen=True)
class RewardTerm:
    """A reward term: its compiled ``row`` (the module docstring), default weight, one line of meaning (with the
    sign)."""

    name: str
    weight: float
    row: Any
    meaning: str


#: Every registered term, by name.
TERMS: dict[str, RewardTerm] = {}


def reward_term(name: str, weight: float, meaning: str) -> Callable[[Callable[..., None]], Any]:
    """Register the decorated row function as reward term ``name`` with default ``weight``; the function
    becomes its compiled row."""

    def add(fn: Callable[..., None]) -> Any:
        if name in TERMS:
            raise ValueError(f"reward term {name!r} is registered already")
        row = jit(fn)
        TERMS[name] = RewardTerm(name, float(weight), row, meaning)
        return row

    return add


@reward_term("progress", 1.0, "g_i(k) - g_i(k+1): the leader's approach to its goal position (m)")
def _progress(b: int, out: Array, w: float, gdist0: Array, gdist: Array) -> None:  # pragma: no cover
    for i in range(out.shape[0]):
        out[i] += w * (gdist0[b, i] - gdist[b, i])


@reward_term(
    "route_progress",
    0.0,
    "r_i(k) - r_i(k+1): the leader's approach to its goal position along its route (m; the route of "
    "``approach``: round the obstacles the scenario knows, straight by default, then equal to ``progress``)",
)
def _route_progress(  # pragma: no cover
    b: int, out: Array, w: float, leaders: NDArray[np.int64], route0: Array, route1: Array
) -> None:
    for i in range(out.shape[0]):
        out[i] += w * (route0[b, leaders[i]] - route1[b, leaders[i]])


@reward_term("distance", 0.0, "-T g_i(k+1): the leader's distance to its goal, per second (m s)")
def _distance(b: int, out: Array, w: float, dt: float, gdist: Array) -> None:  # pragma: no cover
    for i in range(out.shape[0]):
        out[i] -= w * dt * gdist[b, i]


#: Scales of the ``approach`` term: velocity errors weigh as position errors TAU_APPROACH s long, and the
#: log's floor EPS_APPROACH (m) is the distance below which further approach earns little more.
TAU_APPROACH, EPS_APPROACH = 1.0, 0.02


@reward_term(
    "approach",
    0.0,
    "mean over all agents (followers too) of log(eps + s_i(k)) - log(eps + s_i(k+1)), s_i the agent's "
    "phase-space distance to its goal state sqrt(g^2 + (1 s)^2 |v - v*|^2), g its route's length to the goal "
    "(the scenario's, round obstacles it knows; straight by default), eps = 0.02 m; shared by the team: "
    "potential shaping that rewards the whole team arriving and coming to rest, as much for the last "
    "centimetres as for the first metres",
)
def _approach(  # pragma: no cover
    b: int, out: Array, w: float, vel0: Array, gvel0: Array, vel: Array, gvel: Array, route0: Array, route1: Array
) -> None:
    n, d = vel.shape[1], vel.shape[2]
    acc = 0.0
    for i in range(n):
        v0 = v1 = 0.0
        for k in range(d):
            v0 += (vel0[b, i, k] - gvel0[b, i, k]) ** 2
            v1 += (vel[b, i, k] - gvel[b, i, k]) ** 2
        p0 = math.sqrt(route0[b, i] ** 2 + TAU_APPROACH**2 * v0)
        p1 = math.sqrt(route1[b, i] ** 2 + TAU_APPROACH**2 * v1)
        acc += math.log(EPS_APPROACH + p0) - math.log(EPS_APPROACH + p1)
    for i in range(out.shape[0]):
        out[i] += w * acc / n


@reward_term("formation", 1.0, "-T e(k+1): the affine-image formation error, per second (m s)")
def _formation(b: int, out: Array, w: float, dt: float, err: Array) -> None:  # pragma: no cover
    for i in range(out.shape[0]):
        out[i] -= w * dt * err[b]


@reward_term("effort", 0.01, "-T |a_i|^2 / p: the squared clipped action, per input and second (s)")
def _effort(b: int, out: Array, w: float, dt: float, act: Array) -> None:  # pragma: no cover
    p = act.shape[2]
    for i in range(out.shape[0]):
        acc = 0.0
        for j in range(p):
            acc += act[b, i, j] ** 2
        out[i] -= w * (dt / p) * acc


@reward_term("collision", 10.0, "-1 on a collision (agents, obstacles, leaving the world box)")
def _collision(b: int, out: Array, w: float, flags: Bools) -> None:  # pragma: no cover
    if flags[b, FLAG_COLLISION]:
        for i in range(out.shape[0]):
            out[i] -= w


#: Clearance (m) below which the ``proximity`` term starts to cost.
PROXIMITY_MARGIN = 0.3


@reward_term(
    "proximity",
    0.0,
    "-T max(0, 1 - c / 0.3 m), c the smallest gap between surfaces (agents, obstacles): a warning that grows "
    "from 0 at 0.3 m clearance to 1 per second at contact, before the collision penalty",
)
def _proximity(b: int, out: Array, w: float, dt: float, clear: Array) -> None:  # pragma: no cover
    v = dt * min(max(1.0 - clear[b] / PROXIMITY_MARGIN, 0.0), 1.0)
    for i in range(out.shape[0]):
        out[i] -= w * v


@reward_term("success", 10.0, "+1 on success")
def _success(b: int, out: Array, w: float, flags: Bools) -> None:  # pragma: no cover
    if flags[b, FLAG_SUCCESS]:
        for i in range(out.shape[0]):
            out[i] += w


@reward_term(
    "tolerance",
    0.0,
    "+T while the scenario's success test holds at this sample (every agent within "
    "goal_tol of its goal, formation error below formation_tol, no collision), per second (s)",
)
def _tolerance(b: int, out: Array, w: float, dt: float, flags: Bools) -> None:  # pragma: no cover
    if flags[b, FLAG_AT_GOAL]:
        for i in range(out.shape[0]):
            out[i] += w * dt


#: Names of the registered terms, in order.
REWARD_TERMS: tuple[str, ...] = tuple(TERMS)
#: Default weights of the registered terms.
DEFAULT_WEIGHTS: dict[str, float] = {t.name: t.weight for t in TERMS.values()}


def reward_table() -> str:
    """The Markdown table of every registered term (the env's docstring holds it; a test compares)."""
    rows = ["| term | default weight | value |", "|---|---|---|"]
    rows += [f"| ``{t.name}`` | {t.weight:g} | {t.meaning} |" for t in TERMS.values()]
    return "\n".join(rows)
