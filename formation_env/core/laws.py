"""Sampled-data follower control laws, one class each, with their closed-loop analysis.

Every law maps the current states x (all agents) and the leaders' inputs u_l to
follower inputs u_f; the followers then move by the sampled dynamics
x_f(k+1) = A_d x_f + B_d u_f. Laws are batched: x has shape (..., n, q),
u_l (..., n_l, p), u_f (..., n_f, p). ``memory`` carries what a law remembers
between samples (the distributed law's previous inputs), so steps stay pure.

Laws (``LAWS``):

=======================  =====================================================  ==================
name                     law                                                    paper
=======================  =====================================================  ==================
``stationary``           u_f = -g (Omega x)_f  (single integrators)             eq. 17-19, Thm 1
``linear``               u_f = eps K (Omega x)_f, K = -(B'PB)^-1 B'PA           Thm 3, corrected
``linear_paper``         u = [(I - eps Omega) kron K] x  (literal, defective)   eq. 25
``dynamic``              Omega_ff u_f = (Omega x)_f K' - Omega_fl u_l (exact)    eq. 21-22, Thm 2
``dynamic_distributed``  m Jacobi rounds of the same, warm-started              not in the paper
=======================  =====================================================  ==================

Error e = x_f - x_f*, x_f* = L x_l with L = -Omega_ff^-1 Omega_fl (Lemma 2), so
(Omega x)_f = Omega_ff e. Each law's error dynamics decouple over the
eigenvalues of Omega_ff (or of the Jacobi matrix), giving small per-mode
matrices whose spectral radius is the closed loop's (see ``mode_matrices``).
"""

from __future__ import annotations

import itertools
from abc import ABC, abstractmethod
from typing import Any

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from .dynamics import LinearDynamics, check_dynamics, riccati_gain
from .errors import ControlDimension, FormationError, UnstableParameterError
from .stress import Partition
from .validation import as_array, check_dt, check_int, check_real_scalar

__all__ = [
    "LAWS",
    "DynamicLeaderLaw",
    "FollowerLaw",
    "PaperLinearLaw",
    "StressFeedbackLaw",
    "gamma_interval",
    "jacobi_modes",
    "make_law",
    "spectral_radius",
    "stress_modes",
]

LAWS = ("stationary", "linear", "linear_paper", "dynamic", "dynamic_distributed")

Array = NDArray[np.float64]


def spectral_radius(mats: Array) -> float:
    """Largest |eigenvalue| over a stack of square matrices, shape (k, s, s) (0 for an empty stack)."""
    if mats.shape[0] == 0:
        return 0.0
    return float(np.max(np.abs(np.linalg.eigvals(mats))))


def stress_modes(A_d: Array, B_d: Array, K: Array, eps: float, lam: Array) -> Array:
    """Mode matrices of the stress feedback u = eps K (Omega_ff kron I) e: A_d + eps lambda B_d K for each
    eigenvalue lambda (k,) of Omega_ff, shape (k, q, q)."""
    return A_d[None] + eps * lam[:, None, None] * (B_d @ K)[None]


def jacobi_modes(A_d: Array, B_d: Array, K: Array, c: Array) -> Array:
    """Mode matrices of the dynamic-leader law with m Jacobi rounds, on the state (e, s) of error and held input:
    c = nu^m (k,) for the Jacobi eigenvalues nu, shape (k, q + p, q + p)."""
    q, p = B_d.shape
    mats = np.zeros((c.size, q + p, q + p))
    mats[:, :q, :q] = A_d[None] + (1 - c)[:, None, None] * (B_d @ K)[None]
    mats[:, :q, q:] = c[:, None, None] * B_d[None]
    mats[:, q:, :q] = (1 - c)[:, None, None] * K[None]
    mats[:, q:, q:] = c[:, None, None] * np.eye(p)[None]
    return mats


class FollowerLaw(ABC):
    """A sampled-data follower law for agents with dynamics ``dynamics`` sampled at ``dt`` seconds.

    Subclasses implement :meth:`control` and :meth:`mode_matrices`.
    """

    name: str = ""
    #: True when the error e = x_f - x_f* obeys e(k+1) = M e(k) for constant leader
    #: inputs, so that the spectral radius of M is the error decay per step.
    tracks_targets: bool = True

    def __init__(self, part: Partition, dynamics: LinearDynamics, dt: float) -> None:
        if not isinstance(part, Partition):
            raise TypeError(f"part must be a Partition, got {type(part).__name__}")
        check_dynamics(dynamics)
        dt = check_dt(dt)
        self.part = part
        self.dynamics = dynamics
        self.dt = float(dt)
        self.A_d, self.B_d = dynamics.zoh(dt)
        # Leader and follower rows: slices (views, no copies) where the indices are consecutive, as in
        # trilateration frameworks; and the transposed sampled matrices, skipping A_d where it is I.
        self._rows_l = _as_slice(part.leaders)
        self._rows_f = _as_slice(part.followers)
        self._A_t = None if np.array_equal(self.A_d, np.eye(self.A_d.shape[0])) else np.ascontiguousarray(self.A_d.T)
        self._B_t = np.ascontiguousarray(self.B_d.T)
        # Rows of Omega belonging to the followers, for (Omega x)_f in one matmul.
        om = part.omega
        if part.sparse:
            self._omega_f: Any = sp.csr_matrix(om)[part.followers]
        else:
            self._omega_f = np.ascontiguousarray(om[part.followers])

    # ------------------------------------------------------------------ stepping
    def stress_force(self, x: Array) -> Array:
        """(Omega x)_f for x of shape (..., n, q); returns (..., n_f, q)."""
        if self.part.sparse:
            return _sparse_left_matmul(self._omega_f, x)
        return np.matmul(self._omega_f, x)

    def initial_memory(self, batch_shape: tuple[int, ...] = ()) -> Array | None:
        """What the law remembers before the first sample (None if nothing)."""
        return None

    @abstractmethod
    def control(self, x: Array, u_leaders: Array, memory: Array | None) -> tuple[Array, Array | None]:
        """Follower inputs u_f, shape (..., n_f, p), and the updated memory."""

    def step(self, x: Array, u_leaders: Array, memory: Array | None = None) -> tuple[Array, Array | None]:
        """One sample for all agents: returns (x(k+1), memory).

        Leaders move by their inputs ``u_leaders`` (..., n_l, p); followers by the law.
        """
        u_f, memory = self.control(x, u_leaders, memory)
        out = np.empty_like(x)
        for rows, u in ((self._rows_l, u_leaders), (self._rows_f, u_f)):
            xr = x[..., rows, :]
            out[..., rows, :] = (xr if self._A_t is None else xr @ self._A_t) + u @ self._B_t
        return out, memory

    # ------------------------------------------------------------------ analysis
    @abstractmethod
    def mode_matrices(self) -> Array:
        """Closed-loop matrices of the decoupled modes, shape (n_modes, s, s)."""

    def spectral_radius(self) -> float:
        """Spectral radius of the closed-loop error dynamics (the error decay factor per step)."""
        return spectral_radius(self.mode_matrices())

    @abstractmethod
    def closed_loop(self) -> Array:
        """The full closed-loop matrix of the follower error (and memory) state."""


def _as_slice(idx: Any) -> slice | NDArray[np.int64]:
    """Indices as a slice when they are consecutive and increasing (a view instead of a copy), else an array."""
    arr = np.asarray(idx, dtype=np.int64)
    if arr.size and np.array_equal(arr, np.arange(arr[0], arr[0] + arr.size)):
        return slice(int(arr[0]), int(arr[0]) + arr.size)
    return arr


def _sparse_left_matmul(mat: Any, x: Array) -> Array:
    """mat @ x over the agent axis for sparse mat (r, n) and x (..., n, q)."""
    n, q = x.shape[-2], x.shape[-1]
    batch = x.shape[:-2]
    flat = np.moveaxis(x, -2, 0).reshape(n, -1)
    res = np.asarray(mat @ flat).reshape((mat.shape[0],) + batch + (q,))
    return np.moveaxis(res, 0, -2)


def _omega_ff_eigenvalues(part: Partition) -> Array:
    if part.sparse and part.n_f > 3000:
        raise FormationError(
            f"mode analysis of a sparse stress with {part.n_f} followers needs the full spectrum of Omega_ff; "
            "use formation_env.core.analysis.extreme_eigenvalues for the bounds instead"
        )
    return np.asarray(np.linalg.eigvalsh(part.omega_ff_dense), dtype=np.float64)


def gamma_interval(A_d: Array, B_d: Array, K: Array, gamma_max: float = 1e3) -> tuple[float, float]:
    """The interval (g_lo, g_hi) around g = 1 on which A_d + g B_d K is Schur.

    The stress laws' modes are A_d + eps lambda_i B_d K for the eigenvalues lambda_i of
    Omega_ff, so they are all stable iff eps lambda_i lies in this interval for every i.
    Found by a log-spaced scan and bisection of both ends (1e-10 relative).
    """

    def rho(g: float) -> float:
        return float(np.max(np.abs(np.linalg.eigvals(A_d + g * B_d @ K))))

    if rho(1.0) >= 1.0:
        raise UnstableParameterError(
            f"A_d + B_d K is not Schur (spectral radius {rho(1.0):.4g}): the gain K does not stabilise one agent"
        )
    grid = np.geomspace(1.0, gamma_max, 400)
    hi = gamma_max
    for a, b in itertools.pairwise(grid):
        if rho(b) >= 1.0:
            hi = _bisect(rho, a, b)
            break
    grid = np.geomspace(1.0, 1.0 / gamma_max, 400)
    lo = 0.0
    for a, b in itertools.pairwise(grid):
        if rho(b) >= 1.0:
            lo = _bisect(rho, a, b)
            break
    return lo, hi


def _bisect(rho: Any, stable: float, unstable: float) -> float:
    for _ in range(80):
        mid = 0.5 * (stable + unstable)
        if rho(mid) < 1.0:
            stable = mid
        else:
            unstable = mid
    return 0.5 * (stable + unstable)


class StressFeedbackLaw(FollowerLaw):
    """u_f = eps K (Omega x)_f: the stationary-leader law and its general linear form.

    * ``stationary`` (eq. 17): single integrators, K = -g I, eps = 1, so
      x_f(k+1) = [I - T g Omega_ff] x_f - T g Omega_fl x_l (eq. 19). Error modes
      1 - T g lambda_i; stable iff T g lambda_max < 2, i.e. T mu_min > -2 (Theorem 1)
      with mu = eig(-Omega_ff).
    * ``linear``: general agents, K = -(B'PB)^-1 B'PA from the modified Riccati
      equation (Theorem 3) and the corrected law u_i = eps K sum_j w_ij (x_i - x_j)
      (the paper's eq. 24 without its "+ x_i" term). Error modes
      A + eps lambda_i B K; ``eps`` defaults to the value minimising the worst
      spectral radius inside the admissible interval (:meth:`eps_range`).

    Exact tracking needs leaders on A-trajectories (u_l = 0); moving leaders
    leave a tracking lag, which the ``dynamic`` law removes.
    """

    def __init__(
        self,
        part: Partition,
        dynamics: LinearDynamics,
        dt: float,
        K: Array | None = None,
        eps: float | None = None,
        Q: Array | None = None,
        name: str = "linear",
    ) -> None:
        super().__init__(part, dynamics, dt)
        self.name = name
        if K is None:
            K = riccati_gain(self.A_d, self.B_d, Q)
        K = np.asarray(K, dtype=np.float64)
        if K.shape != (dynamics.p, dynamics.q):
            raise ControlDimension(f"K must have shape ({dynamics.p}, {dynamics.q}), got {K.shape}")
        self.K = K
        self._lam: Array | None = None
        if eps is None:
            eps = self.best_eps()
        if not (np.isfinite(eps) and eps > 0):
            raise FormationError(f"eps must be a positive finite number, got {eps}")
        self.eps = float(eps)
        self._gain_t = (self.eps * self.K).T  # (q, p): u_f = (Omega x)_f @ gain_t

    @property
    def lambdas(self) -> Array:
        """Eigenvalues of Omega_ff, increasing, shape (n_f,)."""
        if self._lam is None:
            self._lam = _omega_ff_eigenvalues(self.part)
        return self._lam

    def eps_range(self) -> tuple[float, float]:
        """Admissible eps: every mode A_d + eps lambda_i B_d K is Schur iff eps lies strictly inside."""
        lo, hi = gamma_interval(self.A_d, self.B_d, self.K)
        return lo / float(self.lambdas[0]), hi / float(self.lambdas[-1])

    def best_eps(self) -> float:
        """The eps in :meth:`eps_range` that minimises the largest mode spectral radius."""
        from scipy.optimize import minimize_scalar

        lo, hi = self.eps_range()
        if not lo < hi:
            raise UnstableParameterError(
                f"no eps stabilises every mode: need eps in ({lo:.4g}, {hi:.4g}), which is empty "
                f"(cond(Omega_ff) = {self.lambdas[-1] / self.lambdas[0]:.4g} is too large for this gain)"
            )
        res = minimize_scalar(
            lambda e: spectral_radius(self._modes(e)), bounds=(lo, hi), method="bounded", options={"xatol": 1e-10 * hi}
        )
        return float(res.x)

    def _modes(self, eps: float) -> Array:
        return stress_modes(self.A_d, self.B_d, self.K, eps, self.lambdas)

    def control(self, x: Array, u_leaders: Array, memory: Array | None) -> tuple[Array, Array | None]:
        return self.stress_force(x) @ self._gain_t, memory

    def mode_matrices(self) -> Array:
        """A_d + eps lambda_i B_d K for each eigenvalue lambda_i of Omega_ff, shape (n_f, q, q)."""
        return self._modes(self.eps)

    def closed_loop(self) -> Array:
        """e(k+1) = [I kron A_d + eps Omega_ff kron B_d K] e(k), shape (n_f q, n_f q)."""
        off = self.part.omega_ff_dense
        return np.kron(np.eye(self.part.n_f), self.A_d) + self.eps * np.kron(off, self.B_d @ self.K)


class PaperLinearLaw(StressFeedbackLaw):
    """The paper's literal general-linear law u = [(I - eps Omega) kron K] x (eq. 25).

    Kept to show its defect: the "+ x_i" term (the identity) feeds K x_f back
    towards the origin, so the followers settle at the rest point x_f = M x_f - eps (Omega_fl kron BK) x_l
    of their closed loop M = I kron (A + BK) - eps Omega_ff kron BK (:meth:`closed_loop`),
    not on the affine targets (and the stress term has the opposite sign of the
    local form eq. 24). :attr:`tracks_targets` is False: the error is not an
    autonomous state, so :meth:`mode_matrices` gives the followers' own dynamics.
    """

    tracks_targets = False

    def control(self, x: Array, u_leaders: Array, memory: Array | None) -> tuple[Array, Array | None]:
        xf = x[..., self.part.followers, :]
        return xf @ self.K.T - self.stress_force(x) @ self._gain_t, memory

    def best_eps(self) -> float:
        """The eps minimising the literal closed loop's spectral radius (it is Schur there if anywhere)."""
        from scipy.optimize import minimize_scalar

        _, hi = StressFeedbackLaw.eps_range(self)
        res = minimize_scalar(lambda e: spectral_radius(self._literal_modes(e)), bounds=(0.0, hi), method="bounded")
        return float(res.x)

    def _literal_modes(self, eps: float) -> Array:
        bk = self.B_d @ self.K
        return (self.A_d + bk)[None] - eps * self.lambdas[:, None, None] * bk[None]

    def mode_matrices(self) -> Array:
        """A_d + B_d K - eps lambda_i B_d K for each eigenvalue lambda_i of Omega_ff."""
        return self._literal_modes(self.eps)

    def closed_loop(self) -> Array:
        """x_f(k+1) = [I kron (A_d + B_d K) - eps Omega_ff kron B_d K] x_f + (leader input terms)."""
        off = self.part.omega_ff_dense
        bk = self.B_d @ self.K
        return np.kron(np.eye(self.part.n_f), self.A_d + bk) - self.eps * np.kron(off, bk)


class DynamicLeaderLaw(FollowerLaw):
    """The dynamic-leader law: followers use their neighbours' next moves (eq. 21).

    The paper's law for single integrators,
    u_i = -(1/gamma_i) sum_j w_ij (x_i - x_j - (x_j(k+1) - x_j(k)) / T),
    gamma_i = sum_j w_ij, needs the followers' own next positions, so its exact
    form is the linear solve Omega_ff u_f = (Omega x)_f K' - Omega_fl u_l
    (K = -g I for single integrators, g = 1 in the paper). The error then obeys
    e(k+1) = (A_d + B_d K) e(k) = (1 - g T) e(k) whatever the leaders do:
    deadbeat at g T = 1, stable iff 0 < g T < 2 (Theorem 2). For general linear
    agents the same construction with the Riccati K (our extension) gives
    e(k+1) = (A_d + B_d K) e(k), where u_l feeds forward the leaders' inputs.

    With ``rounds=m`` (``dynamic_distributed``), each follower instead runs m
    Jacobi rounds over the communication graph, starting from its previous
    input: u^(r) = D^-1 [(Omega x)_f K' - N_ff u^(r-1) - Omega_fl u_l], with
    D = diag(Omega_ff), N_ff = Omega_ff - D. With J = -D^-1 N_ff (real
    eigenvalues nu) and c = nu^m, each mode of (e, s = u(k-1) - L u_l) obeys
    [[A + (1 - c) B K, c B], [(1 - c) K, c I]] for constant leader inputs u_l
    (L u_l is the followers' input at zero error; s starts at -L u_l, the
    memory at 0). This is not in the paper, and it
    can be unstable where the exact law is not: on the paper's example one round
    diverges at T = 1 and converges at T = 0.1 (see ``stability_report``).
    """

    def __init__(
        self,
        part: Partition,
        dynamics: LinearDynamics,
        dt: float,
        K: Array | None = None,
        gain: float = 1.0,
        rounds: int | None = None,
        Q: Array | None = None,
    ) -> None:
        super().__init__(part, dynamics, dt)
        if K is None:
            if dynamics.is_single_integrator:
                if not (np.isfinite(gain) and gain > 0):
                    raise FormationError(f"gain must be positive and finite, got {gain}")
                K = -gain * np.eye(dynamics.q)
            else:
                K = riccati_gain(self.A_d, self.B_d, Q)
        K = np.asarray(K, dtype=np.float64)
        if K.shape != (dynamics.p, dynamics.q):
            raise ControlDimension(f"K must have shape ({dynamics.p}, {dynamics.q}), got {K.shape}")
        self.K = K
        self._kt = K.T
        if rounds is not None and (int(rounds) != rounds or rounds < 1):
            raise FormationError(f"rounds must be a positive integer number of communication rounds, got {rounds}")
        self.rounds = None if rounds is None else int(rounds)
        self.name = "dynamic" if rounds is None else "dynamic_distributed"
        off = part.omega_ff
        self._diag = np.asarray(off.diagonal()).copy()
        if np.any(self._diag <= 0):
            raise FormationError("Omega_ff has a non-positive diagonal entry: the Jacobi rounds are undefined")
        self._nff: Any = (off - sp.diags(self._diag)).tocsr() if part.sparse else off - np.diag(self._diag)

    def initial_memory(self, batch_shape: tuple[int, ...] = ()) -> Array | None:
        if self.rounds is None:
            return None
        return np.zeros(batch_shape + (self.part.n_f, self.dynamics.p))

    def control(self, x: Array, u_leaders: Array, memory: Array | None) -> tuple[Array, Array | None]:
        rhs = self.stress_force(x) @ self._kt - np.matmul(self.part.omega_fl, u_leaders)
        if self.rounds is None:
            return _solve_ff(self.part, rhs), None
        u = memory if memory is not None else np.zeros(rhs.shape)
        for _ in range(self.rounds):
            nu = _sparse_left_matmul(self._nff, u) if self.part.sparse else np.matmul(self._nff, u)
            u = (rhs - nu) / self._diag[:, None]
        return u, u

    def jacobi_eigenvalues(self) -> Array:
        """Eigenvalues nu of J = -D^-1 N_ff (real: J is similar to a symmetric matrix), shape (n_f,)."""
        s = 1.0 / np.sqrt(self._diag)
        sym = s[:, None] * self.part.omega_ff_dense * s[None, :]
        return 1.0 - np.linalg.eigvalsh(sym)

    def mode_matrices(self) -> Array:
        a, b, k = self.A_d, self.B_d, self.K
        if self.rounds is None:
            return (a + b @ k)[None]
        return jacobi_modes(a, b, k, self.jacobi_eigenvalues() ** self.rounds)

    def closed_loop(self) -> Array:
        """Exact: I kron (A_d + B_d K). Distributed: the (e, s) block matrix with J^m, shape 2 blocks."""
        nf = self.part.n_f
        a, b, k = self.A_d, self.B_d, self.K
        if self.rounds is None:
            return np.asarray(np.kron(np.eye(nf), a + b @ k), dtype=np.float64)
        jm = np.linalg.matrix_power(-self._nff_dense() / self._diag[:, None], self.rounds)
        ij = np.eye(nf) - jm
        top = np.hstack([np.kron(np.eye(nf), a) + np.kron(ij, b @ k), np.kron(jm, b)])
        bot = np.hstack([np.kron(ij, k), np.kron(jm, np.eye(self.dynamics.p))])
        return np.vstack([top, bot])

    def _nff_dense(self) -> Array:
        return self._nff.toarray() if self.part.sparse else self._nff


def _solve_ff(part: Partition, rhs: Array) -> Array:
    """Omega_ff^-1 rhs over the follower axis, rhs of shape (..., n_f, p)."""
    nf = part.n_f
    batch, p = rhs.shape[:-2], rhs.shape[-1]
    flat = np.moveaxis(rhs, -2, 0).reshape(nf, -1)
    sol = part.solve_ff(flat).reshape((nf,) + batch + (p,))
    return np.moveaxis(sol, 0, -2)


def _check_law_params(params: dict[str, Any], dynamics: LinearDynamics) -> dict[str, Any]:
    """Validate law parameters whatever the law does with them (gain is refused even where K overrides it)."""
    out = dict(params)
    if "gain" in out:
        out["gain"] = check_real_scalar(out["gain"], "gain", low=0.0, unit="1/s", what="positive and finite (1/s)")
    if "eps" in out and out["eps"] is not None:
        out["eps"] = check_real_scalar(out["eps"], "eps", low=0.0, what="a positive finite number")
    if "rounds" in out and out["rounds"] is not None:
        out["rounds"] = check_int(
            out["rounds"], "rounds", low=1, what="a positive integer number of communication rounds"
        )
    if "K" in out and out["K"] is not None:
        out["K"] = as_array(out["K"], "K", shape=(dynamics.p, dynamics.q))
    if "Q" in out and out["Q"] is not None:
        out["Q"] = as_array(out["Q"], "Q", shape=(dynamics.q, dynamics.q))
    return out


def make_law(
    law: str,
    part: Partition,
    dynamics: LinearDynamics,
    dt: float,
    **params: Any,
) -> FollowerLaw:
    """Build a follower law by name (see ``LAWS``) with its parameters.

    Parameters by law: ``stationary``: gain (1/s, default 1); ``linear`` and
    ``linear_paper``: eps, K, Q; ``dynamic``: K, gain, Q; ``dynamic_distributed``:
    rounds (default 1), K, gain, Q. Unknown parameters are refused.
    """
    if not isinstance(law, str):
        raise TypeError(f"law must be a law name (str), one of {', '.join(LAWS)}; got {type(law).__name__}")
    if not isinstance(part, Partition):
        raise TypeError(f"part must be a Partition, got {type(part).__name__}")
    check_dynamics(dynamics)
    dt = check_dt(dt)
    allowed = {
        "stationary": {"gain"},
        "linear": {"eps", "K", "Q"},
        "linear_paper": {"eps", "K", "Q"},
        "dynamic": {"K", "gain", "Q"},
        "dynamic_distributed": {"K", "gain", "Q", "rounds"},
    }
    if law not in allowed:
        raise FormationError(f"unknown law {law!r}; choose one of {', '.join(LAWS)}")
    extra = set(params) - allowed[law]
    if extra:
        raise TypeError(f"law {law!r} got unexpected parameter(s): {', '.join(sorted(extra))}")
    params = _check_law_params(params, dynamics)
    if law == "stationary":
        if not dynamics.is_single_integrator:
            raise FormationError(
                f"the stationary law (eq. 17) is for single integrators, got {dynamics.name} dynamics; "
                "use law='linear' (Riccati gain) or law='dynamic' for general linear agents"
            )
        gain = float(params.get("gain", 1.0))
        if not (np.isfinite(gain) and gain > 0):
            raise FormationError(f"gain must be positive and finite, got {gain}")
        return StressFeedbackLaw(part, dynamics, dt, K=-gain * np.eye(dynamics.q), eps=1.0, name="stationary")
    if law == "linear":
        return StressFeedbackLaw(part, dynamics, dt, name="linear", **params)
    if law == "linear_paper":
        return PaperLinearLaw(part, dynamics, dt, name="linear_paper", **params)
    if law == "dynamic":
        return DynamicLeaderLaw(part, dynamics, dt, **params)
    return DynamicLeaderLaw(part, dynamics, dt, rounds=params.pop("rounds", 1), **params)
