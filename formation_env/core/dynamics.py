"""Agent dynamics: one ``LinearDynamics`` for single, double and general linear agents.

Each agent has state x_i in R^q, input u_i in R^p and position C x_i in R^d.
Continuous models xdot = A x + B u are sampled exactly with a zero-order hold
(inputs held over each sampling period T, paper Section 3 preamble):
A_d = exp(A T), B_d = int_0^T exp(A s) ds B. The paper's single integrator
x(k+1) = x(k) + T u(k) (eq. 16) is the ZOH of xdot = u.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np
import scipy.linalg as sla
from numpy.typing import ArrayLike, NDArray

from .errors import ControlDimension, FormationError
from .validation import _describe, as_array, check_bool, check_dt, check_int, check_shape

__all__ = ["LinearDynamics", "c2d_zoh", "dare", "dlqr", "riccati_gain"]


def c2d_zoh(A: ArrayLike, B: ArrayLike, dt: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Exact zero-order-hold discretisation of xdot = A x + B u with period ``dt`` (s).

    Uses the matrix exponential of [[A, B], [0, 0]] * dt, whose top blocks are
    (A_d, B_d). Agrees with ``scipy.signal.cont2discrete(..., method="zoh")``.

    Returns:
        (A_d, B_d) of shapes (q, q) and (q, p).
    """
    a = as_array(A, "A", ndim=2)
    b = as_array(B, "B", ndim=2)
    q = a.shape[0]
    check_shape(a, (q, q), "A")
    check_shape(b, (q, None), "B")
    dt = check_dt(dt)
    p = b.shape[1]
    m = np.zeros((q + p, q + p))
    m[:q, :q] = a
    m[:q, q:] = b
    e = sla.expm(m * dt)
    return e[:q, :q], e[:q, q:]


@dataclass(frozen=True, eq=False)
class LinearDynamics:
    """Linear time-invariant agent dynamics, identical for every agent.

    Attributes:
        A: state matrix, shape (q, q). Continuous-time unless ``discrete``.
        B: input matrix, shape (q, p).
        C: position output matrix, shape (d, q): the agent's position is C x_i.
        discrete: if True, (A, B) already are the sampled model x(k+1) = A x + B u
            and ``dt`` is ignored by :meth:`zoh` (apart from being recorded).
        name: label used in reports.

    Use :meth:`single_integrator` and :meth:`double_integrator` for the common cases.
    """

    A: NDArray[np.float64]
    B: NDArray[np.float64]
    C: NDArray[np.float64]
    discrete: bool = False
    name: str = "linear"

    def __init__(
        self,
        A: ArrayLike,
        B: ArrayLike,
        C: ArrayLike | None = None,
        discrete: bool = False,
        name: str = "linear",
    ) -> None:
        a = as_array(A, "A", ndim=2)
        q = a.shape[0]
        if q == 0:
            raise ControlDimension("A must be a non-empty square matrix (q >= 1 states), got shape (0, 0)")
        check_shape(a, (q, q), "A")
        b = as_array(B, "B", ndim=2)
        check_shape(b, (q, None), "B")
        if b.shape[1] == 0:
            raise ControlDimension(f"B must have at least one input column, got shape {b.shape}")
        if not isinstance(name, str):
            raise TypeError(f"name must be a string, got {type(name).__name__}")
        discrete = check_bool(discrete, "discrete")
        if np.linalg.matrix_rank(b) < b.shape[1]:
            raise FormationError(f"B must have full column rank ({b.shape[1]}), got rank {np.linalg.matrix_rank(b)}")
        c = np.eye(q) if C is None else as_array(C, "C", ndim=2)
        check_shape(c, (None, q), "C")
        if c.shape[0] == 0 or np.linalg.matrix_rank(c) < c.shape[0]:
            raise FormationError(
                f"C must have full row rank (d = {c.shape[0]} >= 1 independent position outputs), got shape "
                f"{c.shape} and rank {np.linalg.matrix_rank(c) if c.size else 0}"
            )
        for name_, arr in (("A", a), ("B", b), ("C", c)):
            arr = arr.copy()
            arr.setflags(write=False)
            object.__setattr__(self, name_, arr)
        object.__setattr__(self, "discrete", bool(discrete))
        object.__setattr__(self, "name", name)

    # ------------------------------------------------------------------ constructors
    @classmethod
    def single_integrator(cls, d: int = 2) -> LinearDynamics:
        """xdot = u in R^d: state = position, input = velocity (m/s)."""
        d = check_int(d, "d", low=1)
        return cls(np.zeros((d, d)), np.eye(d), np.eye(d), name="single_integrator")

    @classmethod
    def double_integrator(cls, d: int = 2) -> LinearDynamics:
        """pdot = v, vdot = u in R^d: state [p, v] (q = 2d), input = acceleration (m/s^2)."""
        d = check_int(d, "d", low=1)
        a = np.zeros((2 * d, 2 * d))
        a[:d, d:] = np.eye(d)
        b = np.zeros((2 * d, d))
        b[d:, :] = np.eye(d)
        c = np.hstack([np.eye(d), np.zeros((d, d))])
        return cls(a, b, c, name="double_integrator")

    # ------------------------------------------------------------------ properties
    @property
    def q(self) -> int:
        """State dimension per agent."""
        return int(self.A.shape[0])

    @property
    def p(self) -> int:
        """Input dimension per agent."""
        return int(self.B.shape[1])

    @property
    def d(self) -> int:
        """Position dimension per agent."""
        return int(self.C.shape[0])

    @property
    def is_single_integrator(self) -> bool:
        """True for xdot = u with state = position (the paper's Section 4 agents)."""
        return (
            not self.discrete
            and self.q == self.p == self.d
            and not np.any(self.A)
            and np.array_equal(self.B, np.eye(self.q))
            and np.array_equal(self.C, np.eye(self.q))
        )

    def zoh(self, dt: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Sampled model (A_d, B_d) for period ``dt`` (s); cached."""
        dt = check_dt(dt)
        if self.discrete:
            return self.A, self.B
        return _zoh_cached(self, dt)

    def position(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """Positions C x_i of states x, shape (..., q) -> (..., d)."""
        return x @ self.C.T

    def state_from_position(self, pos: ArrayLike) -> NDArray[np.float64]:
        """States at rest at the given positions: x with C x = pos, other coordinates 0.

        Args:
            pos: shape (..., d). Returns shape (..., q).
        """
        p = as_array(pos, "pos")
        if p.ndim == 0 or p.shape[-1] != self.d:
            raise ControlDimension(f"pos must have shape (..., d) with d = {self.d}, got {p.shape}")
        return p @ np.linalg.pinv(self.C).T

    def step(self, x: NDArray[np.float64], u: NDArray[np.float64], dt: float) -> NDArray[np.float64]:
        """One sampled step x(k+1) = A_d x + B_d u, batched: x (..., q), u (..., p)."""
        ad, bd = self.zoh(dt)
        return x @ ad.T + u @ bd.T


def _check_spd(m: NDArray[np.float64], name: str) -> None:
    """Raise FormationError unless ``m`` is symmetric positive definite."""
    scale = float(np.max(np.abs(m))) if m.size else 0.0
    if np.max(np.abs(m - m.T)) > 1e-10 * max(scale, 1.0):
        raise FormationError(
            f"{name} must be symmetric positive definite, got max |{name} - {name}^T| = {np.max(np.abs(m - m.T)):.3g}"
        )
    lo = float(np.min(np.linalg.eigvalsh(m)))
    if lo <= 0:
        raise FormationError(f"{name} must be symmetric positive definite, got smallest eigenvalue {lo:.3g}")


@lru_cache(maxsize=64)
def _zoh_cached(dyn: LinearDynamics, dt: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    ad, bd = c2d_zoh(dyn.A, dyn.B, dt)
    ad.setflags(write=False)
    bd.setflags(write=False)
    return ad, bd


def dare(A: ArrayLike, B: ArrayLike, Q: ArrayLike | None = None, R: ArrayLike | None = None) -> NDArray[np.float64]:
    """Stabilising solution P of the discrete algebraic Riccati equation.

    With ``R`` given: A'PA - P - A'PB (R + B'PB)^-1 B'PA + Q = 0 (standard DARE).
    With ``R=None``: the paper's modified Riccati equation (Theorem 3),
    A'PA - P - A'PB (B'PB)^-1 B'PA + Q = 0, i.e. the cheap-control limit R = 0,
    which needs B of full column rank. ``Q`` defaults to the identity.

    The answer is verified: a residual above 1e-8 relative raises.
    """
    a = as_array(A, "A", ndim=2)
    b = as_array(B, "B", ndim=2)
    q = a.shape[0]
    check_shape(a, (q, q), "A")
    check_shape(b, (q, None), "B")
    p = b.shape[1]
    qm = np.eye(q) if Q is None else as_array(Q, "Q", ndim=2)
    check_shape(qm, (q, q), "Q")
    _check_spd(qm, "Q")
    if np.linalg.matrix_rank(b) < p:
        raise FormationError(f"B must have full column rank {p} for the Riccati gain")
    rm = np.zeros((p, p)) if R is None else as_array(R, "R", ndim=2)
    check_shape(rm, (p, p), "R")
    if R is not None:
        _check_spd(rm, "R")
    try:
        P = sla.solve_discrete_are(a, b, qm, rm)
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise FormationError(
            f"the Riccati equation has no stabilising solution ((A, B) not stabilisable?): {exc}"
        ) from exc
    P = (P + P.T) / 2
    g = rm + b.T @ P @ b
    res = a.T @ P @ a - P - a.T @ P @ b @ np.linalg.solve(g, b.T @ P @ a) + qm
    if np.max(np.abs(res)) > 1e-8 * max(1.0, float(np.max(np.abs(P)))):
        raise FormationError(f"the Riccati solution failed its residual check ({np.max(np.abs(res)):.3g})")
    return P


def riccati_gain(
    A: ArrayLike, B: ArrayLike, Q: ArrayLike | None = None, R: ArrayLike | None = None
) -> NDArray[np.float64]:
    """Gain K = -(R + B'PB)^-1 B'PA of :func:`dare` (R = None: the paper's K, Theorem 3), shape (p, q)."""
    a = as_array(A, "A", ndim=2)
    b = as_array(B, "B", ndim=2)
    P = dare(a, b, Q, R)
    p = b.shape[1]
    rm = np.zeros((p, p)) if R is None else as_array(R, "R", ndim=2)
    return np.asarray(-np.linalg.solve(rm + b.T @ P @ b, b.T @ P @ a), dtype=np.float64)


def dlqr(
    A: ArrayLike, B: ArrayLike, Q: ArrayLike, R: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.complex128]]:
    """Discrete LQR as python-control: returns (K, P, E) for u = -K x, E the closed-loop eigenvalues.

    Args:
        A: (q, q), B: (q, p), Q: (q, q) symmetric positive definite, R: (p, p) symmetric
            positive definite (required: for the paper's cheap-control gain use :func:`riccati_gain`).
    """
    if Q is None:
        raise TypeError("dlqr() needs Q, the (q, q) state weight (symmetric positive definite), got None")
    if R is None:
        raise TypeError(
            "dlqr() needs R, the (p, p) input weight (symmetric positive definite), got None; "
            "for the cheap-control limit R = 0 of Theorem 3 use riccati_gain(A, B, Q)"
        )
    a = as_array(A, "A", ndim=2)
    b = as_array(B, "B", ndim=2)
    P = dare(a, b, Q, R)
    K = np.linalg.solve(as_array(R, "R", ndim=2) + b.T @ P @ b, b.T @ P @ a)
    return np.asarray(K, dtype=np.float64), P, np.asarray(np.linalg.eigvals(a - b @ K), dtype=np.complex128)


def check_dynamics(dyn: Any, name: str = "dynamics") -> Any:
    """A :class:`~formation_env.core.dynamics.LinearDynamics` (None is not accepted here)."""
    if not isinstance(dyn, LinearDynamics):
        raise TypeError(f"{name} must be a LinearDynamics, got {_describe(dyn)}")
    return dyn
