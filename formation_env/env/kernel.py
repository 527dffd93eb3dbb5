"""The compiled step: one numba implementation of a step, composed per engine from its components.

A step runs environment by environment (row b) through its *parts* (:data:`PARTS`, in order): ``law`` (the
followers' law and the dynamics; ``network`` in its place in an engine with a communication network,
:mod:`~formation_env.env.network`), ``capsules`` (every obstacle at the step's time), ``contacts``, ``goal``,
``judge`` (goal distances, affine fit, success, the episode's end) and, when a component reads it, ``route``;
then the engine's reward terms fill the rewards and its observation blocks the observations. Each part declares
the arrays it writes; every array of the step is declared once, in :data:`ARRAYS` (name, shape, unit, the part
that writes it, what it means), with the engine's constants (:class:`Consts`) and the episodes' arrays
(:class:`Episode`). A component is a numba function of the row ``b`` and of the arrays it reads, each parameter
named after one of them (:func:`call`):

* an observation block ``row(b, out, lo, ...)`` writes every leader's entries into ``out[i, lo:lo + size]``;
* a reward term ``row(b, out, w, ...)`` adds w times every leader's value to ``out`` (n_l,);
* a scenario's ``route_row(pvec, radius, pos, goal, out)`` writes each agent's route length (m) to its goal
  (the ``approach`` potential) given the episode's parameters ``pvec`` (k,) and the agent radius (m), pos,
  goal (n, d) -> out (n,); its ``pose_row(goal_p, t, out)`` the pose of a moving goal; a moving obstacle
  type's ``row(p, t, bounds, a, e, rad)`` its capsules at time t.

:func:`compose` reads every component's parameters when the engine is built: it refuses a name that is no array
of the step (naming the component, the name and the arrays that exist), schedules the parts the components
read (the ``route`` when a term or block reads ``route0`` or ``route1``; in ``observe``, the reset's
observation without a step, the parts its blocks read, or it refuses a block that reads what ``observe`` cannot
have), checks that each array has one writer per composed function, and writes the source of the step, which it
compiles once per distinct composition (cached on disk). :func:`array_table` is the table of docs/architecture.md.
"""

from __future__ import annotations

import hashlib
import importlib.util
import inspect
import math
import os
import re
import sys
import tempfile
from collections import namedtuple
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from ._numba import jit, source_stamp
from .network import clip_actions, kinematics, network_row
from .obstacles import path_clearance, point_clearance

__all__ = [
    "ARRAYS",
    "PARTS",
    "ArraySpec",
    "Consts",
    "Episode",
    "NetConsts",
    "Outputs",
    "Part",
    "array_table",
    "call",
    "compose",
    "fit_rows",
    "jit",
    "straight_route",
    "team_half_height",
]

Array = NDArray[np.float64]
Ints = NDArray[np.int64]
Bools = NDArray[np.bool_]


class Consts(NamedTuple):
    """An engine's constants (their shapes, units and meanings: :data:`ARRAYS`, written by ``engine``)."""

    leaders: Ints
    others: Ints
    pair_i: Ints
    pair_j: Ints
    r: Array
    pinv: Array
    law: Array
    c_t: Array
    ca_t: Array
    bounds: Array
    ray_dirs: Array
    obs_low: Array
    obs_high: Array
    noise_mask: Array
    weights: Array
    dt: float
    u_max: float
    radius: float
    fast: float
    goal_tol: float
    formation_tol: float
    v_bound: float
    obstacle_range: float
    sense_radius: float
    max_cycles: int
    hold_steps: int
    n_nearest: int
    k_nearest: int
    end_on_success: bool


class NetConsts(NamedTuple):
    """The network's constants (:data:`ARRAYS`, written by ``engine``), an argument of a networked step only."""

    followers: Ints
    net_recv: Ints
    net_send: Ints
    net_w: Array
    net_row: Ints
    net_gain: Array
    zoh_a: Array
    zoh_b: Array
    dyn_a: Array
    dyn_b: Array
    zoh_kind: int
    loss: float
    hold: bool
    quant: int
    quant_step: float
    jitter: Array


class Episode(NamedTuple):
    """The episodes' arrays from the reset (:data:`ARRAYS`, written by ``reset``); ``mov_p`` holds one array per
    moving obstacle type of the scenario, in its ``obstacle_types`` order."""

    pvec: Array
    cap_a: Array
    cap_e: Array
    cap_r: Array
    mov_p: tuple[Array, ...]
    goal_p: Array


FLAG_COLLISION, FLAG_OOB, FLAG_AT_GOAL, FLAG_SUCCESS, FLAG_TERMINATED, FLAG_TRUNCATED = range(6)
#: The columns of ``flags``, by name (a part's write ``flags:name``).
FLAG_NAMES = ("collision", "oob", "at_goal", "success", "terminated", "truncated")


# ---------------------------------------------------------------------------- the declaration
class ArraySpec(NamedTuple):
    """One array of the step.

    Attributes:
        name: the name a component's parameter gives to read it.
        shape: its shape, in the symbols of the step (B, n, n_l, n_f, d, q, p, m, M_j, ...).
        unit: its unit ("1": none).
        writer: the part that writes it (:data:`PARTS`), or ``state`` (the state before the step), ``engine``
            (a constant, :class:`Consts`), ``reset`` (an episode's, :class:`Episode`).
        meaning: one line.
        alloc: how the step allocates it (a numpy expression in the shape symbols), for the parts' arrays.
        observe: what ``observe`` (an observation without a step) gives: ``state`` (the state's own array),
            ``part`` (its part runs when a block reads it), ``zeros``, or ``""`` (nothing: a block that reads it
            is refused).
        out: the step returns it (:class:`Outputs`).
        state: for a ``state`` array, the ``EngineState`` field it comes from.
    """

    name: str
    shape: str
    unit: str
    writer: str
    meaning: str
    alloc: str = ""
    observe: str = "part"
    out: bool = False
    state: str = ""


# fmt: off
_E = "np.empty"
_LAW = "law, network"
#: Every array of the step, in the order of the step's arguments (the ``state`` ones) and outputs (``out``).
ARRAYS: tuple[ArraySpec, ...] = (
    # the state before the step (the step's inputs; in observe, the state itself)
    ArraySpec("x0", "(B, n, q)", "state", "state", "agent states x", observe="state", state="x"),
    ArraySpec("mem0", "(B, n_f, p)", "input", "state", "follower-law memory (previous inputs; (B, 0, 0): none)",
              observe="state", state="memory"),
    ArraySpec("pos0", "(B, n, d)", "m", "state", "positions C x", observe="state", state="pos"),
    ArraySpec("vel0", "(B, n, d)", "m/s", "state", "velocities", observe="state", state="vel"),
    ArraySpec("goal0", "(B, n, d)", "m", "state", "goal positions", observe="state", state="goal"),
    ArraySpec("gvel0", "(B, n, d)", "m/s", "state", "goal velocities", observe="state", state="goal_vel"),
    ArraySpec("k0", "(B,)", "samples", "state", "samples taken", observe="state", state="k"),
    ArraySpec("gdist0", "(B, n_l)", "m", "state", "each leader's distance to its goal", observe="state",
              state="goal_dist"),
    ArraySpec("streak0", "(B,)", "samples", "state", "consecutive samples at the goal", observe="state",
              state="streak"),
    ArraySpec("sent0", "(B, d_n, n, q)", "state", "state", "network: what every agent sent at k - 1, ..., k - d "
              "(neighbours delay; else (0, 0, 0, 0))", observe="state", state="net_sent"),
    ArraySpec("corr0", "(B, d_i, n_f, q)", "state", "state", "network: the corrections c(k - 1), ..., c(k - d) "
              "(input delay; else (0, 0, 0, 0))", observe="state", state="net_corr"),
    ArraySpec("held0", "(B, m_h, q)", "state", "state", "network: the value each link j -> i holds (hold model; "
              "else (0, 0, 0))", observe="state", state="net_held"),
    ArraySpec("rng0", "(B, 4)", "1", "state", "network: each copy's PCG64 generator state (uint64 words; else "
              "(0, 4))", observe="state", state="net_rng"),
    ArraySpec("lost0", "(B,)", "samples", "state", "network: link samples lost since the reset (else (0,))",
              observe="state", state="net_lost"),
    ArraySpec("time0", "(B,)", "s", "state", "network with jitter: the env time, the sum of the drawn periods (else "
              "(0,): t = k T)", observe="state", state="net_time"),
    # law and dynamics
    ArraySpec("act", "(B, n_l, p)", "1", _LAW, "the leaders' actions, clipped to [-1, 1]", observe="zeros"),
    ArraySpec("effort", "(B, n_l)", "input^2", _LAW, "u_i . u_i, the squared input of each leader (u = u_max a)",
              "np.zeros((B, n_l))", observe="", out=True),
    ArraySpec("x", "(B, n, q)", "state", _LAW, "agent states after the step",
              "x_in if x_in.size else np.empty(x0.shape)", observe="state", out=True),
    ArraySpec("mem", "(B, n_f, p)", "input", _LAW, "follower-law memory after the step",
              "mem_in if x_in.size else np.empty(mem0.shape)", observe="state", out=True),
    ArraySpec("pos", "(B, n, d)", "m", _LAW, "positions after the step", f"{_E}(pos0.shape)", "state", True),
    ArraySpec("vel", "(B, n, d)", "m/s", _LAW, "velocities (C A x, or the change of position over the period)",
              f"{_E}(pos0.shape)", "state", True),
    ArraySpec("k", "(B,)", "samples", _LAW, "samples taken after the step", f"{_E}(B, np.int64)", "state", True),
    # obstacles
    ArraySpec("now", "(B,)", "s", "capsules", "the env time t of the sample: k T, or under jitter the sum of the drawn "
              "periods", "np.empty(B)"),
    ArraySpec("cur_a", "(B, m, d)", "m", "capsules", "every capsule's axis start at t = k T (static, then each "
              "moving type's)", f"{_E}((B, m, d))"),
    ArraySpec("cur_e", "(B, m, d)", "m", "capsules", "every capsule's axis (start to end) at t", f"{_E}((B, m, d))"),
    ArraySpec("cur_r", "(B, m)", "m", "capsules", "every capsule's radius at t", f"{_E}((B, m))"),
    ArraySpec("old_a", "(B, m, d)", "m", "capsules", "axis starts a sample before, t - T (observe: at t)",
              f"{_E}((B, m, d))"),
    ArraySpec("old_e", "(B, m, d)", "m", "capsules", "axes at t - T (observe: at t)", f"{_E}((B, m, d))"),
    ArraySpec("old_r", "(B, m)", "m", "capsules", "radii at t - T (observe: at t)", f"{_E}((B, m))"),
    # contacts (and the judgement's columns of flags)
    ArraySpec("clear", "(B,)", "m", "contacts", "smallest gap between surfaces (agents, capsules; along the "
              "step when something moved fast; observe: at the sample)", "np.full(B, np.inf)", out=True),
    ArraySpec("flags", "(B, 6)", "bool", "contacts, judge", "collision, oob (contacts); at_goal, success, "
              "terminated, truncated (judge): the FLAG_* columns", "np.zeros((B, 6), np.bool_)", out=True),
    # goal
    ArraySpec("goal", "(B, n, d)", "m", "goal", "goal positions at t (the scenario's pose_row, if it moves)",
              f"{_E}(pos0.shape)", "state", True),
    ArraySpec("gvel", "(B, n, d)", "m/s", "goal", "goal velocities (x*(t + T) - x*(t)) / T",
              f"{_E}(pos0.shape)", "state", True),
    # judgement
    ArraySpec("gdist", "(B, n_l)", "m", "judge", "each leader's distance to its goal", f"{_E}(gdist0.shape)",
              "state", True),
    ArraySpec("streak", "(B,)", "samples", "judge", "consecutive samples at the goal", f"{_E}(B, np.int64)",
              "state", True),
    ArraySpec("err", "(B,)", "m", "judge, fit", "formation error: RMS residual of the affine fit", f"{_E}(B)",
              out=True),
    ArraySpec("gmax", "(B,)", "m", "judge", "largest goal distance of any agent", f"{_E}(B)", out=True),
    ArraySpec("theta", "(B, d, d)", "1", "judge, fit", "Theta of the affine fit of all agents",
              f"{_E}((B, d, d))", out=True),
    ArraySpec("bfit", "(B, d)", "m", "judge, fit", "b of the affine fit", f"{_E}((B, d))"),
    # route (when a component reads it)
    ArraySpec("route0", "(B, n)", "m", "route", "each agent's route length to its goal before the step (the "
              "scenario's route_row)", f"{_E}((B, n))"),
    ArraySpec("route1", "(B, n)", "m", "route", "route lengths after the step", f"{_E}((B, n))"),
    # the network (instead of the law's map, when the engine has one)
    ArraySpec("sent", "(B, d_n, n, q)", "state", "network", "what was sent at k, ..., k - d + 1",
              f"{_E}(sent0.shape)", observe="", out=True),
    ArraySpec("corr", "(B, d_i, n_f, q)", "state", "network", "the corrections c(k), ..., c(k - d + 1)",
              f"{_E}(corr0.shape)", observe="", out=True),
    ArraySpec("held", "(B, m_h, q)", "state", "network", "the value each link holds after the step",
              f"{_E}(held0.shape)", observe="", out=True),
    ArraySpec("rng", "(B, 4)", "1", "network", "each copy's generator state after the step's draws",
              f"{_E}(rng0.shape, np.uint64)", observe="", out=True),
    ArraySpec("lost", "(B,)", "samples", "network", "link samples lost since the reset, after the step",
              f"{_E}(lost0.shape, np.int64)", observe="", out=True),
    ArraySpec("period", "(B,)", "s", "network", "the sample's period T_k (drawn under jitter, else T)",
              f"{_E}(lost0.shape[0])", observe="", out=True),
    ArraySpec("time", "(B,)", "s", "network", "under jitter, the env time after the step (else (0,))",
              f"{_E}(time0.shape)", observe="", out=True),
    # the engine's constants
    ArraySpec("leaders", "(n_l,)", "index", "engine", "the leaders' agent indices"),
    ArraySpec("others", "(n_l, n_l - 1)", "index", "engine", "the other leaders of each (leader indices)"),
    ArraySpec("pair_i", "(P,)", "index", "engine", "first agents of the pairs checked for contact"),
    ArraySpec("pair_j", "(P,)", "index", "engine", "second agents of the pairs"),
    ArraySpec("r", "(n, d)", "m", "engine", "nominal configuration"),
    ArraySpec("pinv", "(d + 1, n)", "1/m, 1", "engine", "pseudo-inverse of [r, 1] (the affine fit)"),
    ArraySpec("law", "(nq + n_l p + n_f p, nq + n_f p)", "1", "engine", "the law's one-step map M ([x', mem'] = "
              "[x, u_l, mem] M; (0, 0): the engine stepped the law, a sparse stress)"),
    ArraySpec("c_t", "(q, d)", "1", "engine", "C^T (positions C x)"),
    ArraySpec("ca_t", "(q, d) or (0, d)", "1/s", "engine", "(C A)^T (velocities C A x), or none"),
    ArraySpec("bounds", "(2, d)", "m", "engine", "world box (low, high)"),
    ArraySpec("ray_dirs", "(R, 2)", "1", "engine", "unit directions of the range-sensor rays"),
    ArraySpec("obs_low", "(D,)", "entry's", "engine", "observation bounds, low"),
    ArraySpec("obs_high", "(D,)", "entry's", "engine", "observation bounds, high"),
    ArraySpec("noise_mask", "(D,)", "1", "engine", "1 where observation noise applies"),
    ArraySpec("weights", "(T,)", "1", "engine", "weights of the composed reward terms"),
    ArraySpec("dt", "scalar", "s", "engine", "sampling period T"),
    ArraySpec("u_max", "scalar", "input", "engine", "input of action 1"),
    ArraySpec("radius", "scalar", "m", "engine", "agent radius"),
    ArraySpec("fast", "scalar", "m", "engine", "a move beyond it sweeps contacts: 2 radius / sqrt(d)"),
    ArraySpec("goal_tol", "scalar", "m", "engine", "every agent within it of its goal: at the goal"),
    ArraySpec("formation_tol", "scalar", "m", "engine", "formation error below it: at the goal"),
    ArraySpec("v_bound", "scalar", "m/s", "engine", "velocity bound of observations"),
    ArraySpec("obstacle_range", "scalar", "m", "engine", "obstacle sensing range"),
    ArraySpec("sense_radius", "scalar", "m", "engine", "how far a leader sees other agents"),
    ArraySpec("max_cycles", "scalar", "samples", "engine", "samples before truncation"),
    ArraySpec("hold_steps", "scalar", "samples", "engine", "samples at the goal that make a success"),
    ArraySpec("n_nearest", "scalar", "1", "engine", "nearest obstacles sensed in 3D"),
    ArraySpec("k_nearest", "scalar", "1", "engine", "agents in the nearest_agents block"),
    ArraySpec("end_on_success", "scalar", "bool", "engine", "success ends the episode"),
    ArraySpec("followers", "(n_f,)", "index", "engine", "network: the followers' agent indices (else (0,))"),
    ArraySpec("net_recv", "(m_l,)", "index", "engine", "network: each directed link j -> i's receiver i "
              "(core.network.network_links order)"),
    ArraySpec("net_send", "(m_l,)", "index", "engine", "network: each link's sender j (leaders send too)"),
    ArraySpec("net_w", "(m_l,)", "1/m^2", "engine", "network: each link's weight Omega_ij"),
    ArraySpec("net_row", "(m_l,)", "index", "engine", "network: each link's receiver's row in followers"),
    ArraySpec("net_gain", "(p, q)", "1", "engine", "network: the law's gain G (u_i = G c_i): eps K"),
    ArraySpec("zoh_a", "(q, q)", "1", "engine", "network: A_d at the nominal T"),
    ArraySpec("zoh_b", "(q, p)", "1", "engine", "network: B_d at the nominal T"),
    ArraySpec("dyn_a", "(q, q)", "1/s", "engine", "network: the continuous A (the ZOH at a drawn period)"),
    ArraySpec("dyn_b", "(q, p)", "1", "engine", "network: the continuous B"),
    ArraySpec("zoh_kind", "scalar", "1", "engine", "network: the ZOH at the period: 0 nominal, 1 (I, T B), 2 expm"),
    ArraySpec("loss", "scalar", "1", "engine", "network: probability p that a link loses a sample"),
    ArraySpec("hold", "scalar", "bool", "engine", "network: a lost sample keeps the last value received"),
    ArraySpec("quant", "scalar", "1", "engine", "network: quantiser of what is sent: 0 none, 1 uniform, 2 log"),
    ArraySpec("quant_step", "scalar", "state", "engine", "network: the uniform step delta, or the log density rho"),
    ArraySpec("jitter", "(2,) or (0,)", "s", "engine", "network: (T_min, T_max) of the drawn periods, or none"),
    # the episodes' arrays
    ArraySpec("pvec", "(B, k)", "scenario's", "reset", "the scenario's episode parameters (its param_vector)"),
    ArraySpec("cap_a", "(B, m_s, d)", "m", "reset", "static capsules' axis starts (made at the reset)"),
    ArraySpec("cap_e", "(B, m_s, d)", "m", "reset", "static capsules' axes"),
    ArraySpec("cap_r", "(B, m_s)", "m", "reset", "static capsules' radii"),
    ArraySpec("mov_p", "tuple of (B, M_j, w_j)", "type's", "reset", "each moving type's parameters (its row's p)"),
    ArraySpec("goal_p", "(B, w)", "scenario's", "reset", "what the scenario's pose_row reads of a moving goal"),
    ArraySpec("mov_p0", "(B, M_0, w_0)", "type's", "reset", "the first moving type's parameters, mov_p[0], for a "
              "component that forecasts it ((B, 0, 0) in a scenario with none)"),
)
# fmt: on
SPECS: dict[str, ArraySpec] = {a.name: a for a in ARRAYS}
if set(Consts._fields) | set(NetConsts._fields) != {a.name for a in ARRAYS if a.writer == "engine"} or set(
    Episode._fields
) | {"mov_p0"} != {
    a.name for a in ARRAYS if a.writer == "reset"
}:  # pragma: no cover  (a declaration out of step with the records)
    raise RuntimeError("kernel.ARRAYS must declare every field of Consts (engine) and Episode (reset)")

#: What the step returns of its arrays, in :data:`ARRAYS` order (the compiled step returns a plain tuple, since
#: numba boxes a named one much more slowly).
Outputs = namedtuple("Outputs", [a.name for a in ARRAYS if a.out])  # type: ignore[misc]
#: The state arrays, the step's inputs after ``c`` and ``ep``.
STATE_INPUTS: tuple[ArraySpec, ...] = tuple(a for a in ARRAYS if a.writer == "state")
#: The arrays only a networked step has (its state inputs and outputs): a step without a network neither takes
#: nor returns them, nor ``NetConsts``, so it costs what it cost before networks existed.
NETWORK_ONLY: frozenset[str] = frozenset(
    a.name for a in ARRAYS if a.writer == "network" or (a.writer == "state" and a.state.startswith("net_"))
)
#: The outputs of a step without a network (the first fields of ``Outputs``; the network's follow).
_OUTPUT_NAMES: tuple[str, ...] = tuple(Outputs._fields)
NOMINAL_OUTPUTS: tuple[str, ...] = tuple(name for name in _OUTPUT_NAMES if name not in NETWORK_ONLY)
if Outputs._fields[: len(NOMINAL_OUTPUTS)] != NOMINAL_OUTPUTS:  # pragma: no cover
    raise RuntimeError("kernel.ARRAYS must declare the network's outputs after every other output")


def step_inputs(network: bool) -> tuple[ArraySpec, ...]:
    """The state arrays a composed step takes (the network's only when it has one), in argument order."""
    return tuple(a for a in STATE_INPUTS if network or a.name not in NETWORK_ONLY)


# ---------------------------------------------------------------------------- the parts of a row
@jit
def static_capsules(  # pragma: no cover
    b: int, cap_a: Array, cap_e: Array, cap_r: Array, cur_a: Array, cur_e: Array, cur_r: Array, old_a: Array,
    old_e: Array, old_r: Array
) -> None:  # fmt: skip
    """The static capsules of env b into ``cur_*`` and ``old_*`` (the moving ones follow, from their types'
    rows)."""
    for j in range(cap_r.shape[1]):
        for c in range(cap_a.shape[2]):
            cur_a[b, j, c] = old_a[b, j, c] = cap_a[b, j, c]
            cur_e[b, j, c] = old_e[b, j, c] = cap_e[b, j, c]
        cur_r[b, j] = old_r[b, j] = cap_r[b, j]


@jit
def affine_fit(r: Array, pinv: Array, pos: Array, theta: Array, b: Array) -> float:  # pragma: no cover
    """Least-squares affine fit pos_i ~ Theta r_i + b of positions (n, d): Theta into theta (d, d), b into
    b (d,); returns the RMS residual (m), the formation error."""
    n, d = r.shape
    for c in range(d):
        for j in range(d + 1):
            acc = 0.0
            for i in range(n):
                acc += pinv[j, i] * pos[i, c]
            if j < d:
                theta[c, j] = acc
            else:
                b[c] = acc
    sq = 0.0
    for i in range(n):
        for c in range(d):
            w = pos[i, c] - b[c]
            for j in range(d):
                w -= theta[c, j] * r[i, j]
            sq += w * w
    return math.sqrt(sq / n)


@jit
def fit_rows(r: Array, pinv: Array, pos: Array) -> tuple[Array, Array, Array]:  # pragma: no cover
    """:func:`affine_fit` of every environment, pos (B, n, d) -> Theta (B, d, d), b (B, d), error (B,)."""
    B, _, d = pos.shape
    theta, b, err = np.empty((B, d, d)), np.empty((B, d)), np.empty(B)
    for k in range(B):
        err[k] = affine_fit(r, pinv, pos[k], theta[k], b[k])
    return theta, b, err


@jit
def fit_row(  # pragma: no cover
    b: int, r: Array, pinv: Array, pos: Array, theta: Array, bfit: Array, err: Array
) -> None:
    """The affine fit of env b's positions: ``theta``, ``bfit`` and ``err``."""
    err[b] = affine_fit(r, pinv, pos[b], theta[b], bfit[b])


@jit
def move_row(  # pragma: no cover
    b: int, act: Array, effort: Array, u_max: float, law: Array, x0: Array, mem0: Array, x: Array, mem: Array,
    c_t: Array, ca_t: Array, pos0: Array, pos: Array, vel: Array, dt: float, k0: Ints, k: Ints
) -> None:  # fmt: skip
    """The law and the dynamics of env b: clipped actions, [x', mem'] = [x, u_max a, mem] M, positions C x',
    velocities (C A x' or the change of position over T), the sample count."""
    clip_actions(b, act, effort, u_max)
    if law.shape[0]:
        z = np.concatenate((x0[b].ravel(), u_max * act[b].ravel(), mem0[b].ravel()))
        out = np.zeros(law.shape[1])
        for i in range(z.size):  # row-major over M: z M
            zi = z[i]
            for o in range(out.size):
                out[o] += zi * law[i, o]
        nx = x0.shape[1] * x0.shape[2]
        x[b] = out[:nx].reshape(x.shape[1:])
        mem[b] = out[nx:].reshape(mem.shape[1:])
    kinematics(b, x, c_t, ca_t, pos0, pos, vel, dt, k0, k)


@jit
def contacts_row(  # pragma: no cover
    b: int, pos0: Array, pos: Array, pair_i: Ints, pair_j: Ints, radius: float, cur_a: Array, cur_e: Array,
    cur_r: Array, old_a: Array, old_e: Array, old_r: Array, fast: float, bounds: Array, clear: Array, flags: Bools
) -> None:  # fmt: skip
    """Env b's clearance (agent pairs; capsules at the sample, and along the step when something moved fast),
    collision and out-of-bounds flags.

    Along the step, each agent's straight motion is measured against each capsule in the capsule's frame, which
    translates from its start a sample before to its start now, with its axis now; for capsules whose axis or
    radius changed (a turning bar), also with the axis and radius of a sample before, and the smaller gap counts.
    """
    n, d = pos.shape[1], pos.shape[2]
    best = np.inf
    for q in range(pair_i.shape[0]):
        dd = 0.0
        for c in range(d):
            w = pos[b, pair_i[q], c] - pos[b, pair_j[q], c]
            dd += w * w
        best = min(best, dd)
    gap = math.sqrt(best) - 2.0 * radius
    if cur_r.shape[1]:
        gap = min(gap, point_clearance(pos[b], cur_a[b], cur_e[b], cur_r[b]) - radius)
        moved = 0.0
        for i in range(n):
            for c in range(d):
                moved = max(moved, abs(pos[b, i, c] - pos0[b, i, c]))
        shift = 0.0  # the obstacles' own motion: the relative one is at most the sum
        turned = False
        for j in range(cur_r.shape[1]):
            turned = turned or cur_r[b, j] != old_r[b, j]
            for c in range(d):
                shift = max(shift, abs(cur_a[b, j, c] - old_a[b, j, c]))
                turned = turned or cur_e[b, j, c] != old_e[b, j, c]
        if turned:  # the far ends move too
            for j in range(cur_r.shape[1]):
                for c in range(d):
                    shift = max(shift, abs(cur_a[b, j, c] + cur_e[b, j, c] - old_a[b, j, c] - old_e[b, j, c]))
        if moved + shift > fast:
            gap = min(gap, path_clearance(pos0[b], pos[b], old_a[b], cur_a[b], cur_e[b], cur_r[b]) - radius)
            if turned:
                gap = min(gap, path_clearance(pos0[b], pos[b], old_a[b], cur_a[b], old_e[b], old_r[b]) - radius)
    oob = False
    for i in range(n):
        for c in range(d):
            oob = oob or pos[b, i, c] < bounds[0, c] or pos[b, i, c] > bounds[1, c]
    clear[b] = gap
    flags[b, FLAG_OOB] = oob
    flags[b, FLAG_COLLISION] = gap < 0.0 or oob


@jit
def static_goal(b: int, goal0: Array, gvel0: Array, goal: Array, gvel: Array) -> None:  # pragma: no cover
    """A goal that does not move: the goal positions and their (zero) velocity stay."""
    goal[b] = goal0[b]
    gvel[b] = gvel0[b]


@jit
def affine_into(r: Array, pose: Array, out: Array) -> None:  # pragma: no cover
    """out_i = Theta r_i + b for pose = [Theta, b] (d, d + 1), r (n, d) -> out (n, d)."""
    n, d = r.shape
    for i in range(n):
        for c in range(d):
            acc = pose[c, d]
            for j in range(d):
                acc += pose[c, j] * r[i, j]
            out[i, c] = acc


@jit
def goal_max(b: int, pos: Array, goal: Array) -> float:  # pragma: no cover
    """Env b's largest distance (m) of an agent to its goal position: pos, goal (B, n, d)."""
    far = 0.0
    for i in range(pos.shape[1]):
        dd = 0.0
        for c in range(pos.shape[2]):
            dd += (goal[b, i, c] - pos[b, i, c]) ** 2
        far = max(far, math.sqrt(dd))
    return far


@jit
def judge_row(  # pragma: no cover
    b: int, pos: Array, goal: Array, leaders: Ints, gdist: Array, gmax: Array, r: Array, pinv: Array, theta: Array,
    bfit: Array, err: Array, flags: Bools, goal_tol: float, formation_tol: float, streak0: Ints, streak: Ints,
    hold_steps: int, end_on_success: bool, k: Ints, max_cycles: int
) -> None:  # fmt: skip
    """Env b's goal distances, affine fit, success streak and the episode's end."""
    far = gmax[b] = goal_max(b, pos, goal)
    d = pos.shape[2]
    for i in range(leaders.shape[0]):
        dd = 0.0
        for c in range(d):
            dd += (goal[b, leaders[i], c] - pos[b, leaders[i], c]) ** 2
        gdist[b, i] = math.sqrt(dd)
    err[b] = affine_fit(r, pinv, pos[b], theta[b], bfit[b])
    f = flags[b]
    ok = far < goal_tol and err[b] < formation_tol and not f[FLAG_COLLISION]
    f[FLAG_AT_GOAL] = ok
    streak[b] = streak0[b] + 1 if ok else 0
    f[FLAG_SUCCESS] = streak[b] >= hold_steps
    f[FLAG_TERMINATED] = f[FLAG_COLLISION] or (end_on_success and f[FLAG_SUCCESS])
    f[FLAG_TRUNCATED] = k[b] >= max_cycles and not f[FLAG_TERMINATED]


@jit
def verdict_row(  # pragma: no cover
    b: int, pos: Array, goal: Array, gmax: Array, err: Array, flags: Bools, goal_tol: float, formation_tol: float,
    streak: Ints, hold_steps: int, end_on_success: bool, k: Ints, max_cycles: int
) -> None:  # fmt: skip
    """The judgement of a state without a step (``observe``): the largest goal distance and the flags the step
    that made the state set, from its own streak (which it does not advance)."""
    far = gmax[b] = goal_max(b, pos, goal)
    f = flags[b]
    f[FLAG_AT_GOAL] = far < goal_tol and err[b] < formation_tol and not f[FLAG_COLLISION]
    f[FLAG_SUCCESS] = streak[b] >= hold_steps
    f[FLAG_TERMINATED] = f[FLAG_COLLISION] or (end_on_success and f[FLAG_SUCCESS])
    f[FLAG_TRUNCATED] = k[b] >= max_cycles and not f[FLAG_TERMINATED]


@jit
def straight_route(pvec: Array, radius: float, pos: Array, goal: Array, out: Array) -> None:  # pragma: no cover
    """Straight lines: out[i] = |goal_i - pos_i| (m), the default route of the ``approach`` potential."""
    for i in range(pos.shape[0]):
        dd = 0.0
        for k in range(pos.shape[1]):
            dd += (goal[i, k] - pos[i, k]) ** 2
        out[i] = math.sqrt(dd)


@jit
def team_half_height(pos: Array, radius: float) -> float:  # pragma: no cover
    """Half the team's height with the agents' discs, (max y - min y) / 2 + radius (m), of positions pos (n, d):
    the half-width of the band along y the team sweeps when it moves along x (the ``task`` blocks' room)."""
    lo_y, hi_y = np.inf, -np.inf
    for j in range(pos.shape[0]):
        lo_y, hi_y = min(lo_y, pos[j, 1]), max(hi_y, pos[j, 1])
    return 0.5 * (hi_y - lo_y) + radius


@jit
def finish_obs(  # pragma: no cover
    b: int, buf: Array, noise: Array, noise_mask: Array, obs_low: Array, obs_high: Array, obs: NDArray[np.float32]
) -> None:
    """Env b's observations from ``buf`` (B, n_l, D): noise on the measurements, clipped to the blocks'
    bounds, as float32 into ``obs``."""
    for i in range(buf.shape[1]):
        for j in range(buf.shape[2]):
            v = buf[b, i, j]
            if noise.shape[0]:
                v += noise[b, i, j] * noise_mask[j]
            obs[b, i, j] = min(max(v, obs_low[j]), obs_high[j])


# ---------------------------------------------------------------------------- the parts
class Part(NamedTuple):
    """One part of a row of the step.

    Attributes:
        name: its name.
        writes: the arrays it writes in the step (``flags:column`` for one column of ``flags``).
        observe: what it writes in ``observe`` (None: it does not run there).
        meaning: what it does.
        rows: the compiled functions it calls in the step, each with the arrays its parameters name
            (:func:`call`); empty for the parts whose calls depend on the scenario (capsules, goal, route).
        observe_rows: those it calls in ``observe`` (default: ``rows``).
    """

    name: str
    writes: tuple[str, ...]
    observe: tuple[str, ...] | None
    meaning: str
    rows: tuple[Any, ...] = ()
    observe_rows: tuple[Any, ...] | None = None


_JUDGED = ("flags:at_goal", "flags:success", "flags:terminated", "flags:truncated")
#: The parts of a row, in the step's order (``fit`` runs in ``observe`` only, where no step ran).
PARTS: tuple[Part, ...] = (
    Part("law", ("act", "effort", "x", "mem", "pos", "vel", "k"), None,
         "clipped actions, [x', mem'] = [x, u_max a, mem] M, positions, velocities, the sample count", (move_row,)),
    Part("network", ("act", "effort", "x", "mem", "pos", "vel", "k", "sent", "corr", "held", "rng", "lost", "period",
                     "time"), None,
         "instead of law, with a network: draws, what is sent and received, u_f = G c, every agent's ZOH over the "
         "period (env.network)", (network_row,)),
    Part("capsules", ("now", "cur_a", "cur_e", "cur_r", "old_a", "old_e", "old_r"),
         ("now", "cur_a", "cur_e", "cur_r", "old_a", "old_e", "old_r"),
         "the sample's time t, the static capsules, then each moving type's row at t and at t - T"),
    Part("contacts", ("clear", "flags:collision", "flags:oob"), ("clear", "flags:collision", "flags:oob"),
         "clearance of agent pairs and capsules (swept along the step when something moved fast), the box",
         (contacts_row,)),
    Part("goal", ("goal", "gvel"), None, "the goal at t (the scenario's pose_row when it moves)"),
    Part("judge", ("gdist", "gmax", "theta", "bfit", "err", "streak", *_JUDGED), ("gmax", *_JUDGED),
         "goal distances, the affine fit, the success streak, termination and truncation", (judge_row,),
         (verdict_row,)),
    Part("fit", (), ("theta", "bfit", "err"), "the affine fit of the state (observe)", (), (fit_row,)),
    Part("route", ("route0", "route1"), ("route0", "route1"), "route lengths before and after (scenario's route_row)"),
)  # fmt: skip
PART_NAMES = tuple(p.name for p in PARTS)
_OPTIONAL = ("route",)  # parts that run only when a component reads what they write
#: The part that takes the place of another in an engine with a network (and is left out without one).
_INSTEAD = {"network": "law"}


def _left_out(network: bool) -> frozenset[str]:
    """The parts an engine does not compose: ``network`` without a network, else ``law``."""
    return frozenset(_INSTEAD.values()) if network else frozenset(_INSTEAD)


def _target_array(target: str) -> str:
    return target.split(":")[0]


def _check_declaration() -> None:
    """The declaration is consistent: each written array is declared with its writer, flags' columns exist."""
    for part in PARTS:
        for target in (*part.writes, *(part.observe or ())):
            name, _, col = target.partition(":")
            if name not in SPECS or part.name not in SPECS[name].writer.split(", "):
                raise RuntimeError(f"kernel.PARTS: part {part.name!r} writes {name!r}, not declared so in ARRAYS")
            if col and col not in FLAG_NAMES:
                raise RuntimeError(f"kernel.PARTS: part {part.name!r} writes unknown flags column {col!r}")
        for rows, targets in ((part.rows, part.writes), (part.observe_rows, part.observe)):
            params = {nm for fn in rows or () for nm in _params(fn)}
            if rows and not {_target_array(t) for t in targets or ()} <= params:
                raise RuntimeError(f"kernel.PARTS: part {part.name!r} declares writes its rows do not take")


# ---------------------------------------------------------------------------- the table
def _valid(spec: ArraySpec) -> str:
    """When an array holds its value, in the step and in ``observe``."""
    if spec.writer in ("engine", "reset"):
        return "always"
    if spec.writer == "state":
        return "whole step; observe: the state"
    after = " / ".join(w for w in spec.writer.split(", ") if w != "fit")
    also = {"state": "the state's", "part": "computed at the state", "zeros": "zeros", "": "no (refused)"}
    return f"after {after}; observe: {also[spec.observe]}"


def array_table() -> str:
    """The Markdown table of every array a component can read (docs/architecture.md holds it; a test compares)."""
    rows = ["| name | shape | unit | written by | valid | meaning |", "|---|---|---|---|---|---|"]
    rows += [f"| `{a.name}` | {a.shape} | {a.unit} | {a.writer} | {_valid(a)} | {a.meaning} |" for a in ARRAYS]
    return "\n".join(rows)


# ---------------------------------------------------------------------------- composition
_COMPOSED: dict[str, Any] = {}
#: Names a part's line may use beside the arrays: the row, the observation buffers, the rewards, a pose.
_LOCALS = ("b", "buf", "obs", "noise", "rew", "pose")


def _inputs(network: bool) -> tuple[str, ...]:
    """The composed step's parameters: constants (and the network's), episode, state, actions, law, noise."""
    return ("c", *(("nc",) if network else ()), "ep", *(a.name for a in step_inputs(network)), "act", "x_in",
            "mem_in", "noise")  # fmt: skip


def _name(fn: Any) -> tuple[str, str]:
    py = getattr(fn, "py_func", fn)
    return py.__module__, py.__qualname__


def _params(fn: Any) -> list[str]:
    return list(inspect.signature(getattr(fn, "py_func", fn)).parameters)


def call(fn: Any, alias: str = "", **given: str) -> str:
    """The generated call of a component: each parameter named after an array of the step (:data:`ARRAYS`) gets
    that array, ``b`` the row, the others what ``given`` says (e.g. a block's ``out`` and ``lo``); ``alias``: the
    name the step knows it by. An unknown name raises TypeError naming the function, the name and the arrays."""
    names = _params(fn)
    unknown = [nm for nm in names if nm not in given and nm not in SPECS and nm not in _LOCALS]
    if unknown:
        mod, qual = _name(fn)
        raise TypeError(
            f"{mod}.{qual}: parameter {unknown[0]!r} is not an array of the step nor one of {sorted(given)}; "
            f"the arrays are {', '.join(a.name for a in ARRAYS)} (docs/architecture.md, kernel.ARRAYS)"
        )
    return f"{alias or getattr(fn, '__name__', _name(fn)[1])}({', '.join(given.get(nm, nm) for nm in names)})"


def cache_folder() -> str:
    """Where the composed steps are written: ``$FORMATION_ENV_CACHE``, else ``$XDG_CACHE_HOME/formation_env`` (by
    default ``~/.cache/formation_env``), else, when that cannot be written, a folder of this user's in the
    temporary folder."""
    given = os.environ.get("FORMATION_ENV_CACHE")
    home = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    mine = os.path.join(tempfile.gettempdir(), f"formation_env_{os.getuid()}")
    for folder in [given] if given else [os.path.join(home, "formation_env"), mine]:
        try:
            os.makedirs(folder, exist_ok=True)
        except OSError:
            continue
        if os.access(folder, os.W_OK):
            return folder
    raise OSError(f"no writable folder for the compiled steps; set FORMATION_ENV_CACHE (tried {given or home!r})")


def _reads(lines: Sequence[str]) -> set[str]:
    """The arrays that generated lines name."""
    return {nm for line in lines for nm in re.findall(r"[A-Za-z_]\w*", line)} & set(SPECS)


class _Composer:
    """The source of one engine's step and observe (see :func:`compose`)."""

    def __init__(
        self, moving: Sequence[Any], pose: Any, route: Any, alias: Callable[[Any], str], timed: bool = False
    ) -> None:
        self.moving, self.pose, self.route, self.alias = list(moving), pose, route, alias
        #: The env time of the sample and of the one before: k T, or the sum of the drawn periods (jitter).
        self.now = "time[b]" if timed else "k[b] * dt"
        self.before = "time0[b]" if timed else "(k[b] - 1) * dt"
        self.at_state = "time0[b]" if timed else "k[b] * dt"

    def part_lines(self, part: str, observe: bool) -> list[str]:
        decl = PARTS[PART_NAMES.index(part)]
        rows = decl.observe_rows if observe and decl.observe_rows is not None else decl.rows
        if rows:
            return [call(fn) for fn in rows]
        if part == "capsules":
            lines = [f"now[b] = {self.at_state if observe else self.now}", call(static_capsules)]
            for j, row in enumerate(self.moving):
                nm, sl = self.alias(row), f"[b, m{j}:m{j + 1}]"
                for t, pre in (("now[b]", "cur"), (self.at_state if observe else self.before, "old")):
                    lines.append(f"{nm}(mov_p{j}[b], {t}, bounds, {pre}_a{sl}, {pre}_e{sl}, {pre}_r{sl})")
            return lines
        if part == "goal":
            if self.pose is None:
                return [call(static_goal)]
            nm = self.alias(self.pose)
            return [
                "pose = np.empty((d, d + 1))",
                f"{nm}(goal_p[b], {self.now}, pose)",
                "affine_into(r, pose, goal[b])",
                f"{nm}(goal_p[b], {self.now} + dt, pose)",
                "affine_into(r, pose, gvel[b])",
                "gvel[b] = (gvel[b] - goal[b]) / dt",
            ]
        if part == "route":
            nm = self.alias(self.route)
            return [f"{nm}(pvec[b], radius, {p}[b], {g}[b], {r}[b])"
                    for p, g, r in (("pos0", "goal0", "route0"), ("pos", "goal", "route1"))]  # fmt: skip
        raise KeyError(part)  # pragma: no cover


def _writers(observe: bool, left_out: frozenset[str] = frozenset()) -> dict[str, list[str]]:
    """array name -> the parts that write it (in step order) in the step or in observe (but ``left_out``)."""
    out: dict[str, list[str]] = {}
    for part in PARTS:
        if part.name in left_out:
            continue
        targets = part.observe if observe else (part.writes if part.name != "fit" else None)
        for target in targets or ():
            out.setdefault(_target_array(target), [])
            if part.name not in out[_target_array(target)]:
                out[_target_array(target)].append(part.name)
    return out


def _schedule(
    wanted: set[str], observe: bool, composer: _Composer, always: Sequence[str], left_out: frozenset[str] = frozenset()
) -> list[str]:
    """The parts to run, in step order: ``always`` and the writers of the ``wanted`` arrays, with the parts they
    read in turn (never the ``left_out`` ones)."""
    writers = _writers(observe, left_out)
    chosen = set(always)
    todo = [w for nm in wanted for w in writers.get(nm, [])]
    while todo:
        part = todo.pop()
        if part in chosen:
            continue
        chosen.add(part)
        for nm in _reads(composer.part_lines(part, observe)):
            todo += writers.get(nm, [])
    return [p for p in PART_NAMES if p in chosen]


def _check_writers(parts: Sequence[str], observe: bool, where: str) -> None:
    """Each array (each column of flags) has one writer among the scheduled parts."""
    seen: dict[str, str] = {}
    for part in PARTS:
        if part.name not in parts:
            continue
        for target in (part.observe if observe else part.writes) or ():
            if target in seen:
                raise RuntimeError(f"{where}: {target!r} is written by parts {seen[target]!r} and {part.name!r}")
            seen[target] = part.name


_TEMPLATE = '''"""Generated by formation_env.env.kernel.compose: one engine's step (do not edit)."""
import numpy as np
from numba import njit, prange
from formation_env.env.kernel import affine_into, finish_obs, static_capsules, static_goal


@njit(cache=True)
def step({inputs}):
{head}
    buf, obs, rew = np.zeros((B, n_l, D)), np.empty((B, n_l, D), np.float32), np.zeros((B, n_l))
{step_alloc}
    for b in range(B):
{step_row}
    return ({outputs},), obs, rew


@njit(cache=True, parallel=True)
def step_parallel({inputs}):
{head}
    buf, obs, rew = np.zeros((B, n_l, D)), np.empty((B, n_l, D), np.float32), np.zeros((B, n_l))
{step_alloc}
    for b in prange(B):
{step_row}
    return ({outputs},), obs, rew


@njit(cache=True)
def observe({inputs}):
{head}
    buf, obs = np.zeros((B, n_l, D)), np.empty((B, n_l, D), np.float32)
{observe_alloc}
    for b in range(B):
{observe_row}
    return obs, theta
'''


def _component(kind: str, name: str, fn: Any, given: dict[str, str], alias: str) -> str:
    """The call of a component, or TypeError naming the component when it names an unknown array."""
    try:
        return call(fn, alias, **given)
    except TypeError as exc:
        raise TypeError(f"{kind} {name!r}: {exc}") from None


def compose(
    blocks: Sequence[tuple[str, Any, int]],
    terms: Sequence[tuple[str, Any]],
    route: Any = None,
    moving: Sequence[Any] = (),
    pose: Any = None,
    network: bool = False,
    timed: bool = False,
) -> Any:
    """The compiled module of an engine's components: ``step``, ``step_parallel`` and ``observe``.

    ``blocks``: (name, row function, first entry) of each observation block; ``terms``: (name, row function) of
    the reward terms of nonzero weight, in ``Consts.weights`` order; ``route``: the scenario's route row (run only
    when a component reads ``route0`` or ``route1``; None: :func:`straight_route`); ``moving``: the rows of the
    scenario's moving obstacle types ``row(p (M, w), t, bounds, a (M, d), e (M, d), rad (M,))``, in capsule order;
    ``pose``: the scenario's ``pose_row(goal_p (w,), t, out (d, d + 1))`` of a moving goal, or None (a static
    goal). Each component's parameters are named after the step's arrays (:func:`call`). ``network``: the
    ``network`` part (:mod:`~formation_env.env.network`) takes the place of ``law``; without it the step has no
    network part at all. ``timed``: the env time is the sum of the drawn periods (``time``, jitter), not k T.

    Raises TypeError naming the component when it names no array of the step, or when a block reads an array that
    ``observe`` does not have (:data:`ARRAYS`: ``observe``). The source is written to a cache folder
    (:func:`cache_folder`) under a name made of its hash and of the stamps of every function it compiles
    (:func:`~formation_env.env._numba.source_stamp`), so a composition compiles once per machine and again after
    any of their sources changed.
    """
    route = straight_route if route is None else route
    funcs: list[Any] = [fn for _, fn, _ in blocks] + [fn for _, fn in terms] + [route, *moving]
    funcs += [pose] if pose is not None else []
    aliases: dict[int, str] = {}
    for fn in funcs:
        aliases.setdefault(id(fn), re.sub(r"\W", "_", _name(fn)[1]) + f"_fn{len(aliases)}")
    composer = _Composer(moving, pose, route, lambda fn: aliases[id(fn)], timed)
    term_lines = [_component("reward term", nm, fn, {"out": "rew[b]", "w": f"weights[{i}]"}, aliases[id(fn)])
                  for i, (nm, fn) in enumerate(terms)]  # fmt: skip
    block_lines = [_component("observation block", nm, fn, {"out": "buf[b]", "lo": str(lo)}, aliases[id(fn)])
                   for nm, fn, lo in blocks]  # fmt: skip
    for (nm, fn, _), line in zip(blocks, block_lines, strict=True):
        missing = sorted(a for a in _reads([line]) if SPECS[a].observe == "")
        if missing:
            raise TypeError(
                f"observation block {nm!r} ({'.'.join(_name(fn))}) reads {missing[0]!r}, which the reset's "
                f"observation (Engine.observe, no step) does not have; a block may read the arrays whose 'valid' "
                "column of kernel.array_table() says observe: ..."
            )
    obs_lines = [*block_lines, call(finish_obs)]
    wanted = _reads(term_lines + block_lines)
    left_out = _left_out(network)
    always = [p for p in PART_NAMES if p not in _OPTIONAL and p != "fit" and p not in left_out]
    step_parts = _schedule(wanted, False, composer, always, left_out)
    observe_parts = _schedule(_reads(block_lines) | {"theta"}, True, composer, ["fit"])
    _check_writers(step_parts, False, "step")
    _check_writers(observe_parts, True, "observe")
    step_row = [line for p in step_parts for line in composer.part_lines(p, False)] + term_lines + obs_lines
    observe_row = [line for p in observe_parts for line in composer.part_lines(p, True)] + obs_lines
    step_alloc, observe_alloc = _alloc(step_row, step_parts, False), _alloc(observe_row, observe_parts, True)
    src = _TEMPLATE.format(
        inputs=", ".join(_inputs(network)),
        head=_head([*step_row, *observe_row, step_alloc, observe_alloc], len(moving)),
        step_alloc=step_alloc,
        observe_alloc=observe_alloc,
        step_row="\n".join("        " + line for line in step_row),
        observe_row="\n".join("        " + line for line in observe_row),
        outputs=", ".join(Outputs._fields if network else NOMINAL_OUTPUTS),
    )
    part_rows = {fn.__name__: fn for part in PARTS for fn in (*part.rows, *(part.observe_rows or ()))}
    kernel_funcs = [affine_into, finish_obs, static_capsules, static_goal, *part_rows.values()]
    stamps = [f"{'.'.join(_name(fn))}={source_stamp(fn)}" for fn in kernel_funcs + funcs]
    key = hashlib.sha1("\n".join([src, *stamps]).encode()).hexdigest()[:16]
    if key not in _COMPOSED:
        _COMPOSED[key] = _load(key, src, {**part_rows, **{aliases[id(fn)]: fn for fn in funcs}})
    return _COMPOSED[key]


def _head(lines: Sequence[str], n_moving: int) -> str:
    """The generated function's first lines: the sizes, the constants and episode arrays it reads, the moving
    types' capsule ranges."""
    used = _reads(lines) | {"obs_low", "cap_r"}
    out = ["B, n, d = pos0.shape", "n_l = act.shape[1]", "D = obs_low.shape[0]"]
    out = [f"{nm} = c.{nm}" for nm in Consts._fields if nm in used] + out
    out += [f"{nm} = nc.{nm}" for nm in NetConsts._fields if nm in used]
    out += [f"{nm} = ep.{nm}" for nm in Episode._fields if nm in used]
    out += [f"mov_p{j} = ep.mov_p[{j}]" for j in range(n_moving)]
    out += ["mov_p0 = np.zeros((B, 0, 0))"] if n_moving == 0 and "mov_p0" in used else []
    out += ["m0 = cap_r.shape[1]"] + [f"m{j + 1} = m{j} + mov_p{j}.shape[1]" for j in range(n_moving)]
    out += [f"m = m{n_moving}"]
    return "\n".join("    " + line for line in out)


def _alloc(lines: Sequence[str], parts: Sequence[str], observe: bool) -> str:
    """The allocation of every array the scheduled parts write and of the outputs (in observe, the state's arrays
    stand for the state after the step, and ``act`` is zeros)."""
    names = {_target_array(t) for p in PARTS if p.name in parts for t in ((p.observe if observe else p.writes) or ())}
    names |= _reads(lines) & {a.name for a in ARRAYS if a.writer not in ("state", "engine", "reset")}
    if not observe:
        names |= set(Outputs._fields) - (NETWORK_ONLY if "network" not in parts else frozenset())
    out = []
    for spec in ARRAYS:
        if spec.name not in names or spec.name == "act":
            continue
        if observe and spec.observe == "state":
            out.append(f"{spec.name} = {spec.name}0")
        else:
            out.append(f"{spec.name} = {spec.alloc}")
    if observe and "theta" not in names:  # pragma: no cover  (fit always runs in observe)
        out.append("theta = np.empty((B, d, d))")
    return "\n".join("    " + line for line in out)


def _load(key: str, src: str, funcs: dict[str, Any]) -> Any:
    """The generated module ``src`` under ``key`` in the cache folder, its components given as globals."""
    folder = cache_folder()
    path = os.path.join(folder, f"step_{key}.py")
    if not os.path.exists(path):
        tmp = f"{path}.{os.getpid()}"
        with open(tmp, "w") as fh:
            fh.write(src)
        os.replace(tmp, path)
    spec = importlib.util.spec_from_file_location(f"formation_env_steps.step_{key}", path)
    if spec is None or spec.loader is None:  # pragma: no cover
        raise ImportError(f"cannot load the composed step {path}")
    mod = importlib.util.module_from_spec(spec)
    mod.__dict__.update(funcs)
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    return mod


_check_declaration()
