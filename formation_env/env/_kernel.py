"""The single-env (B = 1) step's nonlinear part as one compiled function (numba), for ``Engine.step1``.

At B = 1 and n = 5 a numpy step is ~35 calls of ~1-2 us each, so the call overhead, not the
arithmetic, is the cost. ``step1`` does the whole step in one call: the two matmuls, wall
excess, feature norms, contact clearance, success test, world-box guard, 2D ray sensing of
walls, observation assembly (clipped, float32) and the reward's linear part. It computes exactly
what the batched numpy step (``Engine.step``) computes, which stays the reference: tests compare
the two on every scenario. Without numba (``AVAILABLE`` False) ``step1`` takes the batched step.

Compiled on first use and cached on disk (``cache=True``), so later processes start at once.
"""

from __future__ import annotations

from typing import Any

import numpy as np

try:  # numba is a dependency; the env still works (slower at B = 1) without it
    from numba import njit

    AVAILABLE = True
except ImportError:  # pragma: no cover - exercised only where numba is missing
    AVAILABLE = False

    def njit(*args: Any, **kwargs: Any) -> Any:  # type: ignore[no-redef]
        return lambda f: f


__all__ = ["AVAILABLE", "LAYOUT", "SENSE_CONST", "SENSE_GIVEN", "SENSE_WALLS", "step1"]

#: How ``step1`` gets the leaders' obstacle sensing: a constant, the given array, or 2D rays on walls.
SENSE_CONST, SENSE_GIVEN, SENSE_WALLS = 0, 1, 2
#: Names of the int64 layout vector ``step1`` takes (offsets into ``out`` and ``g``, sizes).
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
    "q1",  # g[:q1]: features Q (d per row); g[q1:q1 + 3 n S]: (along - length, -along, 0) per agent and wall
    "walls0",  # index in Q of the first wall row's excess component
    "sense_mode",
)


@njit(cache=True)
def step1(
    x: np.ndarray,
    a: np.ndarray,
    mem: np.ndarray,
    ref: np.ndarray,
    M: np.ndarray,
    M1: np.ndarray,
    thr: np.ndarray,
    rays: np.ndarray,
    sense_in: np.ndarray,
    gprev: np.ndarray,
    w_tail: np.ndarray,
    lin_lo: np.ndarray,
    lin_hi: np.ndarray,
    err_hi: float,
    lay: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One B = 1 step after the checks: z = [x, clip(a), mem, ref], out = z M, g = z M1, then the rest.

    Args:
        x (n q,), a (n_l p,) raw actions, mem (n_f p,) or empty, ref (2 n d + 2,): the state and inputs.
        M: the folded step (Z, C) (see ``Engine._build_static``); M1: the episode's feature map (Z, C1)
            (see ``Engine._fold_episode``).
        thr: contact / goal / formation thresholds (Kc + n + 1,), m.
        rays: per-episode ray map (d + 1, 2 S R): a leader's [p, 1] -> (T, AH) per wall and ray.
        sense_in: the sensing when ``sense_mode`` is SENSE_CONST or SENSE_GIVEN, shape (n_l, ks).
        gprev: the leaders' goal distances before the step (n_l,), m.
        w_tail: the reward map's rows for [a^2 (n_l p), gprev, goal distances after], shape (., 2 n_l).
        lin_lo, lin_hi: bounds of the linear observation entries, shape (n_l L1,).
        err_hi: bound of the formation-error entry (m).
        lay: int64 layout, the fields ``LAYOUT``.
    Returns:
        out (C,) = z M; obs (n_l, obs_dim) float32; nv (Kc + n + 1,): contact distances, goal distances
        (leaders first), formation error; rew (2 n_l,): the reward's and the effort's part linear in
        [a^2, gprev, goal distances]; scalars [min clearance, max of (nv - thr)[Kc:], min guard margin,
        bad action flag]. On an action holding NaN or inf the flag is 1 and the arrays are empty.
    """
    na = a.shape[0]
    for i in range(na):
        if not np.isfinite(a[i]):
            return np.empty(0), np.empty((0, 0), dtype=np.float32), np.empty(0), np.empty(0), np.array([0.0, 0, 0, 1])
    nx, nm = x.shape[0], mem.shape[0]
    z = np.empty(nx + na + nm + ref.shape[0])
    z[:nx] = x
    af = np.empty(na)
    for i in range(na):
        v = a[i]
        af[i] = -1.0 if v < -1.0 else (1.0 if v > 1.0 else v)
    z[nx : nx + na] = af
    z[nx + na : nx + na + nm] = mem
    z[nx + na + nm :] = ref
    out = np.dot(z, M)
    g = np.dot(z, M1)
    kc, kd, d, nl, S, R = lay[0], lay[1], lay[2], lay[3], lay[4], lay[5]
    L1, od, guard0, guard1, obs0, laug0 = lay[6], lay[7], lay[8], lay[9], lay[10], lay[11]
    q1, walls0, mode = lay[12], lay[13], lay[14]
    ns = (g.shape[0] - q1) // 3
    for i in range(ns):  # excess along the wall: max(along - length, -along, 0)
        e = g[q1 + i]
        b = g[q1 + ns + i]
        if b > e:
            e = b
        if e < 0.0:
            e = 0.0
        g[walls0 + d * i] = e
    nrow = thr.shape[0]
    nv = np.empty(nrow)
    for r in range(kd):
        acc = 0.0
        for c in range(d):
            v = g[r * d + c]
            acc += v * v
        nv[r] = np.sqrt(acc)
    acc = 0.0
    for j in range(kd * d, q1):
        acc += g[j] * g[j]
    nv[nrow - 1] = np.sqrt(acc)
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
    err = nv[nrow - 1]
    obs = np.empty((nl, od), dtype=np.float32)
    for li in range(nl):
        for j in range(L1):
            v = out[obs0 + li * L1 + j]
            lo = lin_lo[li * L1 + j]
            hi = lin_hi[li * L1 + j]
            if v < lo:
                v = lo
            if v > hi:
                v = hi
            obs[li, j] = v
        obs[li, L1] = err if err < err_hi else err_hi
        if mode == 2:  # 2D rays: T / sensor range of the first hit inside a wall, else 1
            sr = S * R
            for r in range(R):
                best = 1.0
                for s in range(S):
                    t = rays[d, s * R + r]
                    h = rays[d, sr + s * R + r]
                    for c in range(d):
                        p = out[laug0 + li * (d + 1) + c]
                        t += p * rays[c, s * R + r]
                        h += p * rays[c, sr + s * R + r]
                    if t >= 0.0 and abs(h) <= 1.0 and t < best:
                        best = t
                obs[li, L1 + 1 + r] = best
        else:
            for j in range(od - L1 - 1):
                obs[li, L1 + 1 + j] = sense_in[li, j]
    feats = np.empty(na + 2 * nl)
    for i in range(na):
        feats[i] = af[i] * af[i]
    for li in range(nl):
        feats[na + li] = gprev[li]
        feats[na + nl + li] = nv[kc + li]
    nf = feats.shape[0]
    rew = np.zeros(w_tail.shape[1])
    for i in range(nf):
        f = feats[i]
        if f != 0.0:
            for j in range(w_tail.shape[1]):
                rew[j] += f * w_tail[i, j]
    return out, obs, nv, rew, np.array([clear, worst, gmin, 0.0])
