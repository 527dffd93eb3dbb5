"""The engine's steps compiled (numba): the single-env step ``step1`` and the batched step's rows.

At B = 1 and n = 5 a numpy step is ~35 calls of ~1-2 us each, so the call overhead, not the
arithmetic, is the cost. ``step1`` does the whole step in one call: the folded matmul z M, the
features [pos, 1] G0 of the new positions with the episode's offsets, wall distances, feature
norms, contact clearance, success test, world-box guard, swept checks, 2D ray sensing of walls,
observation assembly (clipped, float32), global state, episode end and rewards. Its arguments are
few (the engine's constants and the episode's arrays each packed in one vector) and its outputs are
allocated by the caller, since at this size numba's cost per argument and per returned array (which it
allocates and boxes) weighs as much as the arithmetic. It computes what the batched numpy step (``Engine.step``)
computes, which stays the reference: tests compare the two on every scenario. Without numba
(``AVAILABLE`` False) ``step1`` takes the batched step.

The batched step (``Engine.step`` at B > 1) is ``step_rows`` = ``linear_rows`` (the folded matmul per
env) then ``measure_rows`` (contacts, rays, observations, rewards), over a range of env rows with
the GIL released, so that ``run_rows`` can split a large batch over threads; the rows are
independent, so the result does not depend on the number of threads. The matmul is compiled too, so
that it runs on the same threads as the rest instead of beside OpenBLAS's own thread pool.

Compiled on first use and cached on disk (``cache=True``), so later processes start at once.
"""

from __future__ import annotations

import os
import threading
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np

try:  # numba is a dependency; the env still works (slower at B = 1) without it
    import numba
    from numba import njit, prange

    AVAILABLE = True
except ImportError:  # pragma: no cover - exercised only where numba is missing
    AVAILABLE = False

    def njit(*args: Any, **kwargs: Any) -> Any:  # type: ignore[no-redef]
        return lambda f: f

    prange = range


try:  # the compiled draws (draw_runs, settle_starts) call numpy's bit generators through their C function pointers
    from llvmlite import ir
    from numba import types
    from numba.extending import intrinsic
    from numba.np.random._constants import fi_double, ki_double, wi_double, ziggurat_nor_inv_r, ziggurat_nor_r

    DRAWS = AVAILABLE
except ImportError:  # pragma: no cover - numba without its Generator support: the draws stay in Python
    DRAWS = False


__all__ = [
    "AVAILABLE",
    "DRAWS",
    "LAYOUT",
    "SENSE_CONST",
    "SENSE_GIVEN",
    "SENSE_WALLS",
    "WANT_GLOBAL",
    "WANT_OBS",
    "bit_generators",
    "copy_rows",
    "default_threads",
    "draw_runs",
    "linear_rows",
    "measure1",
    "measure_rows",
    "native_threads",
    "run_rows",
    "settle_starts",
    "step1",
    "step_end_rows",
    "step_rows",
    "swept_rows",
]

#: How ``step1`` gets the leaders' obstacle sensing: a constant, the given array, or 2D rays on walls.
SENSE_CONST, SENSE_GIVEN, SENSE_WALLS = 0, 1, 2
#: Names of the int64 layout vector ``step1`` takes: sizes, offsets into ``out`` = z M and ``g`` = z M1, and offsets
#: into its packed arrays ``c1`` (the engine's constants) and ``ep`` (the episode's arrays, ``Engine._pack_episode``).
LAYOUT = (
    "kc",  # contact rows (pairs, circles, walls)
    "kd",  # rows before the affine residual (contacts, then goal deltas)
    "d",
    "nl",
    "n_seg",  # S
    "n_rays",  # R
    "L1",  # observation entries that are linear in the state
    "obs_dim",
    "guard0",  # out[guard0:guard1]: world-box and fast-step margins, all >= 0 in a quiet step
    "guard1",
    "obs0",  # out[obs0:obs0 + nl L1]: the linear observation entries, leader-major
    "laug0",  # out[laug0:laug0 + nl (d + 1)]: each leader's [p, 1]
    "q1",  # features Q (d per row: contacts, goal deltas, the affine residual) = [pos, 1] G0 + the episode's offsets
    "walls0",  # index in Q of the first wall row's excess component (then its across component)
    "circ0",  # index in Q of the first agent-circle row (p_i - c_j)
    "delta0",  # index in Q of the first goal row (x_i* - p_i, leaders first: the agents in the order lay[perm0:])
    "perm0",  # lay[perm0:perm0 + n]: the agents, leaders first
    "sense_mode",
    "pos0",  # out[pos0:pos0 + n d], out[vel0:vel0 + n d], out[ref0:ref0 + 2 n d + 2]: next positions, velocities, ref
    "vel0",
    "ref0",
    "x0",  # out[x0:x0 + n q], out[mem0:mem0 + n_f p]: the next agent states and law memory
    "mem0",
    "Z",  # rows of M and M1: z = [x (n q), a (n_l p), mem (n_f p), ref (2 n d + 2)]
    "C",  # columns of M
    "n_circ",
    "kp",  # scenario parameters in the global state
    "c_M",  # c1[c_M:]: M (Z, C); then G0 (n d + 1, q1); the reward map's tail w_tail (n_l p + 2 n_l, 2 n_l), the bounds
    "c_G",  # of the linear observation entries (n_l, L1) low and high, theta_map (n d, d d), the global state's bounds
    "c_wt",  # (state_dim) low and high, the constant sensing (n_l, obs_dim - L1 - 1), and the scalars [err_hi,
    "c_lo",  # 1 / max_cycles, agent radius, reward weights of success, collision, formation error, dt]
    "c_hi",
    "c_tm",
    "c_slo",
    "c_shi",
    "c_sense",
    "c_scal",
    "e_thr",  # ep[0, e_thr:]: the thresholds (Kc + n + 1); then the wall map (d + 1, 3 S), the ray map (2, S R), the
    "e_walls",  # scenario parameters (kp), the wall starts and vectors (S, 2) each, the circles (n_circ, d + 1)
    "e_rays",
    "e_pvec",
    "e_a",
    "e_e",
    "e_circ",
    "hold_steps",
    "terminate_on_success",
    "max_cycles",
)
#: What ``step1`` computes beyond the step: the leaders' observations, the next state's global state.
WANT_OBS, WANT_GLOBAL = 1, 2
#: The entries of ``step1``'s ``scal`` output: flags (0 or 1), the info's scalars (m, s), then the leaders' rewards and
#: their control efforts (n_l each).
S1_BAD, S1_TERM, S1_TRUNC, S1_SUCCESS, S1_COLLISION, S1_OOB, S1_ERR, S1_CLEAR, S1_GOAL, S1_TIME, S1_REW = range(11)


@njit(cache=True, inline="always")
def _geometry1(pos: np.ndarray, rs: np.ndarray, r0: int, c1: np.ndarray, e1: np.ndarray, lay: np.ndarray) -> np.ndarray:
    """The norms ``nv`` (Kc + n + 1,) of one env's features Q = [pos, 1] G0 + the episode's offsets, as
    ``Engine._norms(Engine._features(...))``: contact distances, goal distances (leaders first), formation error (m).

    Args:
        pos (1, n, d): positions (m); rs[r0:r0 + n d]: the goal positions (agent order); c1, e1: the engine's and the
        episode's packed arrays, lay: ``step1``'s layout.
    """
    kd, d, S, q1, walls0, circ0, delta0, perm0 = lay[1], lay[2], lay[4], lay[12], lay[13], lay[14], lay[15], lay[16]
    nc, c_G, e_walls, e_circ = lay[25], lay[28], lay[38], lay[43]
    n = pos.shape[1]
    nd = n * d
    G0 = c1[c_G : c_G + (nd + 1) * q1].reshape((nd + 1, q1))
    g = np.zeros(q1)
    for i in range(n):  # [pos, 1] G0, row by row
        for c in range(d):
            p = pos[0, i, c]
            for j in range(q1):
                g[j] += p * G0[i * d + c, j]
    for j in range(q1):
        g[j] += G0[nd, j]
    for i in range(n):  # p_i - c_j
        for jj in range(nc):
            for c in range(d):
                g[circ0 + (i * nc + jj) * d + c] -= e1[e_circ + jj * (d + 1) + c]
    for kk in range(n):  # x_k* - p_k
        a = lay[perm0 + kk]
        for c in range(d):
            g[delta0 + kk * d + c] += rs[r0 + a * d + c]
    if S:
        walls = e1[e_walls : e_walls + (d + 1) * 3 * S].reshape((d + 1, 3 * S))
        for i in range(n):  # per agent and wall: (excess along it, distance across), from [p_i, 1] W
            for s in range(S):
                across, aml, back = 0.0, 0.0, 0.0
                for c in range(d):
                    p = pos[0, i, c]
                    across += p * walls[c, s]
                    aml += p * walls[c, S + s]
                    back += p * walls[c, 2 * S + s]
                across += walls[d, s]
                aml += walls[d, S + s]
                back += walls[d, 2 * S + s]
                e = aml if aml > back else back
                row = walls0 + (i * S + s) * d
                g[row] = e if e > 0.0 else 0.0
                g[row + 1] = across
    nv = np.empty(kd + 1)
    for r in range(kd):
        acc = 0.0
        for c in range(d):
            v = g[r * d + c]
            acc += v * v
        nv[r] = np.sqrt(acc)
    acc = 0.0
    for j in range(kd * d, q1):
        acc += g[j] * g[j]
    nv[kd] = np.sqrt(acc)
    return nv


@njit(cache=True)
def measure1(pos: np.ndarray, ref: np.ndarray, c1: np.ndarray, ep: np.ndarray, lay: np.ndarray) -> np.ndarray:
    """``_geometry1``'s norms (Kc + n + 1,) of positions ``pos`` (1, n, d) with the goals of ``ref`` (1, 2 n d + 2):
    a reset's goal distances and formation error at B = 1."""
    return _geometry1(pos, ref[0], 0, c1, ep[0], lay)


@njit(cache=True)
def step1(
    x: np.ndarray,
    mem: np.ndarray,
    ref: np.ndarray,
    prev: np.ndarray,
    gprev: np.ndarray,
    k: np.ndarray,
    streak: np.ndarray,
    a: np.ndarray,
    c1: np.ndarray,
    ep: np.ndarray,
    lay: np.ndarray,
    want: int,
    x2: np.ndarray,
    mem2: np.ndarray,
    pos2: np.ndarray,
    vel2: np.ndarray,
    ref2: np.ndarray,
    gd2: np.ndarray,
    err2: np.ndarray,
    k2: np.ndarray,
    streak2: np.ndarray,
    obs: np.ndarray,
    glob: np.ndarray,
    scal: np.ndarray,
) -> None:
    """One B = 1 step after the checks: z = [x, clip(a), mem, ref], out = z M, the features of the new positions
    (``_geometry1``), then the rest, into the given output arrays (allocated by the caller: cheaper than arrays made
    here and returned).

    Args:
        x (1, n, q), mem (1, n_f, p) or (1, 0, 0), ref (1, 2 n d + 2), prev (1, n, d) positions (m), gprev (1, n_l)
            the leaders' goal distances (m), k, streak (1,) int64: the state (``EngineState``'s fields).
        a (n_l p,): the raw actions.
        c1: the engine's constants, ep (1, E): the episode's arrays, both packed as ``LAYOUT`` says (see
            ``Engine._build_fast1``, ``Engine._pack_episode``); lay: the int64 layout, the fields ``LAYOUT``.
        want: ``WANT_OBS`` | ``WANT_GLOBAL``, what to compute besides the step.
    Outputs (written):
        x2, mem2, pos2, vel2, ref2, gd2, err2 (1,), k2, streak2: the next state's fields, shaped as the inputs
        (velocities as the positions); obs (n_l, obs_dim) float32 with ``WANT_OBS`` (else (0, obs_dim), untouched):
        the leaders' observations, sensing included except for ``SENSE_GIVEN``; glob (state_dim,) float32 with
        ``WANT_GLOBAL`` (else (0,)): the next state's global state as ``global_state`` makes it; scal: the entries
        ``S1_*``: bad action, terminated, truncated, success, collision (a contact, out of the world box, or a
        swept contact of a fast agent) and out of the box as 0 or 1, formation error, min clearance, goal
        distance (the largest of any agent, m), time (s), then the rewards and efforts. On an action holding NaN
        or inf only ``scal[S1_BAD]`` is written (1).
    Where a guard trips (``Engine._guarded``), the world box is tested and fast agents' motions get ``swept_rows``'
    checks.
    """
    na = a.shape[0]
    for i in range(na):
        if not np.isfinite(a[i]):
            scal[S1_BAD] = 1.0
            return
    # the fields of LAYOUT, in its order
    kc, kd, d, nl, S, R, L1, od, guard0, guard1, obs0, laug0 = (
        lay[0], lay[1], lay[2], lay[3], lay[4], lay[5], lay[6], lay[7], lay[8], lay[9], lay[10], lay[11],
    )  # fmt: skip
    mode, pos0, vel0, ref0, x0, mem0, Z, C, nc, kp = (
        lay[17], lay[18], lay[19], lay[20], lay[21], lay[22], lay[23], lay[24], lay[25], lay[26],
    )  # fmt: skip
    c_M, c_wt, c_lo, c_hi, c_tm, c_slo, c_shi, c_sense, c_scal = (
        lay[27], lay[29], lay[30], lay[31], lay[32], lay[33], lay[34], lay[35], lay[36],
    )  # fmt: skip
    e_walls, e_rays, e_pvec, e_a, e_e, e_circ = lay[38], lay[39], lay[40], lay[41], lay[42], lay[43]
    hold, tos, max_cycles = lay[44], lay[45], lay[46]
    n, q, nr = x.shape[1], x.shape[2], ref.shape[1]
    nx, nmf, nmp = n * q, mem.shape[1], mem.shape[2]
    nd = n * d
    e1 = ep[0]
    z = np.empty(Z)
    for i in range(n):
        for c in range(q):
            z[i * q + c] = x[0, i, c]
    af = np.empty(na)
    for i in range(na):
        v = a[i]
        af[i] = -1.0 if v < -1.0 else (1.0 if v > 1.0 else v)
        z[nx + i] = af[i]
    j = nx + na
    for i in range(nmf):
        for c in range(nmp):
            z[j + i * nmp + c] = mem[0, i, c]
    j += nmf * nmp
    for i in range(nr):
        z[j + i] = ref[0, i]
    out = np.dot(z, c1[c_M : c_M + Z * C].reshape((Z, C)))
    for i in range(n):
        for c in range(d):
            pos2[0, i, c] = out[pos0 + i * d + c]
            vel2[0, i, c] = out[vel0 + i * d + c]
    nv = _geometry1(pos2, out, ref0, c1, e1, lay)
    nrow = kd + 1
    thr = e1[lay[37] : lay[37] + nrow]  # e_thr
    clear = np.inf
    for r in range(kc):
        v = nv[r] - thr[r]
        if v < clear:
            clear = v
    worst = -np.inf
    for r in range(kc, nrow):
        v = nv[r] - thr[r]
        if v > worst:
            worst = v
    gmin = np.inf
    for j in range(guard0, guard1):
        if out[j] < gmin:
            gmin = out[j]
    collided = clear < 0.0
    oob = False
    if gmin < 0.0:  # the rare guards (``Engine._guarded``): the world box, then swept checks of fast agents
        half = guard0 + (guard1 - guard0) // 2  # the box rows, then the speed rows
        box, speed = np.inf, np.inf
        for j in range(guard0, guard1):
            v = out[j]
            if j < half:
                box = v if v < box or v != v else box  # a NaN stays, as in numpy's min
            else:
                speed = v if v < speed or v != v else speed
        oob = box < 0.0
        if speed < 0.0:
            seg_a = e1[e_a : e_a + 2 * S].reshape((1, S, 2))
            seg_e = e1[e_e : e_e + 2 * S].reshape((1, S, 2))
            circles = e1[e_circ : e_circ + nc * (d + 1)].reshape((1, nc, d + 1))
            one = np.ones((1, 2), dtype=np.bool_)
            low = np.array([[clear]])
            hit = np.zeros(1, dtype=np.bool_)
            swept_rows(0, 1, one, prev, pos2, seg_a, seg_e, circles, c1[c_scal + 2], low, 0, hit)
            clear = low[0, 0]
            collided |= hit[0]
        collided |= oob
    err = nv[nrow - 1]
    kn = k[0] + 1
    ok = worst < 0.0 and not collided
    st = (1 if ok else 0) if hold == 1 else (streak[0] + 1) * (1 if ok else 0)
    success = st >= hold
    term = collided or (success and tos != 0)
    trunc = kn >= max_cycles and not term
    for i in range(n):
        for c in range(q):
            x2[0, i, c] = out[x0 + i * q + c]
    for i in range(nmf):
        for c in range(nmp):
            mem2[0, i, c] = out[mem0 + i * nmp + c]
    for i in range(nr):
        ref2[0, i] = out[ref0 + i]
    for li in range(nl):
        gd2[0, li] = nv[kc + li]
    err2[0] = err
    k2[0] = kn
    streak2[0] = st
    if want & WANT_GLOBAL:
        tm = c1[c_tm : c_tm + nd * d * d].reshape((nd, d * d))
        slo, shi = c1[c_slo:c_shi], c1[c_shi : c_shi + (c_shi - c_slo)]
        pvec = e1[e_pvec : e_pvec + kp]
        _global_row(out, pos0, out, vel0, out, ref0, err, tm, pvec, kn * c1[c_scal + 1], slo, shi, glob)
    if want & WANT_OBS:
        lin_lo = c1[c_lo : c_lo + nl * L1].reshape((nl, L1))
        lin_hi = c1[c_hi : c_hi + nl * L1].reshape((nl, L1))
        err_hi = c1[c_scal]
        ks = od - L1 - 1
        sense_in = c1[c_sense : c_sense + nl * ks].reshape((nl, ks))
        walls = e1[e_walls : e_walls + (d + 1) * 3 * S].reshape((d + 1, 3 * S))
        rays = e1[e_rays : e_rays + 2 * S * R].reshape((2, S * R))
        for li in range(nl):
            for j in range(L1):
                v = out[obs0 + li * L1 + j]
                lo = lin_lo[li, j]
                hi = lin_hi[li, j]
                if v < lo:
                    v = lo
                if v > hi:
                    v = hi
                obs[li, j] = v
            obs[li, L1] = err if err < err_hi else err_hi
            if mode == 2:  # 2D rays: T / sensor range of the first hit inside a wall, else 1 (as ``measure_rows``)
                best = np.ones(R)
                for s in range(S):
                    across, aml, back = walls[d, s], walls[d, S + s], walls[d, 2 * S + s]
                    for c in range(d):
                        p = out[laug0 + li * (d + 1) + c]
                        across += p * walls[c, s]
                        aml += p * walls[c, S + s]
                        back += p * walls[c, 2 * S + s]
                    f = -across
                    for r in range(R):
                        gr = rays[0, s * R + r]
                        t, uf = f * gr, rays[1, s * R + r] * f
                        if gr != 0.0 and t >= 0.0 and uf >= back and aml + uf <= 0.0 and t < best[r]:
                            best[r] = t
                for r in range(R):
                    obs[li, L1 + 1 + r] = best[r]
            else:
                for j in range(ks):
                    obs[li, L1 + 1 + j] = sense_in[li, j]
    nw = 2 * nl
    w_tail = c1[c_wt : c_wt + (na + nw) * nw].reshape((na + nw, nw))
    rew = np.zeros(nw)
    for i in range(na + nw):
        if i < na:
            f = af[i] * af[i]
        elif i < na + nl:
            f = gprev[0, i - na]
        else:
            f = nv[kc + i - na - nl]
        if f != 0.0:
            for j in range(nw):
                rew[j] += f * w_tail[i, j]
    fs = 1.0 if success else 0.0
    fc = 1.0 if collided else 0.0
    head = fs * c1[c_scal + 3] + fc * c1[c_scal + 4] + err * c1[c_scal + 5]
    goal = -np.inf
    for r in range(kc, nrow - 1):
        if nv[r] > goal:
            goal = nv[r]
    scal[S1_BAD] = 0.0
    scal[S1_TERM] = 1.0 if term else 0.0
    scal[S1_TRUNC] = 1.0 if trunc else 0.0
    scal[S1_SUCCESS] = fs
    scal[S1_COLLISION] = fc
    scal[S1_OOB] = 1.0 if oob else 0.0
    scal[S1_ERR] = err
    scal[S1_CLEAR] = clear
    scal[S1_GOAL] = goal
    scal[S1_TIME] = kn * c1[c_scal + 6]
    for li in range(nl):
        scal[S1_REW + li] = rew[li] + head
        scal[S1_REW + nl + li] = rew[nl + li]


#: Env rows ``measure_rows`` takes at a time, transposed (its loops then run over envs: SIMD).
MEASURE_BLOCK = 128


@njit(cache=True, nogil=True, inline="always")
def _rows_t(col: np.ndarray, s0: int, m: int, row: np.ndarray) -> None:
    """``row[:m] = col[s0:s0 + m]``: one column of a block of env rows into a row of its transpose, in a loop of
    constant length ``MEASURE_BLOCK`` for a full block (vectorised; a loop of length m is not)."""
    if m == MEASURE_BLOCK:
        for e in range(MEASURE_BLOCK):
            row[e] = col[s0 + e]
    else:
        for e in range(m):
            row[e] = col[s0 + e]


@njit(cache=True, nogil=True, inline="always")
def _clear_rows(d2: np.ndarray, one: bool, low: np.ndarray, tk: np.ndarray, clear: np.ndarray, m: int) -> None:
    """One contact row of a block: squared distances ``d2[:m]`` lower ``low`` (``one``: every such row has one
    threshold, rooted once by ``_fold_root``) or lower ``clear`` by sqrt(d2) - ``tk``."""
    if one:
        for e in range(m):
            v, lw = d2[e], low[e]
            low[e] = v if v < lw else lw
    else:
        for e in range(m):
            v = np.sqrt(d2[e]) - tk[e]
            cl = clear[e]
            clear[e] = v if v < cl else cl


@njit(cache=True, nogil=True, inline="always")
def _fold_root(low: np.ndarray, t: float, clear: np.ndarray, m: int) -> None:
    """``clear[:m]`` lowered by sqrt(``low``) - t (the least of the rows' sqrt(d2) - t, to the bit: both are
    monotone), and ``low`` reset to inf."""
    for e in range(m):
        v = np.sqrt(low[e]) - t
        cl = clear[e]
        clear[e] = v if v < cl else cl
        low[e] = np.inf


@njit(cache=True, nogil=True)
def measure_rows(
    b0: int,
    b1: int,
    pos: np.ndarray,
    prev: np.ndarray,
    vel: np.ndarray,
    ref: np.ndarray,
    act: np.ndarray,
    gprev: np.ndarray,
    circles: np.ndarray,
    walls: np.ndarray,
    rays: np.ndarray,
    thr: np.ndarray,
    pairs: np.ndarray,
    leaders: np.ndarray,
    perm: np.ndarray,
    pinv: np.ndarray,
    hfit: np.ndarray,
    box: np.ndarray,
    fast: float,
    inv_cycles: float,
    lin_lo: np.ndarray,
    lin_hi: np.ndarray,
    err_hi: float,
    w_tail: np.ndarray,
    sense_in: np.ndarray,
    mode: int,
    obs: np.ndarray,
    dist: np.ndarray,
    flags: np.ndarray,
    rew: np.ndarray,
) -> None:
    """Everything of a batched step that is not linear in the state, for envs b0 <= b < b1, from the new
    positions, written into rows [b0, b1) of ``obs``, ``dist``, ``flags`` and ``rew`` (and nothing else).

    The same quantities as ``Engine.step``'s numpy code (the reference, compared in tests), computed
    directly from positions instead of through the folded feature matrices. The envs go ``MEASURE_BLOCK``
    at a time, transposed, so that each loop runs over a block of envs (SIMD, branch-free minima); each
    env's arithmetic keeps one order, so its result does not depend on the block or the rows' split.
    The rays go env by env, SIMD over the rays, from the leaders' across / along values of the agent-wall loop.

    Args:
        b0, b1: the env rows to compute.
        pos, prev, vel: new positions, previous positions, new velocities, shape (B, n, d) (m, m/s).
        ref: the new exogenous row [goal (n d), goal velocity (n d), 1, k], shape (B, 2 n d + 2).
        act: the actions (B, n_l p), clipped to [-1, 1] and squared here; gprev: goal distances before the
        step (B, n_l), m.
        circles (B, C, d + 1); walls (B, d + 1, 3 S): [p, 1] -> (across, along - length, -along);
        rays (B, 2, S R): per wall and ray G and U (``wall_maps``); thr (B, Kc + n + 1) thresholds (m), or (1, ...)
        shared by every env.
        pairs (P, 2) agent pairs checked for contact; leaders (n_l,); perm (n,): leaders first.
        pinv (d + 1, n), hfit (n, d + 1): the affine fit [r, 1]^+ and [r, 1].
        box (2, d): world box low and high; fast: per-axis displacement (m) above which an agent is fast.
        inv_cycles: 1 / max_cycles; lin_lo, lin_hi (n_l, L1); err_hi; w_tail: reward rows for
        [a2, gprev, goal distances]; sense_in (B, n_l, ks) used unless ``mode`` is SENSE_WALLS.
    Outputs:
        obs (B, n_l, obs_dim) float32; dist (B, n_l + 4): leader goal distances, formation error, largest
        goal distance, min clearance, max of the success margins (nv - thr)[Kc:]; flags (B, 2) bool: out of
        the box, some agent fast; rew (B, 2 n_l): the reward's and effort's parts linear in [a2, gprev, dist].
    """
    n, d = pos.shape[1], pos.shape[2]
    nl, L1 = lin_lo.shape
    od = obs.shape[2]
    C = circles.shape[1]
    S = walls.shape[2] // 3
    R = rays.shape[2] // S if S > 0 else 0
    P = pairs.shape[0]
    kc = P + n * C + n * S
    nd = n * d
    tk2 = 2 * nd + 1  # the column of k in ref
    nt = thr.shape[1]
    na = act.shape[1]
    nw = rew.shape[1]
    nf = na + 2 * nl
    sqn = np.sqrt(float(n))
    W = max(min(MEASURE_BLOCK, b1 - b0), 1)  # the block's buffers (a small batch needs no full ones)
    pt = np.empty((nd, W))  # the block's positions, transposed: row i d + c is p[i, c] of each env
    vt = np.empty((nl * d, W))  # leaders' velocities
    gt = np.empty((2 * nd + 2, W))  # ref
    tt = np.empty((nt, W))  # thresholds
    ct = np.empty((C * d, W))  # circle centres
    wt = np.empty(((d + 1) * 3 * S, W))  # wall maps
    ft = np.empty((nf, W))  # reward features [a2, gprev, goal distances of the leaders]
    coef = np.empty(((d + 1) * d, W))
    lin = np.empty((L1, W))
    acc = np.empty(W)
    res = np.empty(W)  # a residual of the affine fit
    wa, wl, wb = np.empty(W), np.empty(W), np.empty(W)  # across, along - length, -along of one agent and wall
    lw = np.empty((nl * S * 3, W))  # and of each leader and wall, for the rays
    lead = np.full(n, -1)  # an agent's leader index, or -1
    for li in range(nl):
        lead[leaders[li]] = li
    clear = np.empty(W)
    worst = np.empty(W)
    gmax = np.empty(W)
    err = np.empty(W)
    oob = np.empty(W, dtype=np.bool_)
    fst = np.empty(W, dtype=np.bool_)
    moved = np.empty(W)  # per env, the largest per-axis displacement of an agent
    rt = np.empty((nw, W))
    best = np.empty(R)  # one leader's readings, per env
    shared = thr.shape[0] == 1  # one row of thresholds for every env: transposed once
    if shared:
        for j in range(nt):
            for e in range(W):
                tt[j, e] = thr[0, j]
    # one threshold t for every pair (or every agent-wall row): min (sqrt(d2) - t) = sqrt(min d2) - t exactly
    # (sqrt and - t are monotone), so one square root per env instead of one per pair
    one_pair, one_wall = shared and P > 0, shared and n * S > 0
    for k in range(1, P):
        one_pair &= thr[0, k] == thr[0, 0]
    kw = P + n * C  # the first agent-wall row
    for k in range(1, n * S):
        one_wall &= thr[0, kw + k] == thr[0, kw]
    low = np.empty(W)  # the least squared distance so far (one_pair, one_wall)
    for s0 in range(b0, b1, W):
        m = min(W, b1 - s0)
        # the block, transposed (column by column, ``_rows_t``): then every loop below runs over its envs (SIMD)
        for i in range(n):
            for c in range(d):
                _rows_t(pos[:, i, c], s0, m, pt[i * d + c])
        for e in range(m):
            moved[e] = 0.0
        for i in range(n):  # the largest per-axis displacement (prev read in place): the fast-agent test
            for c in range(d):
                pc = pt[i * d + c]
                for e in range(m):
                    step = abs(pc[e] - prev[s0 + e, i, c])
                    moved[e] = step if step > moved[e] else moved[e]
        for e in range(m):
            fst[e] = moved[e] > fast
        for li in range(nl):
            a = leaders[li]
            for c in range(d):
                _rows_t(vel[:, a, c], s0, m, vt[li * d + c])
                _rows_t(ref[:, nd + a * d + c], s0, m, gt[nd + a * d + c])  # the leaders' goal velocities
        for j in range(nd):  # the goal; its velocity only where observed (above), and k
            _rows_t(ref[:, j], s0, m, gt[j])
        _rows_t(ref[:, tk2], s0, m, gt[tk2])
        if not shared:
            for j in range(nt):
                _rows_t(thr[:, j], s0, m, tt[j])
        for j in range(C):
            for c in range(d):
                _rows_t(circles[:, j, c], s0, m, ct[j * d + c])
        for r in range(d + 1):
            for j in range(3 * S):
                _rows_t(walls[:, r, j], s0, m, wt[r * 3 * S + j])
        for j in range(na):  # the squared clipped actions
            fj = ft[j]
            _rows_t(act[:, j], s0, m, fj)
            for e in range(m):
                v = fj[e]
                v = -1.0 if v < -1.0 else v
                v = 1.0 if v > 1.0 else v
                fj[e] = v * v
        for j in range(nl):
            _rows_t(gprev[:, j], s0, m, ft[na + j])
        for e in range(m):
            clear[e] = np.inf
            low[e] = np.inf
        for k in range(P):  # agent pairs
            i, j = pairs[k, 0], pairs[k, 1]
            for e in range(m):
                acc[e] = 0.0
            for c in range(d):
                pi, pj = pt[i * d + c], pt[j * d + c]
                for e in range(m):
                    v = pi[e] - pj[e]
                    acc[e] += v * v
            _clear_rows(acc, one_pair, low, tt[k], clear, m)
        if one_pair:
            _fold_root(low, thr[0, 0], clear, m)
        for i in range(n):
            for j in range(C):  # agent-circle
                for e in range(m):
                    acc[e] = 0.0
                for c in range(d):
                    pi, cj = pt[i * d + c], ct[j * d + c]
                    for e in range(m):
                        v = pi[e] - cj[e]
                        acc[e] += v * v
                _clear_rows(acc, False, low, tt[P + i * C + j], clear, m)  # (circles' radii: thresholds differ)
            for s in range(S):  # agent-wall: distance across, and excess along the wall (rows of wt, SIMD)
                tk = tt[P + n * C + i * S + s]
                o = d * 3 * S
                w0, w1, w2 = wt[o + s], wt[o + S + s], wt[o + 2 * S + s]
                for e in range(m):
                    wa[e] = w0[e]
                    wl[e] = w1[e]
                    wb[e] = w2[e]
                for c in range(d):
                    pc, y0 = pt[i * d + c], wt[c * 3 * S + s]
                    y1, y2 = wt[c * 3 * S + S + s], wt[c * 3 * S + 2 * S + s]
                    for e in range(m):
                        pe = pc[e]
                        wa[e] += pe * y0[e]
                        wl[e] += pe * y1[e]
                        wb[e] += pe * y2[e]
                if mode == 2 and lead[i] >= 0:
                    r0 = (lead[i] * S + s) * 3
                    lw[r0, :m], lw[r0 + 1, :m], lw[r0 + 2, :m] = wa[:m], wl[:m], wb[:m]
                for e in range(m):  # the squared distance to the wall: across, and the excess along it
                    across, along, back = wa[e], wl[e], wb[e]
                    ex = along if along > back else back
                    ex = ex if ex > 0.0 else 0.0
                    acc[e] = across * across + ex * ex
                _clear_rows(acc, one_wall, low, tk, clear, m)
        if one_wall:
            _fold_root(low, thr[0, kw], clear, m)
        for e in range(m):
            worst[e] = -np.inf
            gmax[e] = 0.0
        for k in range(n):  # goal distances, leaders first
            i = perm[k]
            for e in range(m):
                acc[e] = 0.0
            for c in range(d):
                gi, pi = gt[i * d + c], pt[i * d + c]
                for e in range(m):
                    v = gi[e] - pi[e]
                    acc[e] += v * v
            tk = tt[kc + k]
            for e in range(m):
                g = np.sqrt(acc[e])
                gm = gmax[e]
                gmax[e] = g if g > gm else gm
                if k < nl:
                    ft[na + nl + k, e] = g
                v = g - tk[e]
                wo = worst[e]
                worst[e] = v if v > wo else wo
        for r in range(d + 1):  # affine fit, then the RMS residual
            for c in range(d):
                cf = coef[r * d + c]
                for e in range(m):
                    cf[e] = 0.0
                for q in range(n):
                    w = pinv[r, q]
                    pq = pt[q * d + c]
                    for e in range(m):
                        cf[e] += w * pq[e]
        for e in range(m):
            acc[e] = 0.0
        for q in range(n):
            for c in range(d):
                pq = pt[q * d + c]
                for e in range(m):
                    res[e] = pq[e]
                for r in range(d + 1):  # res = p - [r, 1] coef, term by term (each env's order as before)
                    h, cr = hfit[q, r], coef[r * d + c]
                    for e in range(m):
                        res[e] -= h * cr[e]
                for e in range(m):
                    v = res[e]
                    acc[e] += v * v
        tk = tt[kc + n]
        for e in range(m):
            er = np.sqrt(acc[e]) / sqn
            err[e] = er
            v = er - tk[e]
            wo = worst[e]
            worst[e] = v if v > wo else wo
        for e in range(m):
            oob[e] = False
        for i in range(n):  # world box
            for c in range(d):
                lo, hi = box[0, c], box[1, c]
                pi = pt[i * d + c]
                for e in range(m):
                    v = pi[e]
                    oob[e] |= (v < lo) | (v > hi)
        for j in range(nw):  # reward tail: [a2, gprev, goal distances] @ w_tail
            rj = rt[j]
            for e in range(m):
                rj[e] = 0.0
            for i in range(nf):
                w = w_tail[i, j]
                fi = ft[i]
                for e in range(m):
                    f = fi[e]
                    x = rj[e]
                    rj[e] = x + f * w if f != 0.0 else x
        for e in range(m):
            b = s0 + e
            flags[b, 0] = oob[e]
            flags[b, 1] = fst[e]
            for k in range(nl):
                dist[b, k] = ft[na + nl + k, e]
            dist[b, nl] = err[e]
            dist[b, nl + 1] = gmax[e]
            dist[b, nl + 2] = clear[e]
            dist[b, nl + 3] = worst[e]
            for j in range(nw):
                rew[b, j] = rt[j, e]
        for li in range(nl):  # observations (layout: Engine.obs_blocks)
            a = leaders[li]
            o = 0
            for c in range(d):
                pa, va = pt[a * d + c], vt[li * d + c]
                la, lb = lin[o + c], lin[o + d + c]
                for e in range(m):
                    la[e] = pa[e]
                    lb[e] = va[e]
            o += 2 * d
            for lj in range(nl):
                if lj != li:
                    for c in range(d):
                        pa, pb, lo_ = pt[a * d + c], pt[leaders[lj] * d + c], lin[o + c]
                        for e in range(m):
                            lo_[e] = pb[e] - pa[e]
                    o += d
            for c in range(d):
                pa, ga, gv = pt[a * d + c], gt[a * d + c], gt[nd + a * d + c]
                la, lb = lin[o + c], lin[o + d + c]
                for e in range(m):
                    la[e] = ga[e] - pa[e]
                    lb[e] = gv[e]
            o += 2 * d
            for i_ in range(d):  # Theta[i_, j_] = sum_m pinv[j_, m] p_m[i_]: row i_ of Theta is column i_ of coef
                for j_ in range(d):
                    cf, lo_ = coef[j_ * d + i_], lin[o + i_ * d + j_]
                    for e in range(m):
                        lo_[e] = cf[e]
            o += d * d
            gk, lo_ = gt[tk2], lin[o]
            for e in range(m):
                lo_[e] = gk[e] * inv_cycles
            for j in range(L1):
                lo, hi, lj_ = lin_lo[li, j], lin_hi[li, j], lin[j]
                for e in range(m):
                    v = lj_[e]
                    v = lo if v < lo else v
                    lj_[e] = hi if v > hi else v
            if mode == 2:  # 2D rays: T / sensor range of the first hit inside a wall, else 1 (per env, SIMD over rays)
                for e in range(m):
                    b = s0 + e
                    gs, us = rays[b, 0], rays[b, 1]
                    for r in range(R):
                        best[r] = 1.0
                    for s in range(S):  # the leader's across, along - length, -along (the agent-wall loop's)
                        r0 = (li * S + s) * 3
                        f, aml, back = -lw[r0, e], lw[r0 + 1, e], lw[r0 + 2, e]
                        for r in range(R):  # branch-free: hit inside the wall (along from 0 to length), nearer
                            g, bt = gs[s * R + r], best[r]
                            t, uf = f * g, us[s * R + r] * f
                            best[r] = t if (g != 0.0) & (t >= 0.0) & (uf >= back) & (aml + uf <= 0.0) & (t < bt) else bt
                    for r in range(R):
                        obs[b, li, L1 + 1 + r] = best[r]
            else:
                for e in range(m):
                    for j in range(od - L1 - 1):
                        obs[s0 + e, li, L1 + 1 + j] = sense_in[s0 + e, li, j]
            for e in range(m):
                b = s0 + e
                for j in range(L1):
                    obs[b, li, j] = lin[j, e]
                er = err[e]
                obs[b, li, L1] = er if er < err_hi else err_hi


#: Env rows ``linear_rows`` takes at a time (its transposed blocks then stay in the L1/L2 cache).
LINEAR_BLOCK = 64


@njit(cache=True, nogil=True)
def linear_rows(
    b0: int,
    b1: int,
    x: np.ndarray,
    a: np.ndarray,
    mem: np.ndarray,
    ref: np.ndarray,
    k: np.ndarray,
    ptr: np.ndarray,
    row_of: np.ndarray,
    val: np.ndarray,
    take: np.ndarray,
    pv: np.ndarray,
    x_o: np.ndarray,
    mem_o: np.ndarray,
    ref_o: np.ndarray,
    pos_o: np.ndarray,
    vel_o: np.ndarray,
) -> None:
    """The linear part of a batched step for envs b0 <= b < b1: [x', mem', pos', vel'] = [x, a, mem, ref] Mk,
    as the distinct columns ``y = z Mc`` and then column j of [x', mem', pos', vel'] = ``y[take[j]]`` (pos'
    and vel' are columns of x' for the integrators, so they are not computed twice).

    Mc comes by its nonzeros, column by column (CSC, rows increasing): column j of Mc holds
    ``val[ptr[j]:ptr[j + 1]]`` in the rows ``row_of[ptr[j]:ptr[j + 1]]``. The laws act on each dimension alike
    (Omega kron I_d), and the integrators' blocks are sparse, so most of Mc is zero (82 % for the benchmark's 10
    agents in 2D, a complete graph; more for sparser stresses). The envs go ``LINEAR_BLOCK`` at a
    time, transposed, so that each nonzero of Mc is one multiply-add over a contiguous block of envs (SIMD).
    Every output sums its terms from zero in the order of z, as the dense product row by row does, and the
    terms left out are exact zeros, so for finite z the result has the same bits as that dense product.

    Args:
        x (B, n q) states, a (B, n_l p) actions (clipped to [-1, 1] here), mem (B, n_f p) law memory (width 0:
        none), ref (B, 2 n d + 2) exogenous row, used in z only when Mc has rows for it (more than n q + n_l p +
        n_f p); k (B,) int64: the samples after the step.
        ptr (columns of Mc + 1,) int64, row_of (nnz,) int64, val (nnz,): Mc in CSC form;
        take (n q + n_f p + 2 n d,) int64: the distinct column of each output; pv (2 n d,) int64: the column of
        x' that each entry of [pos', vel'] equals (then they are gathered from the env's row of x', in the L1
        cache, instead of from the transposed block again), or width 0: from the block.
    Outputs (rows b0..b1-1): x_o (B, n q), mem_o (B, n_f p), pos_o and vel_o (B, n, d) (m, m/s); ref_o: the new
    exogenous row of a fixed goal, ref with k in its last column (B, 2 n d + 2), or width 0: not written.
    """
    nx, na, nm = x.shape[1], a.shape[1], mem.shape[1]
    n, d = pos_o.shape[1], pos_o.shape[2]
    ncol = ptr.shape[0] - 1
    nz = 0
    for t in range(row_of.shape[0]):
        nz = max(nz, row_of[t] + 1)
    nr = max(nz - nx - na - nm, 0)
    W = LINEAR_BLOCK
    zt = np.empty((nx + na + nm + nr, W))
    yt = np.empty((ncol, W))
    c0 = nx + nm
    nd = n * d
    po, vo = pos_o.reshape(pos_o.shape[0], nd), vel_o.reshape(vel_o.shape[0], nd)
    direct = pv.shape[0] == 2 * nd
    for s in range(b0, b1, W):
        m = min(W, b1 - s)
        for e in range(m):  # z of the block, transposed (the actions clipped to [-1, 1])
            b = s + e
            for i in range(nx):
                zt[i, e] = x[b, i]
            for i in range(na):
                v = a[b, i]
                v = -1.0 if v < -1.0 else v
                zt[nx + i, e] = 1.0 if v > 1.0 else v
            for i in range(nm):
                zt[nx + na + i, e] = mem[b, i]
            for i in range(nr):
                zt[nx + na + nm + i, e] = ref[b, i]
        for j in range(ncol):
            yj = yt[j]
            for e in range(m):
                yj[e] = 0.0
            for t in range(ptr[j], ptr[j + 1]):
                v = val[t]
                zi = zt[row_of[t]]
                for e in range(m):
                    yj[e] += v * zi[e]
        last = ref_o.shape[1] - 1  # -1: ref_o has width 0, the goal moves (ref' is made in numpy)
        for e in range(m):
            b = s + e
            xr, pr, vr = x_o[b], po[b], vo[b]
            for j in range(nx):
                xr[j] = yt[take[j], e]
            for j in range(nm):
                mem_o[b, j] = yt[take[nx + j], e]
            if direct:
                for j in range(nd):
                    pr[j] = xr[pv[j]]
                for j in range(nd):
                    vr[j] = xr[pv[nd + j]]
            else:
                for j in range(nd):
                    pr[j] = yt[take[c0 + j], e]
                for j in range(nd):
                    vr[j] = yt[take[c0 + nd + j], e]
            if last >= 0:  # the new exogenous row of a fixed goal: the old one, k in its last column
                for j in range(last):
                    ref_o[b, j] = ref[b, j]
                ref_o[b, last] = k[b]


@njit(cache=True, nogil=True)
def step_rows(b0: int, b1: int, linear: tuple[np.ndarray, ...], *measure: Any) -> None:
    """A whole batched step for envs b0 <= b < b1: ``linear_rows(b0, b1, *linear, pos, vel)`` (``linear``: its
    arguments from ``x`` to ``ref_o``, with the old row ``ref``) into ``measure``'s pos and vel, then
    ``measure_rows(b0, b1, *measure)`` on the new positions (``measure``: ``measure_rows``'s arguments from
    ``pos`` on, with the new row ``ref``)."""
    linear_rows(b0, b1, *linear, measure[0], measure[2])
    measure_rows(b0, b1, *measure)


@njit(cache=True, nogil=True)
def step_end_rows(
    b0: int, b1: int, linear: tuple[Any, ...], measure: tuple[Any, ...], swept: tuple[Any, ...], end: tuple[Any, ...]
) -> None:
    """``step_rows`` and the rest of a batched step for envs b0 <= b < b1, so that it too runs on the step's
    threads: the swept checks of the envs with a fast agent (``swept_rows``: ``swept`` = its (a, e, circles,
    radius, col, hit)), then the episode ends (``episode_rows``: ``end`` = its arguments after ``hit``; the
    default success test). ``measure``: ``measure_rows``' arguments from ``pos`` on."""
    step_rows(b0, b1, linear, *measure)
    pos, prev, dist, flags = measure[0], measure[1], measure[25], measure[26]
    a, e, circles, radius, col, hit = swept
    swept_rows(b0, b1, flags, prev, pos, a, e, circles, radius, dist, col, hit)
    ok_in, re, st0, k, hold, eos, mc, ws, wc, wf, rew, ends, err, clear, gd, streak = end
    episode_rows(
        b0, b1, dist, flags, hit, ok_in, re, st0, k, hold, eos, mc, ws, wc, wf, rew, ends, err, clear, gd, streak
    )


@njit(cache=True, nogil=True)
def episode_rows(
    b0: int,
    b1: int,
    dist: np.ndarray,
    flags: np.ndarray,
    hit: np.ndarray,
    ok_in: np.ndarray,
    re: np.ndarray,
    streak_prev: np.ndarray,
    k: np.ndarray,
    hold: int,
    end_on_success: bool,
    max_cycles: int,
    ws: float,
    wc: float,
    wf: float,
    rew: np.ndarray,
    ends: np.ndarray,
    err: np.ndarray,
    clear: np.ndarray,
    gd: np.ndarray,
    streak: np.ndarray,
) -> None:
    """The end of a batched step for envs b0 <= b < b1, after ``measure_rows`` (and the swept checks): contacts,
    the success streak, episode ends and rewards; the same operations in the same order as ``Engine._step_batch``'s
    numpy reference (``Engine._episode_end``), so the same bits.

    Args:
        dist (B, n_l + 4), flags (B, 2) bool, re (B, 2 n_l): ``measure_rows``' outputs (``dist``'s clearance
        column lowered by the swept checks, if any); hit (B,) bool: swept wall crossings.
        ok_in: (B,) bool, the scenario's own success test, or (0,): success is ``dist[:, n_l + 3] < 0``.
        streak_prev (B,) int64: successes in a row before the step; k (B,) int64: samples after it.
        hold: successes in a row that are a success; end_on_success: a success ends the episode;
        max_cycles: samples of an episode; ws, wc, wf: reward weights of success, collision, formation error.
    Outputs:
        rew (B, n_l): rewards; ends (5, B) bool: success, collision, out of bounds, terminated, truncated;
        err, clear (B,): formation error and clearance (m); gd (B, n_l): leader goal distances (m);
        streak (B,) int64.
    """
    nl = gd.shape[1]
    own = ok_in.shape[0] > 0
    for b in range(b0, b1):
        cl, er = dist[b, nl + 2], dist[b, nl]
        oob = flags[b, 0]
        col = (cl < 0.0) | oob | hit[b]
        ok = (ok_in[b] if own else dist[b, nl + 3] < 0.0) & (not col)
        st = np.int64(ok) if hold == 1 else (streak_prev[b] + 1) * np.int64(ok)
        suc = st >= hold
        term = (col | suc) if end_on_success else col
        ends[0, b], ends[1, b], ends[2, b] = suc, col, oob
        ends[3, b], ends[4, b] = term, (k[b] >= max_cycles) & (not term)
        head = (ws if suc else 0.0) + (wc if col else 0.0) + er * wf
        for j in range(nl):
            rew[b, j] = re[b, j] + head
            gd[b, j] = dist[b, j]
        err[b], clear[b], streak[b] = er, cl, st


@njit(cache=True, nogil=True)
def swept_rows(
    b0: int,
    b1: int,
    flags: np.ndarray,
    prev: np.ndarray,
    pos: np.ndarray,
    a: np.ndarray,
    e: np.ndarray,
    circles: np.ndarray,
    radius: float,
    dist: np.ndarray,
    col: int,
    hit: np.ndarray,
) -> None:
    """``Engine._swept`` compiled, for the envs b0 <= b < b1 with ``flags[b, 1]`` (an agent fast: it could
    tunnel): a motion prev -> pos that properly crosses a wall (2D; ``geometry.segment_crossings``) marks
    ``hit[b]``; the swept clearance from the circles (``geometry.circle_clearance``, minus ``radius``) lowers
    ``dist[b, col]`` and marks ``hit[b]`` when negative. The same operations as the numpy code, per env.

    Args:
        flags (B, 2) bool: ``measure_rows``' flags; prev, pos (B, n, d): positions before and after (m);
        a, e (B, S, 2): wall starts and vectors (S = 0: none); circles (B, C, d + 1): centres and radii;
        radius: the agent radius (m); dist (B, k): ``measure_rows``' distances, column ``col`` the clearance.
    Outputs: dist[:, col] lowered in place; hit (B,) bool set where a swept contact is found.
    """
    n, d = pos.shape[1], pos.shape[2]
    S, C = a.shape[1], circles.shape[1]
    for b in range(b0, b1):
        if not flags[b, 1]:
            continue
        if d == 2:
            for i in range(n):
                x0, y0, x1, y1 = prev[b, i, 0], prev[b, i, 1], pos[b, i, 0], pos[b, i, 1]
                mx, my = x1 - x0, y1 - y0
                for s in range(S):
                    ax, ay, ex, ey = a[b, s, 0], a[b, s, 1], e[b, s, 0], e[b, s, 1]
                    side0 = ex * (y0 - ay) - ey * (x0 - ax)
                    side1 = ex * (y1 - ay) - ey * (x1 - ax)
                    end0 = mx * (ay - y0) - my * (ax - x0)
                    end1 = mx * (ay + ey - y0) - my * (ax + ex - x0)
                    if (side0 * side1 < 0.0) & (end0 * end1 < 0.0):
                        hit[b] = True
        if C > 0:
            cc = np.inf
            for i in range(n):
                for j in range(C):
                    mm, wm = 0.0, 0.0
                    for c in range(d):
                        mv = pos[b, i, c] - prev[b, i, c]
                        mm += mv * mv
                        wm += (circles[b, j, c] - prev[b, i, c]) * mv
                    t = wm / max(mm, 1e-300)
                    t = 0.0 if t < 0.0 else (1.0 if t > 1.0 else t)
                    dd = 0.0
                    for c in range(d):
                        mv = pos[b, i, c] - prev[b, i, c]
                        v = (circles[b, j, c] - prev[b, i, c]) - t * mv
                        dd += v * v
                    v = np.sqrt(dd) - circles[b, j, d]
                    cc = v if v < cc else cc
            cc -= radius
            if cc < dist[b, col]:
                dist[b, col] = cc
            if cc < 0.0:
                hit[b] = True


#: Fewest env rows a thread of ``run_rows`` gets: below it, handing work to a thread costs more than it saves.
MIN_ROWS_PER_THREAD = 128
_POOL: dict[str, Any] = {"pid": -1, "pool": None, "size": 0}
_POOL_LOCK = threading.Lock()


def default_threads() -> int:
    """The CPUs this process may run on (at most 8): the default ``num_threads`` of the batched step."""
    try:
        cpus = len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        cpus = os.cpu_count() or 1
    return max(1, min(8, cpus))


def _pool(workers: int) -> ThreadPoolExecutor:
    """This process's worker threads (made again after a fork, where the parent's threads do not exist)."""
    with _POOL_LOCK:
        if _POOL["pid"] != os.getpid() or _POOL["size"] < workers:
            _POOL.update(pid=os.getpid(), size=workers, pool=ThreadPoolExecutor(workers, "formation-env-step"))
        return _POOL["pool"]


@njit(cache=True, nogil=True, parallel=True)
def _linear_rows_par(B: int, nt: int, *args: Any) -> None:
    """``linear_rows`` over [0, B) in ``nt`` chunks on numba's native threads."""
    for t in prange(nt):
        linear_rows(B * t // nt, B * (t + 1) // nt, *args)


@njit(cache=True, nogil=True, parallel=True)
def _measure_rows_par(B: int, nt: int, *args: Any) -> None:
    """``measure_rows`` over [0, B) in ``nt`` chunks on numba's native threads."""
    for t in prange(nt):
        measure_rows(B * t // nt, B * (t + 1) // nt, *args)


@njit(cache=True, nogil=True, parallel=True)
def _step_rows_par(B: int, nt: int, linear: tuple[np.ndarray, ...], *measure: Any) -> None:
    """``step_rows`` over [0, B) in ``nt`` chunks on numba's native threads."""
    for t in prange(nt):
        step_rows(B * t // nt, B * (t + 1) // nt, linear, *measure)


@njit(cache=True, nogil=True, parallel=True)
def _step_end_rows_par(
    B: int, nt: int, linear: tuple[Any, ...], measure: tuple[Any, ...], swept: tuple[Any, ...], end: tuple[Any, ...]
) -> None:
    """``step_end_rows`` over [0, B) in ``nt`` chunks on numba's native threads."""
    for t in prange(nt):
        step_end_rows(B * t // nt, B * (t + 1) // nt, linear, measure, swept, end)


@njit(cache=True, nogil=True, parallel=True)
def _launch(out: np.ndarray) -> None:
    """Starts numba's threading layer (so that ``numba.threading_layer()`` names it)."""
    for t in prange(out.shape[0]):
        out[t] = t


#: The ``*_rows`` kernels' twins on numba's native threads (``run_rows`` prefers them, see ``native_threads``).
_PARALLEL: dict[Any, Any] = {
    linear_rows: _linear_rows_par,
    measure_rows: _measure_rows_par,
    step_rows: _step_rows_par,
    step_end_rows: _step_end_rows_par,
}
#: ``FORMATION_ENV_NATIVE_THREADS=0`` keeps ``run_rows`` on the Python worker threads.
NATIVE_THREADS = os.environ.get("FORMATION_ENV_NATIVE_THREADS", "1") != "0"
_NATIVE: dict[str, Any] = {"pid": -1, "ok": False}


def native_threads() -> bool:
    """Whether ``run_rows`` splits its kernels over numba's native threads (``prange``) in this process.

    They start in tens of microseconds, where a Python worker thread must first take the GIL (a few hundred at
    B = 1024 on a 2-core VM), so the split pays off. Used with a threading layer that is safe from several
    Python threads at once ("omp", "tbb"; not "workqueue"), and never in a process forked after this one
    launched them: GNU OpenMP is not fork-safe, so a forked child uses the Python worker threads."""
    pid = os.getpid()
    if _NATIVE["pid"] == pid:
        return bool(_NATIVE["ok"])
    if not (AVAILABLE and NATIVE_THREADS):
        return False
    with _POOL_LOCK:
        if _NATIVE["pid"] == -1:
            layer = None
            try:
                _launch(np.zeros(2))
                layer = numba.threading_layer()
            except Exception:  # pragma: no cover - no threading layer could start: the Python threads serve
                pass
            _NATIVE.update(pid=pid, ok=layer in ("omp", "tbb"))
        elif _NATIVE["pid"] != pid:  # forked from the process that launched them
            return False
        return bool(_NATIVE["ok"])


def run_rows(fn: Any, B: int, threads: int, *args: Any) -> None:
    """``fn(b0, b1, *args)`` over the env rows [0, B) in up to ``threads`` contiguous chunks at once.

    ``fn`` is one of the ``*_rows`` kernels: compiled with the GIL released, and writing only its own rows,
    so the result is the same for any number of threads. Chunks have at least ``MIN_ROWS_PER_THREAD`` rows.
    The chunks of the compiled kernels go on numba's native threads where ``native_threads()``; else (and for
    any other ``fn``) on Python worker threads, this thread running the first one. An error in a chunk is
    raised once every chunk has stopped.
    """
    nt = max(1, min(int(threads), B // MIN_ROWS_PER_THREAD))
    if nt == 1:
        fn(0, B, *args)
        return
    par = _PARALLEL.get(fn)
    if par is not None and native_threads():
        par(B, nt, *args)
        return
    cuts = [B * t // nt for t in range(nt + 1)]
    futures = [_pool(nt - 1).submit(fn, cuts[t], cuts[t + 1], *args) for t in range(1, nt)]
    try:
        fn(0, cuts[1], *args)
    finally:
        for f in futures:
            f.exception()  # wait: no chunk may still write when the caller goes on (or sees an error)
    for f in futures:
        f.result()


@njit(cache=True, inline="always")
def _global_row(
    ps: np.ndarray,
    p0: int,
    vs: np.ndarray,
    v0: int,
    rs: np.ndarray,
    r0: int,
    err: float,
    theta_map: np.ndarray,
    pvec: np.ndarray,
    t: float,
    lo: np.ndarray,
    hi: np.ndarray,
    out: np.ndarray,
) -> None:
    """One env's global state into ``out`` (state_dim,) float32: positions ``ps[p0:p0 + n d]``, velocities
    ``vs[v0:v0 + n d]``, goal and its velocity ``rs[r0:r0 + 2 n d]``, ``err``, Theta (row-major) from the
    positions by ``theta_map`` (n d, d d), ``pvec`` (kp,), time fraction ``t``; each clipped to [lo, hi] in float64."""
    nd = theta_map.shape[0]
    j = 0
    for i in range(nd):
        out[j] = min(max(ps[p0 + i], lo[j]), hi[j])
        j += 1
    for i in range(nd):
        out[j] = min(max(vs[v0 + i], lo[j]), hi[j])
        j += 1
    for i in range(2 * nd):
        out[j] = min(max(rs[r0 + i], lo[j]), hi[j])
        j += 1
    out[j] = min(max(err, lo[j]), hi[j])
    j += 1
    for c in range(theta_map.shape[1]):
        acc = 0.0
        for i in range(nd):
            acc += ps[p0 + i] * theta_map[i, c]
        out[j] = min(max(acc, lo[j]), hi[j])
        j += 1
    for i in range(pvec.shape[0]):
        out[j] = min(max(pvec[i], lo[j]), hi[j])
        j += 1
    out[j] = min(max(t, lo[j]), hi[j])


@njit(cache=True)
def global_state(
    pos: np.ndarray,
    vel: np.ndarray,
    ref: np.ndarray,
    err: np.ndarray,
    theta_map: np.ndarray,
    pvec: np.ndarray,
    k: np.ndarray,
    inv_cycles: float,
    lo: np.ndarray,
    hi: np.ndarray,
) -> np.ndarray:
    """``Engine.global_state``: [pos, vel, goal, goal velocity, err, Theta, scenario parameters, k / max_cycles]
    per env, clipped to [lo, hi] in float64, as float32 (B, state_dim). pos, vel (B, n d); ref (B, 2 n d + 2);
    err (B,); theta_map (n d, d d): Theta (row-major) from pos; pvec (B, kp); k (B,)."""
    B = pos.shape[0]
    out = np.empty((B, lo.shape[0]), dtype=np.float32)
    for b in range(B):
        _global_row(pos[b], 0, vel[b], 0, ref[b], 0, err[b], theta_map, pvec[b], k[b] * inv_cycles, lo, hi, out[b])
    return out


@njit(cache=True)
def copy_rows(dst: tuple[np.ndarray, ...], idx: np.ndarray, src: tuple[np.ndarray, ...], src_idx: np.ndarray) -> None:
    """``dst[t][idx[i]] = src[t][src_idx[i]]`` for every array t and row i: one call in place of a fancy copy per
    array (~4 us each, even for a few rows). dst, src: tuples of (B, row bytes) uint8 views, row sizes equal
    pairwise; idx, src_idx: (m,) int64."""
    for t in range(len(dst)):
        d, s = dst[t], src[t]
        nb = d.shape[1]
        for i in range(idx.shape[0]):
            di, si = idx[i], src_idx[i]
            for j in range(nb):  # a loop, not a slice copy (each slice made a view): rows of tens of bytes
                d[di, j] = s[si, j]


@njit(cache=True, error_model="numpy")
def _move_and_test(
    out: np.ndarray,
    base: np.ndarray,
    b: int,
    dirs: np.ndarray,
    rad: np.ndarray,
    followers: np.ndarray,
    gap: float,
    trial: np.ndarray,
) -> bool:
    """One episode of ``noisy_starts``: the followers of episode b moved from ``base[b]`` by ``dirs`` (n_f, d) (scaled
    to unit length) times ``rad`` (n_f,) into ``trial`` (n, d), then the all-pairs test; ``out[b]`` gets them if it
    passes."""
    n, d, nf = base.shape[1], base.shape[2], followers.shape[0]
    trial[:] = base[b]
    for k in range(nf):
        acc = 0.0
        for c in range(d):
            acc += dirs[k, c] * dirs[k, c]
        norm = np.sqrt(acc)
        i = followers[k]
        for c in range(d):
            trial[i, c] += dirs[k, c] / norm * rad[k]
    least = np.inf
    for i in range(n):
        for j in range(i + 1, n):
            acc = 0.0
            for c in range(d):
                v = trial[i, c] - trial[j, c]
                acc += v * v
            if acc < least or acc != acc:  # a NaN stays, as in numpy's min
                least = acc
    ok = np.sqrt(least) >= gap
    if ok:
        out[b] = trial
    return ok


@njit(cache=True, error_model="numpy")
def noisy_starts(
    out: np.ndarray,
    base: np.ndarray,
    todo: np.ndarray,
    dirs: np.ndarray,
    rad: np.ndarray,
    followers: np.ndarray,
    gap: float,
) -> np.ndarray:
    """``Scenario._noisy`` per episode: every follower of episode ``todo[i]`` moved from ``base`` along its direction
    draw (scaled to unit length) by its radius, then the all-pairs test; positions that pass go into ``out``. The
    same operations in the same order as the numpy code (the verdict decides whether a generator draws again, so
    it must agree exactly; tests compare the two); a zero division gives inf or NaN, as in numpy.

    Args:
        out: start positions (B, n, d), m, written in place for the episodes that pass.
        base: positions on the start pose, shape (B, n, d), m.
        todo: the episodes to move, shape (m,) int64.
        dirs: their followers' standard normal direction draws, shape (m, n_f, d).
        rad: their followers' displacement lengths, shape (m, n_f), m.
        followers: the followers' agent indices, shape (n_f,).
        gap: smallest allowed distance between two agents (m).
    Returns:
        ok (m,): no two agents of episode ``todo[i]`` closer than ``gap`` (a NaN distance fails).
    """
    m = todo.shape[0]
    trial = np.empty((base.shape[1], base.shape[2]))
    ok = np.empty(m, dtype=np.bool_)
    for e in range(m):
        ok[e] = _move_and_test(out, base, todo[e], dirs[e], rad[e], followers, gap, trial)
    return ok


# ------------------------------------------------------------------ draws from numpy's bit generators
_BITGEN_FNS: dict[type, np.ndarray] = {}


def bit_generators(rngs: list[np.random.Generator]) -> tuple[np.ndarray, np.ndarray] | None:
    """(state addresses (m,) int64, [next_uint64, next_double] addresses (2,) int64) of the generators' bit
    generators, for ``draw_runs`` and ``settle_starts``; None without the compiled draws or when the bit generators
    are of more than one kind. The caller keeps the generators alive and uses none of them elsewhere meanwhile."""
    if not (AVAILABLE and DRAWS) or not rngs:
        return None
    kind = type(rngs[0].bit_generator)
    fns = _BITGEN_FNS.get(kind)
    if fns is None:
        import ctypes

        c = rngs[0].bit_generator.ctypes
        fns = np.array([ctypes.cast(f, ctypes.c_void_p).value for f in (c.next_uint64, c.next_double)], np.int64)
        _BITGEN_FNS[kind] = fns
    addr = np.empty(len(rngs), dtype=np.int64)
    for i, g in enumerate(rngs):
        bg = g.bit_generator
        if type(bg) is not kind:
            return None
        addr[i] = bg.ctypes.state_address
    return addr, fns


if DRAWS:

    def _bitgen_call(ret: Any, ret_ir: Any) -> Any:
        """An intrinsic ``call(fn, state)``: the C function at address fn (``ret (*)(void *)``, a bit generator's
        ``next_uint64`` or ``next_double``) on the state at address state (both int64)."""

        @intrinsic
        def call(typingctx: Any, fn: Any, state: Any) -> Any:
            if not (isinstance(fn, types.Integer) and isinstance(state, types.Integer)):
                return None

            def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
                vp = ir.IntType(8).as_pointer()
                f = builder.inttoptr(args[0], ir.FunctionType(ret_ir, [vp]).as_pointer())
                return builder.call(f, [builder.inttoptr(args[1], vp)])

            return ret(fn, state), codegen

        return call

    _next_uint64 = _bitgen_call(types.uint64, ir.IntType(64))
    _next_double = _bitgen_call(types.float64, ir.DoubleType())

    @njit(cache=True)
    def _standard_normal(fns: np.ndarray, state: int) -> float:
        """numpy's ``random_standard_normal`` (the ziggurat of ``Generator.standard_normal``, its tables as numba
        keeps them), on the bit generator at ``state``."""
        while True:
            r = _next_uint64(fns[0], state)
            idx = r & np.uint64(0xFF)
            r >>= np.uint64(8)
            sign = r & np.uint64(1)
            rabs = (r >> np.uint64(1)) & np.uint64(0x000FFFFFFFFFFFFF)
            x = float(rabs) * wi_double[idx]
            if sign:
                x = -x
            if rabs < ki_double[idx]:
                return x
            if idx == 0:
                while True:
                    xx = -ziggurat_nor_inv_r * np.log1p(-_next_double(fns[1], state))
                    yy = -np.log1p(-_next_double(fns[1], state))
                    if yy + yy > xx * xx:
                        return -(ziggurat_nor_r + xx) if (rabs >> np.uint64(8)) & np.uint64(1) else ziggurat_nor_r + xx
            elif (fi_double[idx - 1] - fi_double[idx]) * _next_double(fns[1], state) + fi_double[idx] < np.exp(
                -0.5 * x * x
            ):
                return x

    @njit(cache=True)
    def _fill(row: np.ndarray, kind: int, fns: np.ndarray, state: int) -> None:
        """``Generator.random(out=row)`` (kind 0) or ``Generator.standard_normal(out=row)`` (kind 1)."""
        if kind == 0:
            for j in range(row.shape[0]):
                row[j] = _next_double(fns[1], state)
        else:
            for j in range(row.shape[0]):
                row[j] = _standard_normal(fns, state)

    @njit(cache=True)
    def draw_runs(raw: np.ndarray, addr: np.ndarray, fns: np.ndarray, runs: np.ndarray) -> None:
        """``DrawPlan.draw_each`` compiled: for each generator b in turn, its runs of same-kind draws into its row
        of ``raw`` (B, K); ``runs`` (r, 3) int64 rows [kind (0 uniform, 1 normal), start, stop]. The same numbers
        as numpy's calls (tests)."""
        for b in range(raw.shape[0]):
            for t in range(runs.shape[0]):
                _fill(raw[b, runs[t, 1] : runs[t, 2]], runs[t, 0], fns, addr[b])

    @njit(cache=True, error_model="numpy")
    def settle_starts(
        out: np.ndarray,
        base: np.ndarray,
        dirs: np.ndarray,
        u: np.ndarray,
        followers: np.ndarray,
        gap: float,
        noise: float,
        inv_d: float,
        tries: int,
        addr: np.ndarray,
        fns: np.ndarray,
    ) -> None:
        """``Scenario._settle`` with ``noisy_starts``, compiled, episode by episode: the followers of episode b moved
        by its draws ``dirs[b]`` (n_f, d) and ``u[b]`` (n_f,) (radius ``noise`` u^inv_d m); while two agents are
        closer than ``gap``, new draws from generator b (standard normal directions, then uniform u, as
        ``_noise_plan``), ``tries`` draws in all. ``out`` (B, n, d), a copy of ``base``, gets the positions that
        pass (the others keep ``base``). u^(1/2) is a square root, as numpy's ``u ** 0.5``."""
        nf, d = dirs.shape[1], dirs.shape[2]
        dr, uu, rad = np.empty((nf, d)), np.empty(nf), np.empty(nf)
        trial = np.empty((base.shape[1], d))
        for b in range(base.shape[0]):
            dr[:] = dirs[b]
            uu[:] = u[b]
            for t in range(max(tries, 1)):
                if t > 0:
                    _fill(dr.reshape(-1), 1, fns, addr[b])
                    _fill(uu, 0, fns, addr[b])
                for k in range(nf):
                    rad[k] = noise * (np.sqrt(uu[k]) if inv_d == 0.5 else uu[k] ** inv_d)
                if _move_and_test(out, base, b, dr, rad, followers, gap, trial):
                    break


@njit(cache=True, error_model="numpy")
def wall_maps(seg: np.ndarray, dirs: np.ndarray, sensor_range: float) -> tuple[np.ndarray, np.ndarray]:
    """``Engine._wall_maps`` per episode: the 2D wall and ray maps of ``_episode_geometry``, the same operations in
    the same order as the numpy code (tests compare the two); a zero division (a wall of zero length) gives inf or
    NaN, as in numpy.

    Args:
        seg: wall segments (start, end), shape (B, S, 2, 2), m.
        dirs: unit ray directions, shape (R, 2).
        sensor_range: ray length (m).
    Returns:
        W (B, 3, 3 S): [p, 1] -> [across, along - length, -along] per wall; Rm (B, 2, S R): per wall and ray,
        G = 1 / (u . n) / sensor range and U = (u . t) / (u . n) (u: the ray's direction; n, t: the wall's normal
        and direction), both 0 for a ray parallel to the wall. A leader at p with across a = n . p - a_n sees
        the wall's line at T = -a G sensor ranges, at along + (-a) U along the wall (inside it from 0 to its
        length; see ``measure_rows``).
    """
    B, S = seg.shape[0], seg.shape[1]
    R = dirs.shape[0]
    W = np.zeros((B, 3, 3 * S))
    Rm = np.empty((B, 2, S * R))
    for b in range(B):
        for s in range(S):
            a0, a1 = seg[b, s, 0, 0], seg[b, s, 0, 1]
            e0, e1 = seg[b, s, 1, 0] - a0, seg[b, s, 1, 1] - a1
            length = np.sqrt(e0 * e0 + e1 * e1)
            lm = max(length, 1e-300)
            t0, t1 = e0 / lm, e1 / lm
            n0, n1 = -t1, t0
            a_t, a_n = a0 * t0 + a1 * t1, a0 * n0 + a1 * n1
            W[b, 0, s], W[b, 1, s], W[b, 2, s] = n0, n1, -a_n
            W[b, 0, S + s], W[b, 1, S + s], W[b, 2, S + s] = t0, t1, -a_t - length
            W[b, 0, 2 * S + s], W[b, 1, 2 * S + s], W[b, 2, 2 * S + s] = -t0, -t1, a_t
            for r in range(R):
                un = dirs[r, 0] * n0 + dirs[r, 1] * n1
                ut = dirs[r, 0] * t0 + dirs[r, 1] * t1
                inv = 1.0 / un if abs(un) > 1e-9 else 0.0
                Rm[b, 0, s * R + r] = inv / sensor_range
                Rm[b, 1, s * R + r] = ut * inv
    return W, Rm
