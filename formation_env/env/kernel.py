"""The compiled step: one numba implementation of a step, composed per engine from its components.

A step runs environment by environment (row b): :func:`move_row` (law and dynamics), the capsules, then
:func:`contacts_row`, the goal and :func:`judge_row` (goal distances, affine fit, success, the episode's end);
then the engine's reward terms fill the rewards and its observation blocks the observations. Every part and
every component is a numba function of the row ``b`` and of the arrays it reads, its parameters named after
the fields of :class:`StepArrays`, :class:`Consts` and :class:`Episode` (:func:`call`):

* an observation block ``row(b, out, lo, ...)`` writes every leader's entries into ``out[i, lo:lo + size]``;
* a reward term ``row(b, out, w, ...)`` adds w times every leader's value to ``out`` (n_l,);
* a scenario's ``route_row(pvec, radius, pos, goal, out)`` writes each agent's route length (m) to its goal
  (the ``approach`` potential) given the episode's parameters ``pvec`` (k,) and the agent radius (m), pos,
  goal (n, d) -> out (n,); its ``pose_row(goal_p, t, out)`` the pose of a moving goal; a moving obstacle
  type's ``row`` its capsules at time t.

:func:`compose` writes the source that calls an engine's parts and components in order and compiles it once
per distinct composition (cached on disk). The constants (:class:`Consts`) and the episode's arrays
(:class:`Episode`) are made once and reused; the step's outputs are allocated inside the compiled code.
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
from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from ._numba import jit
from .obstacles import path_clearance, point_clearance

__all__ = ["Consts", "Episode", "Outputs", "StepArrays", "call", "compose", "fit_rows", "jit", "straight_route"]

Array = NDArray[np.float64]
Ints = NDArray[np.int64]
Bools = NDArray[np.bool_]


class Consts(NamedTuple):
    """An engine's constants: ``leaders`` (n_l,) agent indices; ``others`` (n_l, n_l - 1) the other leaders of
    each (leader indices); ``pair_i``, ``pair_j`` (P,) agent pairs checked for contact; ``r`` (n, d) nominal
    configuration; ``pinv`` (d + 1, n) pseudo-inverse of [r, 1] (the affine fit); ``law`` the law's one-step map
    M ([x', mem'] = [x, u_l, mem] M; (0, 0) when the engine stepped the law itself: sparse stresses); ``c_t``
    (q, d) = C^T; ``ca_t`` (q, d) = (C A)^T, or (0, d): velocity from the change of position; ``bounds`` (2, d)
    world box (m); ``ray_dirs`` (R, 2); ``obs_low``, ``obs_high``, ``noise_mask`` (D,) observation bounds and
    which entries take noise; ``weights`` (T,) reward weights of the composed terms; scalars ``dt`` (s),
    ``u_max``, ``radius`` (m), ``fast`` (m: a move beyond it sweeps contacts), ``goal_tol``, ``formation_tol``
    (m), ``v_bound`` (m/s), ``obstacle_range``, ``sense_radius`` (m), ``max_cycles``, ``hold_steps``,
    ``n_nearest``, ``k_nearest``, ``end_on_success``."""

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


class Episode(NamedTuple):
    """The episodes' arrays from the reset: ``pvec`` (B, k) the scenario's parameters; static capsules
    ``cap_a``, ``cap_e`` (B, m, d) and ``cap_r`` (B, m); ``mov_p`` (B, M, w) the moving obstacles' parameters
    (their type's layout); ``goal_p`` (B, w') what the scenario's ``pose_row`` reads of a moving goal."""

    pvec: Array
    cap_a: Array
    cap_e: Array
    cap_r: Array
    mov_p: Array
    goal_p: Array


class StepArrays(NamedTuple):
    """What the components read and write in one step (made inside the compiled code): the constants ``c``,
    the episodes ``ep``; before the step ``x0`` (B, n, q), ``mem0`` (B, n_f, p), ``pos0``, ``vel0``, ``goal0``,
    ``gvel0`` (B, n, d), ``k0`` (B,), ``gdist0`` (B, n_l); the clipped actions ``act`` (B, n_l, p); after it
    ``x``, ``mem``, ``pos``, ``vel``, ``goal``, ``gvel``, ``k``, ``gdist``, ``streak``, ``err`` (B,) the
    formation error (m), ``theta`` (B, d, d), ``bfit`` (B, d) the affine fit, ``clear`` (B,) the smallest gap
    between surfaces (m), ``gmax`` (B,) the largest goal distance (m), ``flags`` (B, 6) bool: collision,
    out of bounds, at goal, success, terminated, truncated (the ``FLAG_*`` columns); ``effort`` (B, n_l)
    = |u_i|^2; ``cur_a``, ``cur_e`` (B, m, d), ``cur_r`` (B, m) every capsule now and ``old_a`` (B, m, d)
    their axes' starts a sample before; ``route0``, ``route1`` (B, n) route lengths before and after (when a
    term reads them)."""

    c: Consts
    ep: Episode
    x0: Array
    mem0: Array
    pos0: Array
    vel0: Array
    goal0: Array
    gvel0: Array
    k0: Ints
    gdist0: Array
    streak0: Ints
    act: Array
    x: Array
    mem: Array
    pos: Array
    vel: Array
    goal: Array
    gvel: Array
    k: Ints
    gdist: Array
    streak: Ints
    err: Array
    theta: Array
    bfit: Array
    clear: Array
    gmax: Array
    flags: Bools
    effort: Array
    cur_a: Array
    cur_e: Array
    cur_r: Array
    old_a: Array
    route0: Array
    route1: Array


FLAG_COLLISION, FLAG_OOB, FLAG_AT_GOAL, FLAG_SUCCESS, FLAG_TERMINATED, FLAG_TRUNCATED = range(6)


# ---------------------------------------------------------------------------- the parts of a row
@jit
def static_capsules(  # pragma: no cover
    b: int, cap_a: Array, cap_e: Array, cap_r: Array, cur_a: Array, cur_e: Array, cur_r: Array, old_a: Array
) -> None:
    """The static capsules of env b into ``cur_a``, ``cur_e``, ``cur_r`` and ``old_a`` (the moving ones follow,
    from their type's row)."""
    for j in range(cap_r.shape[1]):
        for c in range(cap_a.shape[2]):
            cur_a[b, j, c] = old_a[b, j, c] = cap_a[b, j, c]
            cur_e[b, j, c] = cap_e[b, j, c]
        cur_r[b, j] = cap_r[b, j]


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
    n_l, p = act.shape[1], act.shape[2]
    for i in range(n_l):
        e = 0.0
        for j in range(p):
            act[b, i, j] = min(max(act[b, i, j], -1.0), 1.0)
            e += (u_max * act[b, i, j]) ** 2
        effort[b, i] = e
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
    n, q, d = x.shape[1], x.shape[2], pos.shape[2]
    for i in range(n):
        for c in range(d):
            acc = 0.0
            for j in range(q):
                acc += x[b, i, j] * c_t[j, c]
            pos[b, i, c] = acc
            if ca_t.shape[0]:
                acc = 0.0
                for j in range(q):
                    acc += x[b, i, j] * ca_t[j, c]
                vel[b, i, c] = acc
            else:
                vel[b, i, c] = (acc - pos0[b, i, c]) / dt
    k[b] = k0[b] + 1


@jit
def contacts_row(  # pragma: no cover
    b: int, pos0: Array, pos: Array, pair_i: Ints, pair_j: Ints, radius: float, cur_a: Array, cur_e: Array,
    cur_r: Array, old_a: Array, fast: float, bounds: Array, clear: Array, flags: Bools
) -> None:  # fmt: skip
    """Env b's clearance (agent pairs; capsules at the sample, and along the step when something moved fast),
    collision and out-of-bounds flags."""
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
        for j in range(cur_r.shape[1]):
            for c in range(d):
                shift = max(shift, abs(cur_a[b, j, c] - old_a[b, j, c]))
        if moved + shift > fast:
            gap = min(gap, path_clearance(pos0[b], pos[b], old_a[b], cur_a[b], cur_e[b], cur_r[b]) - radius)
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
def judge_row(  # pragma: no cover
    b: int, pos: Array, goal: Array, leaders: Ints, gdist: Array, gmax: Array, r: Array, pinv: Array, theta: Array,
    bfit: Array, err: Array, flags: Bools, goal_tol: float, formation_tol: float, streak0: Ints, streak: Ints,
    hold_steps: int, end_on_success: bool, k: Ints, max_cycles: int
) -> None:  # fmt: skip
    """Env b's goal distances, affine fit, success streak and the episode's end."""
    n, d = pos.shape[1], pos.shape[2]
    far = 0.0
    for i in range(n):
        dd = 0.0
        for c in range(d):
            dd += (goal[b, i, c] - pos[b, i, c]) ** 2
        far = max(far, math.sqrt(dd))
    gmax[b] = far
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
def straight_route(pvec: Array, radius: float, pos: Array, goal: Array, out: Array) -> None:  # pragma: no cover
    """Straight lines: out[i] = |goal_i - pos_i| (m), the default route of the ``approach`` potential."""
    for i in range(pos.shape[0]):
        dd = 0.0
        for k in range(pos.shape[1]):
            dd += (goal[i, k] - pos[i, k]) ** 2
        out[i] = math.sqrt(dd)


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


@jit
def arrays(  # pragma: no cover
    c: Consts, ep: Episode, x0: Array, mem0: Array, pos0: Array, vel0: Array, goal0: Array, gvel0: Array, k0: Ints,
    gdist0: Array, streak0: Ints, act: Array, x_in: Array, mem_in: Array, new: bool
) -> StepArrays:  # fmt: skip
    """The step's arrays: outputs allocated (``new``; the next state x_in, mem_in when the caller stepped the
    law: a sparse stress) or the state itself (an observation without a step)."""
    B, n, d = pos0.shape
    m = ep.cap_r.shape[1] + ep.mov_p.shape[1]
    e = np.empty
    if new:
        x, mem = (e(x0.shape), e(mem0.shape)) if c.law.shape[0] else (x_in, mem_in)
        pos, vel = e(pos0.shape), e(pos0.shape)
        goal, gvel, k, gdist, streak = e(pos0.shape), e(pos0.shape), e(B, np.int64), e(gdist0.shape), e(B, np.int64)
    else:
        x, mem, pos, vel, goal, gvel, k, gdist, streak = x0, mem0, pos0, vel0, goal0, gvel0, k0, gdist0, streak0
    return StepArrays(
        c, ep, x0, mem0, pos0, vel0, goal0, gvel0, k0, gdist0, streak0, act, x, mem, pos, vel, goal, gvel, k, gdist,
        streak, e(B), e((B, d, d)), e((B, d)), np.full(B, np.inf), e(B), np.zeros((B, 6), np.bool_),
        np.zeros(act.shape[:2]), e((B, m, d)), e((B, m, d)), e((B, m)), e((B, m, d)), e((B, n)), e((B, n)),
    )  # fmt: skip


class Outputs(NamedTuple):
    """What a step returns of its arrays (:class:`StepArrays` fields of the same names; the compiled step returns
    them as a plain tuple, since numba boxes a named one much more slowly)."""

    x: Array
    mem: Array
    pos: Array
    vel: Array
    goal: Array
    gvel: Array
    k: Ints
    gdist: Array
    streak: Ints
    err: Array
    clear: Array
    gmax: Array
    flags: Bools
    effort: Array
    theta: Array


@jit
def outputs(s: StepArrays) -> tuple[NDArray[Any], ...]:  # pragma: no cover
    """The returned part of a step's arrays, in :class:`Outputs` order."""
    return (s.x, s.mem, s.pos, s.vel, s.goal, s.gvel, s.k, s.gdist, s.streak, s.err, s.clear, s.gmax, s.flags,
            s.effort, s.theta)  # fmt: skip


# ---------------------------------------------------------------------------- composition
_COMPOSED: dict[str, Any] = {}
_TEMPLATE = '''"""Generated by formation_env.env.kernel.compose: one engine's step (do not edit)."""
import numpy as np
from numba import njit, prange
from formation_env.env.kernel import (
    affine_into, arrays, contacts_row, finish_obs, fit_row, judge_row, move_row, outputs, static_capsules, static_goal,
)
{imports}


@njit(cache=True)
def step(c, ep, x0, mem0, pos0, vel0, goal0, gvel0, k0, gdist0, streak0, act, x_in, mem_in, noise):
    s = arrays(c, ep, x0, mem0, pos0, vel0, goal0, gvel0, k0, gdist0, streak0, act, x_in, mem_in, True)
    B, n_l, D, d = act.shape[0], act.shape[1], c.obs_low.shape[0], pos0.shape[2]
    buf, obs, rew = np.zeros((B, n_l, D)), np.empty((B, n_l, D), np.float32), np.zeros((B, n_l))
    ms = ep.cap_r.shape[1]
{unpack}
    for b in range(B):
        pose = np.empty((d, d + 1))
{step_row}
    return outputs(s), obs, rew


@njit(cache=True, parallel=True)
def step_parallel(c, ep, x0, mem0, pos0, vel0, goal0, gvel0, k0, gdist0, streak0, act, x_in, mem_in, noise):
    s = arrays(c, ep, x0, mem0, pos0, vel0, goal0, gvel0, k0, gdist0, streak0, act, x_in, mem_in, True)
    B, n_l, D, d = act.shape[0], act.shape[1], c.obs_low.shape[0], pos0.shape[2]
    buf, obs, rew = np.zeros((B, n_l, D)), np.empty((B, n_l, D), np.float32), np.zeros((B, n_l))
    ms = ep.cap_r.shape[1]
{unpack}
    for b in prange(B):
        pose = np.empty((d, d + 1))
{step_row}
    return outputs(s), obs, rew


@njit(cache=True)
def observe(c, ep, x0, mem0, pos0, vel0, goal0, gvel0, k0, gdist0, streak0, act, x_in, mem_in, noise):
    s = arrays(c, ep, x0, mem0, pos0, vel0, goal0, gvel0, k0, gdist0, streak0, act, x_in, mem_in, False)
    B, n_l, D = act.shape[0], act.shape[1], c.obs_low.shape[0]
    buf, obs = np.zeros((B, n_l, D)), np.empty((B, n_l, D), np.float32)
    ms = ep.cap_r.shape[1]
{unpack}
    for b in range(B):
{observe_row}
    return obs, s.theta
'''
#: Where a component's argument of a given name comes from: the generated step unpacks the step's arrays into
#: local names before its loop over the rows (numba's threaded loop takes arrays, not the records).
_SOURCES: dict[str, str] = {
    **{f: f"s.{f}" for f in StepArrays._fields if f not in ("c", "ep")},
    **{f: f"s.c.{f}" for f in Consts._fields},
    **{f: f"s.ep.{f}" for f in Episode._fields},
}
_LOCALS = ("b", "buf", "obs", "noise", "rew", "pose", "ms")


def _source(fn: Any) -> str:
    """The source of a component's module (a changed component recompiles), or a key unique to this process when
    it has none on file (a notebook cell): that composition then compiles once per process."""
    try:
        return inspect.getsource(sys.modules[_name(fn)[0]])
    except (OSError, TypeError, KeyError):
        return f"{os.getpid()}:{id(fn)}"


def _name(fn: Any) -> tuple[str, str]:
    py = getattr(fn, "py_func", fn)
    return py.__module__, py.__name__


def call(fn: Any, alias: str = "", **given: str) -> str:
    """The generated call of a component: each parameter named after a field of the step's arrays
    (:class:`StepArrays`, :class:`Consts`, :class:`Episode`) gets that array, ``b`` the row, the others what
    ``given`` says (e.g. a block's ``out`` and ``lo``); ``alias``: the name the step imports it under."""
    py = getattr(fn, "py_func", fn)
    names = inspect.signature(py).parameters
    unknown = [nm for nm in names if nm not in given and nm not in _SOURCES and nm not in _LOCALS]
    if unknown:
        raise TypeError(
            f"{py.__module__}.{py.__name__}: parameters {unknown} are not arrays of the step "
            f"(kernel.StepArrays, Consts, Episode) nor {sorted(given)}"
        )
    return f"{alias or py.__name__}({', '.join(given.get(nm, nm) for nm in names)})"


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


def compose(
    blocks: Sequence[tuple[Any, int]], terms: Sequence[Any], route: Any, moving: Any = None, pose: Any = None
) -> Any:
    """The compiled module of an engine's components: ``step`` and ``observe``.

    ``blocks``: (row function, first entry) of each observation block; ``terms``: the row functions of the
    reward terms of nonzero weight, in ``Consts.weights`` order; ``route``: the scenario's route row, or None
    when no term reads it; ``moving``: the row of the scenario's moving obstacle type
    ``row(p (M, w), t, bounds, a (M, d), e (M, d), rad (M,))`` or None; ``pose``: the scenario's
    ``pose_row(goal_p (w,), t, out (d, d + 1))`` of a moving goal, or None (a static goal). Each component's
    arguments are named after the step's arrays (:func:`call`). The source is written to a cache folder
    (:func:`cache_folder`), named by its hash and its components', and compiled
    with numba's disk cache, so a composition compiles once per machine.
    """
    funcs = [fn for fn, _ in blocks] + list(terms) + [f for f in (route, moving, pose) if f is not None]
    alias = {id(fn): f"{_name(fn)[1]}_fn{i}" for i, fn in enumerate(funcs)}  # apart from the arrays' names
    imports = [f"from {_name(fn)[0]} import {_name(fn)[1]} as {alias[id(fn)]}" for fn in funcs]
    moving_lines = []
    if moving is not None:
        nm = alias[id(moving)]
        moving_lines = [f"{nm}(mov_p[b], {t}, bounds, {a}[b, ms:], cur_e[b, ms:], cur_r[b, ms:])"
                        for t, a in (("k[b] * dt", "cur_a"), ("(k[b] - 1) * dt", "old_a"))]  # fmt: skip
    goal_lines = [call(static_goal)]
    if pose is not None:
        nm = alias[id(pose)]
        goal_lines = [
            f"{nm}(goal_p[b], k[b] * dt, pose)",
            "affine_into(r, pose, goal[b])",
            f"{nm}(goal_p[b], (k[b] + 1) * dt, pose)",
            "affine_into(r, pose, gvel[b])",
            "gvel[b] = (gvel[b] - goal[b]) / dt",
        ]
    route_lines = []
    if route is not None:
        nm = alias[id(route)]
        route_lines = [f"{nm}(pvec[b], radius, {p}[b], {g}[b], {r}[b])"
                       for p, g, r in (("pos0", "goal0", "route0"), ("pos", "goal", "route1"))]  # fmt: skip
    block_lines = [call(fn, alias[id(fn)], out="buf[b]", lo=str(lo)) for fn, lo in blocks]
    obs_lines = [*block_lines, call(finish_obs)]
    step_row = [call(move_row), call(static_capsules), *moving_lines, call(contacts_row), *goal_lines, call(judge_row)]
    term_lines = [call(fn, alias[id(fn)], out="rew[b]", w=f"weights[{i}]") for i, fn in enumerate(terms)]
    step_row += route_lines + term_lines + obs_lines
    observe_row = [call(fit_row), call(static_capsules), *moving_lines[:1], *obs_lines]
    used = sorted({nm for line in step_row + observe_row for nm in re.findall(r"[A-Za-z_]\w*", line)} & set(_SOURCES))
    src = _TEMPLATE.format(
        imports="\n".join(imports),
        unpack="\n".join(f"    {nm} = {_SOURCES[nm]}" for nm in used),
        step_row="\n".join("        " + line for line in step_row),
        observe_row="\n".join("        " + line for line in observe_row),
    )
    code = [inspect.getsource(sys.modules[__name__])] + [_source(fn) for fn in funcs]
    key = hashlib.sha1("".join([src, *code]).encode()).hexdigest()[:16]
    if key not in _COMPOSED:
        folder = cache_folder()
        path = os.path.join(folder, f"step_{key}.py")
        if not os.path.exists(path):
            tmp = f"{path}.{os.getpid()}"
            with open(tmp, "w") as fh:
                fh.write(src)
            os.replace(tmp, path)
        spec = importlib.util.spec_from_file_location(f"formation_env_steps.step_{key}", path)
        assert spec is not None and spec.loader is not None
        mod = importlib.util.module_from_spec(spec)
        sys.modules[spec.name] = mod
        spec.loader.exec_module(mod)
        _COMPOSED[key] = mod
    return _COMPOSED[key]
