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
from .obstacles import axis_param, toward_axis_at

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
    #: The agent kinds (``Engine.kind``) the term is defined for; None: every kind.
    kinds: tuple[str, ...] | None = None


#: Every registered term, by name.
TERMS: dict[str, RewardTerm] = {}


def reward_term(
    name: str, weight: float, meaning: str, kinds: tuple[str, ...] | None = None
) -> Callable[[Callable[..., None]], Any]:
    """Register the decorated row function as reward term ``name`` with default ``weight`` (defined for the agent
    ``kinds`` given, or every kind); the function becomes its compiled row."""

    def add(fn: Callable[..., None]) -> Any:
        if name in TERMS:
            raise ValueError(f"reward term {name!r} is registered already")
        row = jit(fn)
        TERMS[name] = RewardTerm(name, float(weight), row, meaning, kinds)
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


@jit
def time_to_rest(e: float, v: float, a: float) -> float:  # pragma: no cover
    """The least time (s) in which a double integrator x'' = u, |u| <= a (m/s^2), at position error e = goal - x
    (m) and velocity v (m/s, relative to the goal's) can stand on its goal: bang-bang with one switch. Above the
    switching curve x + v |v| / (2 a) = 0 (x = -e) it brakes first, T = (v + 2 sqrt(v^2 / 2 + a x)) / a; below
    it, T = (-v + 2 sqrt(v^2 / 2 - a x)) / a; on it, |v| / a."""
    x = -e
    s = x + v * abs(v) / (2.0 * a)
    if s > 0.0:
        return (v + 2.0 * math.sqrt(0.5 * v * v + a * x)) / a
    if s < 0.0:
        return (-v + 2.0 * math.sqrt(max(0.5 * v * v - a * x, 0.0))) / a
    return abs(v) / a


@jit
def _team_time(
    b: int, u_max: float, pos: Array, vel: Array, goal: Array, gvel: Array, route: Array
) -> float:  # pragma: no cover
    """The team's mean over agents of each agent's time to stand on its goal (s): the slowest axis's
    :func:`time_to_rest`, the position error being goal - pos scaled to the agent's route length."""
    n, d = pos.shape[1], pos.shape[2]
    acc = 0.0
    for i in range(n):
        straight = 0.0
        for k in range(d):
            straight += (goal[b, i, k] - pos[b, i, k]) ** 2
        straight = math.sqrt(straight)
        scale = route[b, i] / straight if straight > 1e-12 else 1.0
        worst = 0.0
        for k in range(d):
            e, v = scale * (goal[b, i, k] - pos[b, i, k]), vel[b, i, k] - gvel[b, i, k]
            worst = max(worst, time_to_rest(e, v, u_max))
        acc += worst
    return acc / n


@reward_term(
    "time_to_go",
    0.0,
    "mean over all agents of T_i(k) - T_i(k+1) (s), T_i the least time in which the agent, a double integrator "
    "with |u_j| <= u_max per axis, could stand on its goal (bang-bang, the slowest axis; the error to its goal "
    "scaled to its route's length, the goal's velocity as the one to match, the speed cap ignored); shared by "
    "the team: a potential that pays full speed towards the goal and braking at the last moment, where "
    "``approach`` pays speed as it pays distance",
    kinds=("double_integrator",),
)
def _time_to_go(  # pragma: no cover
    b: int,
    out: Array,
    w: float,
    u_max: float,
    pos0: Array,
    vel0: Array,
    goal0: Array,
    gvel0: Array,
    route0: Array,
    pos: Array,
    vel: Array,
    goal: Array,
    gvel: Array,
    route1: Array,
) -> None:
    gain = _team_time(b, u_max, pos0, vel0, goal0, gvel0, route0) - _team_time(b, u_max, pos, vel, goal, gvel, route1)
    for i in range(out.shape[0]):
        out[i] += w * gain


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


#: Scales of the ``closing`` term: the gap (m) that costs even at no closing speed, and the horizon (s) over which
#: a closing speed widens the costly gap.
CLOSING_MARGIN, CLOSING_HORIZON = 0.1, 0.5


@reward_term(
    "closing",
    0.0,
    "-T max over agents (followers too) of max(0, 1 - c_g / (0.1 m + 0.5 s * s_g)), c_g the gap between the "
    "agent's disc and the nearest obstacle surface, s_g >= 0 the speed at which they close (the agent's velocity "
    "toward that surface less the surface's own): a warning that scales with the approach speed, so a team "
    "sliding along a wall pays only within 0.1 m and one running at it pays from 0.5 s away; 1 per second at "
    "contact",
)
def _closing(  # pragma: no cover
    b: int, out: Array, w: float, dt: float, radius: float, pos: Array, vel: Array, cur_a: Array, cur_e: Array,
    cur_r: Array, old_a: Array, old_e: Array, old_r: Array,
) -> None:  # fmt: skip
    a, e, rad = cur_a[b], cur_e[b], cur_r[b]
    n, d = pos.shape[1], pos.shape[2]
    vec = np.empty(d)
    worst = 0.0
    for g in range(n):
        for j in range(rad.shape[0]):
            t = axis_param(pos[b, g], a, e, j)
            dist = toward_axis_at(pos[b, g], a, e, j, t, vec)
            gap = dist - rad[j] - radius
            # the velocity of the axis's nearest point (the capsule's motion over the last period) and the radius's
            # growth, both toward the agent, are taken off the agent's own
            speed = 0.0
            if dist > 0.0:
                for k in range(d):
                    surf_v = (a[j, k] + t * e[j, k] - old_a[b, j, k] - t * old_e[b, j, k]) / dt
                    speed += (vel[b, g, k] - surf_v) * vec[k] / dist
            speed += (rad[j] - old_r[b, j]) / dt
            reach = CLOSING_MARGIN + CLOSING_HORIZON * max(speed, 0.0)
            worst = max(worst, min(max(1.0 - gap / reach, 0.0), 1.0))
    for i in range(out.shape[0]):
        out[i] -= w * dt * worst


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
