"""Stress-matrix design: a PSD equilibrium stress of rank n - d - 1 for a given framework.

The paper takes Omega as given (Section 2.4: "the design of stress matrix is
outside the scope"). :func:`design_stress` computes one by three methods:

``"sdp"``
    The standard semidefinite programme. Equilibrium stresses are w = B c with
    B an orthonormal basis of the stress space (eq. 1, :func:`equilibrium_stress_basis`),
    so Omega(c) r = 0 and Omega(c) 1 = 0 hold exactly. With Q an orthonormal basis
    of the orthogonal complement of span([r, 1]) (dimension p = n - d - 1), the
    SDP maximises t subject to Q^T Omega(c) Q >= t I and trace(Q^T Omega(c) Q) = p.
    t > 0 certifies a PSD stress of rank n - d - 1 (Lemma 1); the optimum t <= 0
    proves that the framework has none (for generic positions: it is not
    universally rigid).
``"min_cond"`` (alias ``"fast"``)
    The stress with the fastest sampled-data law: the error of eq. (17) decays as
    rho(I - T Omega_ff)^k, and the best rho over T is (kappa - 1) / (kappa + 1) with
    kappa = cond(Omega_ff), at T = 2 / (lambda_min + lambda_max). The SDP minimises s
    subject to I <= Omega_ff(c) <= s I. With exactly d + 1 leaders spanning R^d,
    Omega_ff > 0 and Omega [r, 1] = 0 already imply Omega >= 0 with rank n - d - 1
    (the leaders' Schur complement S satisfies S [r_l, 1] = 0 with [r_l, 1]
    invertible, so S = 0). With more leaders the constraint
    Q^T Omega(c) Q >= 1e-4 s I is added.
``"constructive"``
    No solver, fully sparse, for trilateration frameworks: every agent j > d joins
    d + 1 earlier agents that with j form a clique K_{d+2}. The d + 2 points of a
    clique in general position carry a one-dimensional space of equilibrium
    stresses with stress matrix a a^T, a spanning the null space of
    [[p_1 .. p_{d+2}], [1 .. 1]] ((d + 1) x (d + 2)). a is nonzero at the clique's
    newest agent j (its d + 1 partners are affinely independent), so each clique
    adds one to the rank and the sum is PSD with rank n - d - 1. One batched SVD
    and one COO assembly: n = 10,000 in 2D in about 0.15 s, check included.

Every result is checked with :func:`check_stress` before it is returned and is
scaled so that the largest eigenvalue of Omega_ff is 1: the stationary-leader law
(Theorem 1, T mu_min > -2) is then stable for every T in (0, 2).

Solvers. Clarabel at its default settings stops at the first iteration with
``NumericalError`` on the trace-normalised SDP; a static regularisation of 1e-7
fixes it (:data:`SOLVER_SETTINGS`). Its chordal decomposition is switched off:
on the sparse Omega_ff LMIs of trilateration frameworks its clique-graph merge
either panicked (index out of bounds) or looped with memory growing past 8 GB.
With these settings Clarabel solved all of about 500 random kNN and trilateration
frameworks (2D and 3D, n <= 40) tried while writing this. SCS is the fallback, with tight tolerances and
an iteration cap; at n = 100 it can stop "optimal" with a negative eigenvalue, so
every answer is verified here and, if it fails, polished (eigenvalues clipped in
the stress space, then projected back, a few dozen rounds) before the next solver
is tried. Clarabel's interior-point step factors a dense matrix of side
p (p + 1) / 2, so the SDP's cost grows like n^6: on 2 cores, random 8-nearest-
neighbour frameworks in 2D take 0.05 s / 0.7 s / 5 s / 45 s ("sdp") and
0.1 s / 2 s / 18 s / 130 s ("min_cond", two LMIs of side n_f) at n = 20 / 40 /
60 / 100; above n = 80 a warning says so.
"""

from __future__ import annotations

import itertools
import logging
import warnings
from typing import Any

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import ArrayLike, NDArray

from .errors import ControlDimension, FrameworkError, StressMatrixError
from .framework import Framework, check_framework
from .stress import DEFAULT_RTOL, Partition, StressLike, check_stress, equilibrium_stress_basis, stress_from_weights
from .validation import check_bool, check_rtol

__all__ = [
    "METHODS",
    "SOLVER_SETTINGS",
    "clique_stress",
    "condition_number",
    "design_stress",
    "trilateration_cliques",
]

_log = logging.getLogger(__name__)

#: Design methods; "fast" is an alias of "min_cond".
METHODS: tuple[str, ...] = ("sdp", "min_cond", "constructive")
_ALIASES = {"fast": "min_cond"}

#: cvxpy solvers tried in order when ``solver=None``, with the settings that made them robust here.
SOLVER_SETTINGS: dict[str, dict[str, Any]] = {
    "CLARABEL": {"static_regularization_constant": 1e-7, "chordal_decomposition_enable": False, "max_iter": 300},
    "SCS": {"eps_abs": 1e-9, "eps_rel": 1e-9, "max_iters": 10_000},
}

#: Above this many agents the SDP methods warn that they are slow.
_SLOW_SDP_N = 80

#: Above this many followers, sparse spectra use ARPACK instead of a dense eigendecomposition.
_DENSE_EIG_LIMIT = 300


def design_stress(
    fw: Framework,
    method: str = "sdp",
    *,
    rtol: float = DEFAULT_RTOL,
    solver: str | None = None,
    sparse: bool | None = None,
    cliques: ArrayLike | None = None,
    verbose: bool = False,
) -> NDArray[np.float64] | sp.csr_matrix:
    """A PSD equilibrium stress of ``fw`` with rank n - d - 1, checked and scaled to lambda_max(Omega_ff) = 1.

    Parameters
    ----------
    fw
        The framework (G, r) with its leaders, n agents in R^d.
    method
        ``"sdp"`` (max-min eigenvalue), ``"min_cond"`` or its alias ``"fast"`` (minimum
        cond(Omega_ff)), or ``"constructive"`` (trilateration frameworks, no solver);
        see the module docstring.
    rtol
        Relative tolerance of the final :func:`check_stress`.
    solver
        cvxpy solver for the SDP methods (e.g. ``"CLARABEL"``, ``"SCS"``); None tries
        those of :data:`SOLVER_SETTINGS` in order. Not used by "constructive".
    sparse
        Return a ``scipy.sparse.csr_matrix`` (True) or a dense array (False); None
        gives dense for the SDP methods and sparse for "constructive".
    cliques
        "constructive" only: the cliques, shape (n - d - 1, d + 2), the last agent of
        each being the one it adds. None takes ``fw.cliques`` if the framework carries
        them (``trilateration(..., n_leaders=k)``), else finds them in index order
        (:func:`trilateration_cliques`).
    verbose
        Print the solver's log.

    Returns
    -------
    omega
        Stress matrix, shape (n, n), dense or CSR.

    Raises
    ------
    StressMatrixError
        The framework has no PSD equilibrium stress of rank n - d - 1 (too few
        edges, an agent with fewer than d + 1 neighbours, or the SDP optimum
        t <= 0), or every solver's answer failed the check (the message lists why).
    FrameworkError
        "constructive" on a framework without a trilateration ordering.
    ValueError
        Unknown method or solver, or an argument the method does not use.
    """
    check_framework(fw)
    if not isinstance(method, str):
        raise TypeError(f"method must be a string, one of {[*METHODS, *_ALIASES]}; got {type(method).__name__}")
    rtol = check_rtol(rtol)
    sparse = None if sparse is None else check_bool(sparse, "sparse")
    verbose = check_bool(verbose, "verbose")
    name = _ALIASES.get(method, method)
    if name not in METHODS:
        raise ValueError(f"unknown method {method!r}; choose one of {[*METHODS, *_ALIASES]}")
    if name != "constructive":
        if cliques is not None:
            raise ValueError(f"cliques applies to method 'constructive' only, not to {method!r}")
        dense = _solve(fw, name, rtol, solver, verbose)  # verified by check_stress
        return sp.csr_matrix(dense) if sparse else dense
    if solver is not None:
        raise ValueError("solver applies to the SDP methods ('sdp', 'min_cond'), not to 'constructive'")
    omega = _constructive(fw, cliques)
    out = omega if sparse is None or sparse else omega.toarray()
    try:
        check_stress(out, fw, rtol=rtol)
    except StressMatrixError as exc:
        raise StressMatrixError(
            f"the constructive stress of {fw.name or 'the framework'} fails its check: {exc}"
        ) from exc
    return out


# ------------------------------------------------------------------------------------------- SDP methods
def _necessary_conditions(fw: Framework, basis: NDArray[np.float64]) -> None:
    """Raise ``StressMatrixError`` on the cheap necessary conditions of universal rigidity."""
    n, d = fw.n, fw.d
    deg = fw.degree()
    low = np.flatnonzero(deg < d + 1)
    if low.size:
        raise StressMatrixError(
            f"agent {low[0]} has {deg[low[0]]} neighbour(s), fewer than d + 1 = {d + 1}: a universally rigid "
            f"framework in R^{d} needs every agent joined to at least d + 1 others (the graph must be "
            f"(d + 1)-connected); add edges"
        )
    if basis.shape[1] == 0:
        m = len(fw.edges)
        raise StressMatrixError(
            f"the framework has no nonzero equilibrium stress ({m} edges; a generic framework in R^{d} needs "
            f"more than n d - d (d + 1) / 2 = {n * d - d * (d + 1) // 2}): it is not universally rigid; add edges"
        )


def _congruence(edges: NDArray[np.int64], basis: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:
    """V^T Omega_k V for every basis stress Omega_k (column k of ``basis``), shape (k, p, p) for V of shape (n, p)."""
    dv = v[edges[:, 0]] - v[edges[:, 1]]  # (m, p): Omega_k = sum_e B_ek (e_i - e_j)(e_i - e_j)^T
    m, p = dv.shape
    kr = (dv[:, :, None] * dv[:, None, :]).reshape(m, p * p)
    return (basis.T @ kr).reshape(-1, p, p)


def _solve(fw: Framework, method: str, rtol: float, solver: str | None, verbose: bool) -> NDArray[np.float64]:
    """Run the SDP ``method`` with each solver in turn; return the first verified, scaled stress."""
    from formation_env._extras import require

    cp: Any = require("cvxpy", "design", f"design_stress(method={method!r})")

    if solver is not None and solver not in cp.installed_solvers():
        raise ValueError(f"solver {solver!r} is not an installed cvxpy solver; installed: {cp.installed_solvers()}")
    basis = equilibrium_stress_basis(fw)
    _necessary_conditions(fw, basis)
    n, d, edges = fw.n, fw.d, fw.edge_array()
    if n > _SLOW_SDP_N:
        warnings.warn(
            f"design_stress({method!r}) with n = {n}: the SDP's cost grows like n^6 (about 45 s for 'sdp' and 130 s "
            f"for 'min_cond' at n = 100 on 2 cores); 'constructive' takes well under a second for trilateration "
            "frameworks",
            stacklevel=3,
        )
    q = sla.null_space(np.hstack([fw.positions, np.ones((n, 1))]).T)  # (n, p): complement of span([r, 1])
    gq = _congruence(edges, basis, q)  # Q^T Omega_k Q
    k, p = basis.shape[1], q.shape[1]
    c = cp.Variable(k)

    def lmi(g: NDArray[np.float64]) -> Any:
        size = g.shape[1]
        x = cp.reshape(g.reshape(k, size * size).T @ c, (size, size), order="F")
        return (x + x.T) / 2

    big_m = lmi(gq)
    if method == "sdp":
        t = cp.Variable()
        trace = np.trace(gq, axis1=1, axis2=2)
        problem = cp.Problem(cp.Maximize(t), [big_m >> t * np.eye(p), trace @ c == p])
    else:
        s = cp.Variable()
        sel = np.zeros((n, len(fw.followers)))
        sel[list(fw.followers), np.arange(len(fw.followers))] = 1.0
        ff = lmi(_congruence(edges, basis, sel))
        eye = np.eye(len(fw.followers))
        cons = [ff >> eye, ff << s * eye]
        if len(fw.leaders) > d + 1:
            cons.append(big_m >> 1e-4 * s * np.eye(p))
        problem = cp.Problem(cp.Minimize(s), cons)

    failures: list[str] = []
    for name in [solver] if solver is not None else list(SOLVER_SETTINGS):
        try:
            with warnings.catch_warnings():  # "solution may be inaccurate": every answer is verified below
                warnings.filterwarnings("ignore", message="Solution may be inaccurate", category=UserWarning)
                problem.solve(solver=name, verbose=verbose, **SOLVER_SETTINGS.get(name, {}))
        except cp.error.SolverError as exc:
            failures.append(f"{name}: solver error ({exc})")
            continue
        status = problem.status
        if status in (cp.INFEASIBLE, cp.INFEASIBLE_INACCURATE):
            raise StressMatrixError(
                f"no PSD equilibrium stress of rank n - d - 1 = {n - d - 1} exists ({name} reports the "
                f"{method!r} SDP {status}): the framework is not universally rigid (for generic positions); add edges"
            )
        if c.value is None:
            failures.append(f"{name}: status {status}, no solution")
            continue
        coef = np.asarray(c.value, dtype=np.float64)
        eig = np.linalg.eigvalsh(np.tensordot(coef, gq, axes=1))
        if method == "sdp" and status == cp.OPTIMAL and eig[0] <= rtol * eig[-1]:
            raise StressMatrixError(
                f"no PSD equilibrium stress of rank n - d - 1 = {n - d - 1} exists: the largest achievable "
                f"smallest eigenvalue of Q^T Omega Q is t = {eig[0]:.3g} (largest {eig[-1]:.3g}, {name} optimal), "
                "so the framework is not universally rigid (for generic positions); add edges"
            )
        omega, why = _scaled_and_checked(fw, basis @ coef, rtol)
        if omega is None:
            failures.append(f"{name} ({status}): {why}")
            polished = _polish(gq, coef, rtol)
            if polished is None:
                failures.append(f"{name}: polishing found no positive definite stress")
                continue
            omega, why = _scaled_and_checked(fw, basis @ polished, rtol)
            if omega is None:
                failures.append(f"{name} after polishing: {why}")
                continue
            warnings.warn(
                f"design_stress({method!r}): {name}'s answer failed its check and was polished; the stress is valid "
                "but not optimal",
                stacklevel=3,
            )
        if failures:
            _log.info("design_stress(%r) succeeded with %s after: %s", method, name, "; ".join(failures))
        return omega
    raise StressMatrixError(
        f"design_stress({method!r}) found no valid stress for {fw.name or 'the framework'} "
        f"(n = {n}, {len(edges)} edges, {k} independent stresses): " + "; ".join(failures)
    )


def _scaled_and_checked(fw: Framework, w: NDArray[np.float64], rtol: float) -> tuple[NDArray[np.float64] | None, str]:
    """The stress matrix of edge weights ``w`` scaled to lambda_max(Omega_ff) = 1, or None and why it fails."""
    omega = np.asarray(stress_from_weights(fw.n, fw.edges, w))
    ff_max = float(np.linalg.eigvalsh(Partition(omega, fw.leaders).omega_ff_dense)[-1])
    if ff_max <= 0:
        return None, f"Omega_ff has no positive eigenvalue (largest {ff_max:.3g})"
    omega = omega / ff_max
    try:
        check_stress(omega, fw, rtol=rtol)
    except StressMatrixError as exc:
        return None, str(exc)
    return omega, ""


def _polish(
    g: NDArray[np.float64], coef: NDArray[np.float64], rtol: float, rounds: int = 50
) -> NDArray[np.float64] | None:
    """Alternating projections to a c with sum_k c_k G_k positive definite, or None if none found.

    Clips the eigenvalues of M = sum_k c_k G_k at sqrt(rtol) * lambda_max (far above
    the rank tolerance of :func:`check_stress`) and projects the clipped matrix back
    onto span{G_k} by least squares; stops as soon as M is positive definite.
    """
    k, p, _ = g.shape
    qr_q, qr_r = np.linalg.qr(g.reshape(k, p * p).T)
    cc = coef
    for _ in range(rounds):
        lam, vec = np.linalg.eigh(np.tensordot(cc, g, axes=1))
        floor = np.sqrt(rtol) * lam[-1]
        if lam[-1] <= 0:
            return None
        if lam[0] >= floor / 2:
            return cc
        clipped = (vec * np.maximum(lam, floor)) @ vec.T
        cc = sla.solve_triangular(qr_r, qr_q.T @ clipped.ravel())
    return None


# ------------------------------------------------------------------------------------------- constructive
def trilateration_cliques(fw: Framework) -> NDArray[np.int64]:
    """The cliques of a trilateration ordering of ``fw`` in index order, shape (n - d - 1, d + 2).

    Row j - d - 1 lists d + 1 agents with smaller index than j that are pairwise
    joined and joined to j, then j itself (agents j = d + 1, ..., n - 1). Agents
    with exactly d + 1 earlier neighbours are handled in one vectorised pass;
    others are searched for a (d + 1)-clique among their earlier neighbours.

    Raises
    ------
    FrameworkError
        Some agent j > d has no d + 1 pairwise-joined earlier neighbours: the
        framework has no trilateration ordering in index order.
    """
    n, d = fw.n, fw.d
    e = fw.edge_array()
    order = np.lexsort((e[:, 0], e[:, 1]))
    lo, hi = e[order, 0], e[order, 1]  # edges grouped by their later agent
    count = np.bincount(hi, minlength=n)
    start = np.concatenate([[0], np.cumsum(count)])
    agents = np.arange(d + 1, n)
    hint = "constructive design needs a trilateration ordering (pass cliques=..., or use method 'sdp')"
    short = agents[count[agents] < d + 1]
    if short.size:
        j = int(short[0])
        raise FrameworkError(
            f"agent {j} has {count[j]} neighbour(s) with a smaller index, fewer than d + 1 = {d + 1}: {hint}"
        )
    keys = np.sort(e[:, 0] * n + e[:, 1])
    out = np.empty((agents.size, d + 2), dtype=np.int64)
    out[:, -1] = agents
    exact = agents[count[agents] == d + 1]
    nb = lo[start[exact][:, None] + np.arange(d + 1)]  # (J, d + 1), increasing along rows
    ok = np.ones(exact.size, dtype=bool)
    for a, b in itertools.combinations(range(d + 1), 2):
        ok &= np.isin(nb[:, a] * n + nb[:, b], keys)
    if not ok.all():
        j = int(exact[~ok][0])
        raise FrameworkError(f"the d + 1 earlier neighbours of agent {j} are not pairwise joined: {hint}")
    out[exact - d - 1, :-1] = nb
    edge_set = set(fw.edges)
    for j in agents[count[agents] > d + 1]:
        earlier = lo[start[j] : start[j + 1]].tolist()
        found = next(
            (
                c
                for c in itertools.combinations(earlier, d + 1)
                if all(pr in edge_set for pr in itertools.combinations(c, 2))
            ),
            None,
        )
        if found is None:
            raise FrameworkError(
                f"no d + 1 of the earlier neighbours {earlier} of agent {j} are pairwise joined: {hint}"
            )
        out[j - d - 1, :-1] = found
    return out


def clique_stress(positions: ArrayLike, cliques: ArrayLike, rtol: float = 1e-9) -> sp.csr_matrix:
    """Sum over cliques of the rank-one clique stresses a a^T, shape (n, n), CSR.

    For each clique of d + 2 agents, a (unit norm) spans the null space of
    [[p_1 .. p_{d+2}], [1 .. 1]], shape (d + 1, d + 2), so sum_i a_i = 0 and
    sum_i a_i p_i = 0. All null spaces come from one batched SVD and the matrix from
    one COO assembly, so n = 10,000 in 2D takes a few milliseconds.

    Parameters
    ----------
    positions
        Nominal positions r, shape (n, d).
    cliques
        Agent indices, shape (N, d + 2); the last agent of each clique is the one it
        adds (its entry of a must be nonzero for the rank to grow).
    rtol
        A clique is degenerate when its (d + 1)-th singular value, or |a| at its last
        agent, is at most ``rtol`` times its scale.

    Raises
    ------
    ControlDimension
        ``cliques`` is not an integer array of shape (N, d + 2).
    FrameworkError
        ``cliques`` refers to agents outside 0..n - 1.
    StressMatrixError
        A clique is not in general position.
    """
    r = np.asarray(positions, dtype=np.float64)
    cl = np.asarray(cliques)
    n, d = r.shape
    if cl.ndim != 2 or cl.shape[1] != d + 2 or not np.issubdtype(cl.dtype, np.integer):
        raise ControlDimension(f"cliques must be integers of shape (N, d + 2 = {d + 2}), got {cl.dtype} {cl.shape}")
    if cl.size and (cl.min() < 0 or cl.max() >= n):
        raise FrameworkError(f"cliques refer to agents outside 0..{n - 1}")
    pts = r[cl]  # (N, d + 2, d)
    h = np.concatenate([pts.transpose(0, 2, 1), np.ones((cl.shape[0], 1, d + 2))], axis=1)
    _, sv, vt = np.linalg.svd(h)  # sv (N, d + 1), vt (N, d + 2, d + 2)
    a = vt[:, -1, :]
    bad = np.flatnonzero((sv[:, -1] <= rtol * sv[:, 0]) | (np.abs(a[:, -1]) <= rtol))
    if bad.size:
        raise StressMatrixError(
            f"clique {cl[bad[0]].tolist()} is not in general position in R^{d}: its last agent's d + 1 partners are "
            "affinely dependent, so its stress adds no rank"
        )
    m = d + 2
    rows = np.repeat(cl, m, axis=1).ravel()
    cols = np.tile(cl, (1, m)).ravel()
    vals = (a[:, :, None] * a[:, None, :]).ravel()
    return sp.coo_matrix((vals, (rows, cols)), shape=(n, n)).tocsr()


def _constructive(fw: Framework, cliques: ArrayLike | None) -> sp.csr_matrix:
    if cliques is None and fw.cliques is not None:
        cliques = fw.cliques
    cl = trilateration_cliques(fw) if cliques is None else cliques
    omega = clique_stress(fw.positions, cl)
    lam_max = _extreme_eigenvalues(Partition(omega, fw.leaders).omega_ff, largest_only=True)[1]
    if lam_max <= 0:
        raise StressMatrixError("the clique stresses vanish on the followers: Omega_ff = 0 (are all cliques leaders?)")
    return omega / lam_max


# ------------------------------------------------------------------------------------------- conditioning
def _extreme_eigenvalues(a: Any, largest_only: bool = False) -> tuple[float, float]:
    """(lambda_min, lambda_max) of a symmetric matrix (lambda_min is NaN with ``largest_only``)."""
    if not sp.issparse(a) or a.shape[0] <= _DENSE_EIG_LIMIT:
        eig = np.linalg.eigvalsh(a.toarray() if sp.issparse(a) else a)
        return float(eig[0]), float(eig[-1])
    hi = float(spla.eigsh(a, k=1, which="LA", tol=1e-8, return_eigenvectors=False)[0])
    if largest_only:
        return float("nan"), hi
    lo = float(spla.eigsh(sp.csc_matrix(a), k=1, sigma=0.0, which="LM", return_eigenvectors=False)[0])
    return lo, hi


def condition_number(omega: StressLike, leaders: ArrayLike) -> float:
    """cond(Omega_ff) = lambda_max / lambda_min of the follower block, the kappa of the "min_cond" design.

    The best spectral radius of the stationary-leader law I - T Omega_ff (eq. 17) is
    (kappa - 1) / (kappa + 1), reached at T = 2 / (lambda_min + lambda_max).

    Parameters
    ----------
    omega
        Stress matrix, shape (n, n), dense or sparse. Sparse matrices with more than
        300 followers use ARPACK (shift-invert at 0 for lambda_min).
    leaders
        Leader indices; the followers are the others.

    Raises
    ------
    StressMatrixError
        Omega_ff is not positive definite.
    """
    lo, hi = _extreme_eigenvalues(Partition(omega, np.asarray(leaders).tolist()).omega_ff)
    if not lo > 0:
        raise StressMatrixError(
            f"Omega_ff is not positive definite (smallest eigenvalue {lo:.3g}): its condition number is undefined"
        )
    return hi / lo
