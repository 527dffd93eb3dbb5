"""Stress matrices: construction, checks, projection, and the leader/follower partition.

An equilibrium stress assigns a weight w_ij to every edge with
sum_j w_ij (r_i - r_j) = 0 for every agent i (paper eq. 1). Its stress matrix
Omega (eq. 2) has Omega_ij = -w_ij for edges, Omega_ii = sum_j w_ij, i.e.
Omega = sum_(i,j) w_ij (e_i - e_j)(e_i - e_j)^T. For affine formation control
Omega must also be positive semi-definite with rank n - d - 1 and Omega_ff
nonsingular (Lemma 2), so that followers can be localised by
x_f* = -Omega_ff^-1 Omega_fl x_l.

Dense (numpy) and sparse (scipy.sparse) stress matrices are both accepted; the
sparse path never forms a dense eigendecomposition.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import cached_property
from typing import Any, TypeAlias

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import ArrayLike, NDArray

from .errors import ControlDimension, FormationError, FrameworkError, StressMatrixError
from .framework import Framework, check_framework, check_leaders_span
from .validation import (
    as_array,
    as_index_array,
    check_bool,
    check_int,
    check_rtol,
    check_square_matrix,
    check_symmetric,
)

__all__ = [
    "DEFAULT_RTOL",
    "Partition",
    "StressLike",
    "check_partition",
    "check_stress",
    "equilibrium_stress_basis",
    "follower_targets",
    "is_sparse_dense_threshold",
    "project_stress",
    "stress_from_weights",
    "weights_from_stress",
]

#: A dense (n, n) array or a scipy.sparse matrix.
StressLike: TypeAlias = Any

#: Default relative tolerance of every check (relative to the largest |eigenvalue| or entry).
DEFAULT_RTOL = 1e-8

#: The remedies named when a tolerance check fails: a rounded matrix (the paper prints its omega to 3 decimals) fails
#: the default tolerance by far, and passes with a looser ``rtol`` or after projection onto the exact stresses.
ROUNDED_REMEDY = (
    "if omega is rounded (as the paper's printed matrix is), pass rtol=1e-3 to accept it as it is, or use "
    "project_stress(omega, fw) (the paper's: paper_omega()) for the nearest exact stress"
)

#: Above this many agents the dense checks are refused for sparse input.
is_sparse_dense_threshold = 3000


def _as_stress(omega: Any, name: str = "omega") -> StressLike:
    """A real, finite, square dense array or CSR matrix (TypeError / ControlDimension / FormationError)."""
    return check_square_matrix(omega, name)


def stress_from_weights(
    n: int, edges: Sequence[tuple[int, int]] | NDArray[np.int64], weights: ArrayLike, sparse: bool = False
) -> StressLike:
    """Stress matrix of edge weights (paper eq. 2), shape (n, n).

    Args:
        n: number of agents.
        edges: (m, 2) undirected edges, integer indices in 0..n-1, no self-loops.
        weights: (m,) stress w_ij of each edge.
        sparse: return a ``scipy.sparse.csr_matrix`` instead of a dense array.

    Raises:
        TypeError: n not an integer, float edge indices, non-numeric weights.
        FormationError: an edge index outside 0..n-1, a self-loop, non-finite weights.
        ControlDimension: edges not (m, 2) or weights not (m,).
    """
    n = check_int(n, "n", low=1)
    e = as_index_array(edges, "edges", n=n, ndim=2)
    loops = np.flatnonzero(e[:, 0] == e[:, 1])
    if loops.size:
        raise FormationError(f"edges must join two distinct agents, got the self-loop {tuple(e[loops[0]].tolist())}")
    sparse = check_bool(sparse, "sparse")
    w = as_array(weights, "weights", ndim=1)
    if w.shape[0] != e.shape[0]:
        raise ControlDimension(f"weights must have one entry per edge ({e.shape[0]}), got {w.shape[0]}")
    i, j = e[:, 0], e[:, 1]
    rows = np.concatenate([i, j, i, j])
    cols = np.concatenate([j, i, i, j])
    vals = np.concatenate([-w, -w, w, w])
    mat = sp.coo_matrix((vals, (rows, cols)), shape=(n, n)).tocsr()
    mat.sum_duplicates()
    return mat if sparse else mat.toarray()


def weights_from_stress(omega: StressLike, edges: Sequence[tuple[int, int]]) -> NDArray[np.float64]:
    """Edge weights w_ij = -Omega_ij for the given edges, shape (m,)."""
    e = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    if sp.issparse(omega):
        return -np.asarray(sp.csr_matrix(omega)[e[:, 0], e[:, 1]]).ravel()
    return -np.asarray(omega)[e[:, 0], e[:, 1]]


def equilibrium_stress_basis(fw: Framework, rtol: float = 1e-10) -> NDArray[np.float64]:
    """Orthonormal basis of the equilibrium stresses of ``fw``, shape (m, k).

    The columns span {w : sum_j w_ij (r_i - r_j) = 0 for all i} (eq. 1), the null
    space of the (n d) x m rigidity-matrix transpose. For a generic
    infinitesimally rigid framework k = m - n d + d (d + 1) / 2.
    """
    check_framework(fw)
    rtol = check_rtol(rtol)
    e = fw.edge_array()
    r = fw.positions
    m, n, d = e.shape[0], fw.n, fw.d
    diff = r[e[:, 0]] - r[e[:, 1]]  # (m, d)
    rig = np.zeros((n, d, m))
    idx = np.arange(m)
    rig[e[:, 0], :, idx] = diff
    rig[e[:, 1], :, idx] = -diff
    return sla.null_space(rig.reshape(n * d, m), rcond=rtol)


def _scale(omega: StressLike) -> float:
    if sp.issparse(omega):
        mat = sp.csr_matrix(omega)
        return float(abs(mat).max()) if mat.nnz else 0.0
    return float(np.max(np.abs(omega))) if omega.size else 0.0


def check_stress(
    omega: Any,
    fw: Framework,
    rtol: float = DEFAULT_RTOL,
    check_graph: bool = True,
) -> None:
    """Check that ``omega`` is a valid stress matrix for affine formation control of ``fw``.

    Checks, in order, and raises on the first that fails, naming it:
    shape (n, n); finite; symmetric; rows sum to zero; equilibrium Omega r = 0;
    supported on the graph's edges (if ``check_graph``); positive semi-definite;
    rank n - d - 1; leaders affinely span R^d; Omega_ff nonsingular.

    Tolerances are relative: an entry-wise residual counts as zero when it is at
    most ``rtol * max|Omega_ij| * (1 + max|r|)``, an eigenvalue when it is at most
    ``rtol * max|eigenvalue|``. The paper prints Omega rounded to 3 decimals
    (row sums -0.001, an eigenvalue of -4.6e-4): pass ``rtol=1e-3`` to accept it
    as printed, or use :func:`project_stress` to get the nearest exact stress.

    Sparse input is checked without a dense eigendecomposition: PSD and rank
    follow from Omega_ff > 0 (a symmetric sparse LDL^T factorisation) and the
    small Schur complement on the leaders.

    Raises:
        StressMatrixError: the failed property, with expected against actual.
        FrameworkError: the leaders do not affinely span R^d.
        TypeError / FormationError: ``fw`` is not a Framework, ``rtol`` not in [0, 1).
    """
    fw = check_framework(fw)
    rtol = check_rtol(rtol)
    check_graph = check_bool(check_graph, "check_graph")
    omega = _as_stress(omega)
    n = fw.n
    if omega.shape != (n, n):
        raise StressMatrixError(f"omega must have shape ({n}, {n}) for this framework, got {omega.shape}")
    scale = _scale(omega)
    if scale == 0.0:
        raise StressMatrixError("omega is the zero matrix: a stress matrix must have rank n - d - 1")
    tol = rtol * scale
    r = fw.positions
    rscale = 1.0 + float(np.max(np.abs(r)))
    asym = abs(omega - omega.T).max() if sp.issparse(omega) else np.max(np.abs(omega - omega.T))
    if asym > tol:
        raise StressMatrixError(f"omega is not symmetric: max |Omega - Omega^T| = {asym:.3g} > tolerance {tol:.3g}")
    rowsum = np.asarray(omega.sum(axis=1)).ravel()
    worst = int(np.argmax(np.abs(rowsum)))
    if abs(rowsum[worst]) > tol * np.sqrt(n):
        raise StressMatrixError(
            f"omega rows must sum to zero: row {worst} sums to {rowsum[worst]:.3g} (tolerance {tol * np.sqrt(n):.3g} "
            f"at rtol={rtol:g}); {ROUNDED_REMEDY}"
        )
    resid = np.asarray(omega @ r)
    worst = int(np.argmax(np.max(np.abs(resid), axis=1)))
    if np.max(np.abs(resid)) > tol * rscale * np.sqrt(n):
        raise StressMatrixError(
            f"omega is not an equilibrium stress of the nominal positions: Omega r = 0 fails at "
            f"agent {worst} with residual {np.max(np.abs(resid[worst])):.3g} "
            f"(tolerance {tol * rscale * np.sqrt(n):.3g} at rtol={rtol:g}); {ROUNDED_REMEDY}"
        )
    if check_graph:
        allowed = {(i, j) for i, j in fw.edges}
        coo = sp.coo_matrix(omega)
        off = (coo.row < coo.col) & (np.abs(coo.data) > tol)
        for i, j, v in zip(coo.row[off], coo.col[off], coo.data[off], strict=True):
            if (int(i), int(j)) not in allowed:
                raise StressMatrixError(
                    f"omega has a nonzero entry Omega[{i}, {j}] = {v:.3g} but ({i}, {j}) is not an edge of the "
                    "graph: the control law would not be distributed"
                )
    check_leaders_span(r, fw.leaders)
    if sp.issparse(omega):
        _check_spectrum_sparse(omega, fw, rtol)
    else:
        _check_spectrum_dense(np.asarray(omega), fw, rtol)


def _check_spectrum_dense(omega: NDArray[np.float64], fw: Framework, rtol: float) -> None:
    n, d = fw.n, fw.d
    eig = np.linalg.eigvalsh((omega + omega.T) / 2)
    etol = rtol * max(abs(eig[0]), abs(eig[-1]))
    if eig[0] < -etol:
        raise StressMatrixError(
            f"omega is not positive semi-definite: smallest eigenvalue {eig[0]:.3g} < -tolerance {etol:.3g} "
            f"(rtol={rtol:g}); {ROUNDED_REMEDY}"
        )
    rank = int(np.sum(eig > etol))
    if rank != n - d - 1:
        raise StressMatrixError(
            f"omega must have rank n - d - 1 = {n - d - 1} (universal rigidity), got rank {rank} "
            f"(eigenvalues within {etol:.3g} of zero count as zero)"
        )
    part = Partition(omega, fw.leaders)
    eff = np.linalg.eigvalsh(part.omega_ff_dense)
    if eff[0] <= etol:
        raise StressMatrixError(
            f"Omega_ff is singular (smallest eigenvalue {eff[0]:.3g}): the followers are not affinely "
            "localisable from these leaders"
        )


def _check_spectrum_sparse(omega: sp.csr_matrix, fw: Framework, rtol: float) -> None:
    n, d = fw.n, fw.d
    part = Partition(omega, fw.leaders)
    try:
        inertia_neg, inertia_zero, diag = _ldl_inertia(part.omega_ff, rtol)
    except RuntimeError as exc:
        raise StressMatrixError(f"Omega_ff is singular: {exc}") from exc
    if inertia_neg or inertia_zero:
        raise StressMatrixError(
            f"Omega_ff is not positive definite ({inertia_neg} negative and {inertia_zero} zero pivots in "
            f"its LDL^T factorisation): omega is not PSD with rank n - d - 1, or Omega_ff is singular"
        )
    # Omega >= 0 with rank n - d - 1  <=>  Omega_ff > 0 and the Schur complement
    # S = Omega_ll - Omega_lf Omega_ff^-1 Omega_fl >= 0 with rank n_l - d - 1.
    s = part.schur_complement()
    eig = np.linalg.eigvalsh((s + s.T) / 2) if s.size else np.zeros(0)
    etol = rtol * max(float(np.max(diag)), 1e-300)
    if eig.size and eig[0] < -etol:
        raise StressMatrixError(
            f"omega is not positive semi-definite: the leaders' Schur complement has eigenvalue {eig[0]:.3g}"
        )
    rank = part.n_f + int(np.sum(eig > etol))
    if rank != n - d - 1:
        raise StressMatrixError(f"omega must have rank n - d - 1 = {n - d - 1} (universal rigidity), got rank {rank}")


def _ldl_inertia(a: sp.spmatrix, rtol: float) -> tuple[int, int, NDArray[np.float64]]:
    """Inertia of a sparse symmetric matrix from a symmetric-mode LU (no row pivoting).

    With SuperLU in symmetric mode and no off-diagonal pivoting, A = P L U P^T
    with U = D L^T, so by Sylvester's law the signs of diag(U) give the inertia.
    """
    lu = spla.splu(
        sp.csc_matrix(a),
        permc_spec="MMD_AT_PLUS_A",
        diag_pivot_thresh=0.0,
        options={"SymmetricMode": True},
    )
    if not np.array_equal(lu.perm_r, lu.perm_c):
        raise RuntimeError("the factorisation needed off-diagonal pivoting (indefinite matrix)")
    diag = lu.U.diagonal()
    tol = rtol * float(np.max(np.abs(diag)))
    return int(np.sum(diag < -tol)), int(np.sum(np.abs(diag) <= tol)), diag


def project_stress(omega: StressLike, fw: Framework, rtol: float = DEFAULT_RTOL) -> NDArray[np.float64]:
    """Nearest exact equilibrium stress of ``fw`` to ``omega`` in the Frobenius norm.

    Projects the edge weights -Omega_ij onto the equilibrium-stress space of the
    framework (:func:`equilibrium_stress_basis`); the result is symmetric, has
    zero row sums and satisfies Omega r = 0 to machine precision. It is then
    checked with :func:`check_stress` (rounding can in principle break PSD).
    Used for the paper's matrix, which is printed rounded to 3 decimals.
    """
    fw = check_framework(fw)
    rtol = check_rtol(rtol)
    om = as_array(omega.toarray() if sp.issparse(omega) else omega, "omega", ndim=2)
    if om.shape != (fw.n, fw.n):
        raise StressMatrixError(f"omega must have shape ({fw.n}, {fw.n}), got {om.shape}")
    basis = equilibrium_stress_basis(fw)
    if basis.shape[1] == 0:
        raise StressMatrixError("the framework has no nonzero equilibrium stress: it cannot be universally rigid")
    e = fw.edge_array()
    # ||Omega(w) - om||_F^2 = sum over edges of 2 (w_e + om_e)^2 + diagonal terms; minimise over
    # the stress space exactly by least squares on the vectorised matrix.
    cols = np.stack([stress_from_weights(fw.n, e, basis[:, k]).ravel() for k in range(basis.shape[1])], axis=1)
    coef, *_ = np.linalg.lstsq(cols, ((om + om.T) / 2).ravel(), rcond=None)
    proj = np.asarray(stress_from_weights(fw.n, e, basis @ coef))
    check_stress(proj, fw, rtol=rtol)
    return proj


class Partition:
    """The leader/follower blocks of a stress matrix and a cached factorisation of Omega_ff.

    ``omega`` is reordered as [[Omega_ll, Omega_lf], [Omega_fl, Omega_ff]] (eq. 20)
    with ``leaders`` and ``followers`` as index arrays into the original agent order.
    Dense input gives dense blocks and a Cholesky factor; sparse input gives CSR
    blocks and a sparse LU factor.
    """

    def __init__(self, omega: Any, leaders: Sequence[int]) -> None:
        om = _as_stress(omega)
        n = om.shape[0]
        try:
            lead = as_index_array(leaders, "leaders", n=n, min_size=1, distinct=True)
        except FormationError as exc:  # keep the historical class for range / duplicate errors
            raise FrameworkError(f"leaders must be distinct indices in 0..{n - 1}: {exc}") from exc
        if lead.size >= n:
            raise FrameworkError(f"leaders must leave at least one follower: {lead.size} leaders of {n} agents")
        mask = np.ones(n, dtype=bool)
        mask[lead] = False
        self.n = n
        self.leaders = lead
        self.followers = np.flatnonzero(mask)
        self.sparse = sp.issparse(om)
        self.omega = om
        if self.sparse:
            csr = sp.csr_matrix(om)
            self.omega_ff: Any = csr[self.followers][:, self.followers].tocsc()
            self.omega_fl: Any = csr[self.followers][:, lead].toarray()
            self.omega_lf: Any = csr[lead][:, self.followers].tocsr()
            self.omega_ll: Any = csr[lead][:, lead].toarray()
        else:
            self.omega_ff = om[np.ix_(self.followers, self.followers)]
            self.omega_fl = om[np.ix_(self.followers, lead)]
            self.omega_lf = om[np.ix_(lead, self.followers)]
            self.omega_ll = om[np.ix_(lead, lead)]

    @property
    def n_l(self) -> int:
        """Number of leaders."""
        return int(self.leaders.size)

    @property
    def n_f(self) -> int:
        """Number of followers."""
        return int(self.followers.size)

    @property
    def omega_ff_dense(self) -> NDArray[np.float64]:
        """Omega_ff as a dense array, shape (n_f, n_f)."""
        return self.omega_ff.toarray() if self.sparse else self.omega_ff

    @cached_property
    def _factor(self) -> Any:
        if self.sparse:
            try:
                return spla.splu(sp.csc_matrix(self.omega_ff))
            except RuntimeError as exc:
                raise StressMatrixError(f"Omega_ff is singular: {exc}") from exc
        try:
            return ("chol", sla.cho_factor(self.omega_ff))
        except np.linalg.LinAlgError:
            try:
                return ("lu", sla.lu_factor(self.omega_ff, check_finite=False))
            except (np.linalg.LinAlgError, ValueError) as exc:
                raise StressMatrixError(f"Omega_ff is singular: {exc}") from exc

    def solve_ff(self, rhs: NDArray[np.float64]) -> NDArray[np.float64]:
        """Solve Omega_ff X = rhs for rhs of shape (n_f, k)."""
        f = self._factor
        if self.sparse:
            return np.asarray(f.solve(np.ascontiguousarray(rhs)))
        kind, fac = f
        if kind == "chol":
            return sla.cho_solve(fac, rhs, check_finite=False)
        return sla.lu_solve(fac, rhs, check_finite=False)

    @cached_property
    def localisation(self) -> NDArray[np.float64]:
        """L = -Omega_ff^-1 Omega_fl, shape (n_f, n_l): x_f* = L x_l (Lemma 2)."""
        return -self.solve_ff(np.asarray(self.omega_fl))

    def schur_complement(self) -> NDArray[np.float64]:
        """S = Omega_ll - Omega_lf Omega_ff^-1 Omega_fl, shape (n_l, n_l)."""
        return np.asarray(self.omega_ll) + np.asarray(self.omega_lf @ self.localisation)

    def targets(self, x_leaders: NDArray[np.float64]) -> NDArray[np.float64]:
        """Follower targets x_f* = -Omega_ff^-1 Omega_fl x_l.

        Args:
            x_leaders: leader positions (or states), shape (..., n_l, q).
        Returns:
            shape (..., n_f, q).
        """
        return np.einsum("fl,...lq->...fq", self.localisation, x_leaders)

    def stress_force(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """(Omega x)_f = Omega_ff x_f + Omega_fl x_l for all agents' x, shape (..., n, q) -> (..., n_f, q)."""
        xf = x[..., self.followers, :]
        xl = x[..., self.leaders, :]
        if self.sparse:
            flat = np.moveaxis(xf, -2, 0).reshape(self.n_f, -1)
            ff = np.moveaxis((self.omega_ff @ flat).reshape((self.n_f,) + xf.shape[:-2] + xf.shape[-1:]), 0, -2)
        else:
            ff = np.einsum("fg,...gq->...fq", self.omega_ff, xf)
        return ff + np.einsum("fl,...lq->...fq", self.omega_fl, xl)


def check_partition(part: Partition, rtol: float = DEFAULT_RTOL, name: str = "omega") -> None:
    """Check the stress properties the laws rely on, without the nominal positions.

    ``omega`` must be nonzero and symmetric (max |Omega - Omega^T| <= rtol max |Omega_ij|),
    its rows must sum to zero (tolerance rtol max |Omega_ij| sqrt(n): targets are then
    translation-equivariant), and Omega_ff must be positive definite (smallest eigenvalue
    > rtol times the largest; sparse: an LDL^T inertia count), so that the affine
    localisation x_f* = -Omega_ff^-1 Omega_fl x_l exists and the laws' modes are real.
    Omega r = 0 needs the positions: see :func:`check_stress`.

    Raises:
        StressMatrixError: the failed property, naming ``name`` with expected against actual.
    """
    rtol = check_rtol(rtol)
    om = part.omega
    scale = _scale(om)
    if scale == 0.0:
        raise StressMatrixError(f"{name} is the zero matrix: a stress matrix must have rank n - d - 1 > 0")
    try:
        check_symmetric(om, name, rtol)
    except FormationError as exc:
        raise StressMatrixError(str(exc)) from exc
    rowsum = np.asarray(om.sum(axis=1)).ravel()
    worst = int(np.argmax(np.abs(rowsum)))
    tol = rtol * scale * np.sqrt(part.n)
    if abs(rowsum[worst]) > tol:
        raise StressMatrixError(
            f"{name} rows must sum to zero (a stress matrix): row {worst} sums to {rowsum[worst]:.3g} "
            f"(tolerance {tol:.3g} at rtol={rtol:g}); {ROUNDED_REMEDY}"
        )
    if part.sparse and part.n_f > 2000:
        try:
            neg, zero, _ = _ldl_inertia(part.omega_ff, max(rtol, 1e-14))
        except RuntimeError as exc:
            raise StressMatrixError(f"{name}: Omega_ff is not positive definite ({exc})") from exc
        if neg or zero:
            raise StressMatrixError(
                f"{name}: Omega_ff is not positive definite (it must be): {neg} negative and {zero} zero pivot(s) "
                "in its LDL^T factorisation (the followers are not affinely localisable from these leaders)"
            )
        return
    eff = np.linalg.eigvalsh(part.omega_ff_dense)
    if not eff[0] > rtol * max(abs(eff[-1]), abs(eff[0])):
        raise StressMatrixError(
            f"{name}: Omega_ff is not positive definite (it must be), smallest eigenvalue {eff[0]:.3g} (largest "
            f"{eff[-1]:.3g}): the followers are not affinely localisable from these leaders"
        )


def follower_targets(
    omega: Any, leaders: Sequence[int], x_leaders: ArrayLike, *, check: bool = True, rtol: float = DEFAULT_RTOL
) -> NDArray[np.float64]:
    """Follower targets x_f* = -Omega_ff^-1 Omega_fl x_l (Lemma 2).

    Args:
        omega: stress matrix, shape (n, n), dense or sparse.
        leaders: leader indices (n_l of them); followers are the others, in increasing order.
        x_leaders: leader positions, shape (n_l, d) or batched (..., n_l, d).
        check: validate omega with :func:`check_partition` (symmetric, zero row sums,
            Omega_ff positive definite) at ``rtol``; ``check=False`` skips it for speed.
        rtol: relative tolerance of the check.
    Returns:
        Follower targets, shape (n_f, d) (or (..., n_f, d)), m.

    Raises:
        StressMatrixError: omega fails the check.
    """
    part = Partition(omega, leaders)
    if check_bool(check, "check"):
        check_partition(part, rtol)
    xl = as_array(x_leaders, "x_leaders")
    if xl.ndim < 2 or xl.shape[-2] != part.n_l:
        raise ControlDimension(f"x_leaders must have shape (..., {part.n_l}, d), got {xl.shape}")
    return part.targets(xl)
