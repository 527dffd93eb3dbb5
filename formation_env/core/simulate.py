"""``simulate``: run a follower law on a stress matrix for a number of samples."""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Literal, overload

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .analysis import require_stable
from .dynamics import LinearDynamics
from .errors import ControlDimension, FormationError, StabilityWarning
from .laws import FollowerLaw, make_law
from .stress import Partition
from .validation import as_array

__all__ = ["SimResult", "simulate"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class SimResult:
    """Everything a simulation produced.

    Attributes:
        positions: agent positions, shape (steps + 1, n, d), m.
        states: agent states, shape (steps + 1, n, q).
        inputs: inputs applied at each sample, shape (steps, n, p).
        targets: follower targets -Omega_ff^-1 Omega_fl x_l (positions), shape (steps + 1, n_f, d).
        errors: follower tracking error ||x_f - x_f*|| over all followers (state), shape (steps + 1,).
        law: the law object, for its analysis (``law.spectral_radius()``).
        dt: sampling period (s).
    """

    positions: Array
    states: Array
    inputs: Array
    targets: Array
    errors: Array
    law: FollowerLaw
    dt: float

    @property
    def times(self) -> Array:
        """Sample times (s), shape (steps + 1,)."""
        return np.arange(self.positions.shape[0], dtype=np.float64) * self.dt


def _leader_states(value: ArrayLike, n_l: int, dyn: LinearDynamics, k: int) -> Array:
    v = as_array(value, f"leader_path({k})", ndim=2)
    if v.shape == (n_l, dyn.q):
        return v
    if v.shape == (n_l, dyn.d):
        return dyn.state_from_position(v)
    raise ControlDimension(f"leader_path({k}) must return shape ({n_l}, {dyn.d}) or ({n_l}, {dyn.q}), got {v.shape}")


@overload
def simulate(
    omega: Any,
    leaders: Sequence[int],
    x0: ArrayLike,
    dt: float = ...,
    steps: int = ...,
    law: str = ...,
    leader_path: Callable[[int], ArrayLike] | None = ...,
    dynamics: LinearDynamics | None = ...,
    *,
    require_stable_law: bool = ...,
    return_result: Literal[False] = ...,
    **params: Any,
) -> Array: ...


@overload
def simulate(
    omega: Any,
    leaders: Sequence[int],
    x0: ArrayLike,
    dt: float = ...,
    steps: int = ...,
    law: str = ...,
    leader_path: Callable[[int], ArrayLike] | None = ...,
    dynamics: LinearDynamics | None = ...,
    *,
    require_stable_law: bool = ...,
    return_result: Literal[True],
    **params: Any,
) -> SimResult: ...


def simulate(
    omega: Any,
    leaders: Sequence[int],
    x0: ArrayLike,
    dt: float = 1.0,
    steps: int = 180,
    law: str = "stationary",
    leader_path: Callable[[int], ArrayLike] | None = None,
    dynamics: LinearDynamics | None = None,
    *,
    require_stable_law: bool = False,
    return_result: bool = False,
    **params: Any,
) -> Array | SimResult:
    """Simulate n agents under a follower law for ``steps`` samples of ``dt`` seconds.

    Args:
        omega: stress matrix, shape (n, n), dense or sparse.
        leaders: leader indices (n_l >= d + 1).
        x0: initial positions (n, d) (states at rest), or full states (n, q).
        dt: sampling period T (s).
        steps: number of samples.
        law: ``stationary`` | ``dynamic`` | ``dynamic_distributed`` | ``linear`` | ``linear_paper``.
        leader_path: None (leaders follow x_l(k+1) = A_d x_l: they stay for single
            integrators), or k -> leader positions (n_l, d) or states (n_l, q) at
            sample k. Leaders are placed on the path exactly; for positions with
            higher-order dynamics the velocity is the forward difference. Their
            input, fed forward to the dynamic laws, is the least-squares
            B_d^+ (x_l(k+1) - A_d x_l(k)).
        dynamics: agent dynamics; default single integrators in R^d.
        require_stable_law: raise ``UnstableParameterError`` instead of warning when the
            closed loop is not Schur.
        return_result: return a :class:`SimResult` instead of the positions.
        **params: law parameters (gain, eps, K, Q, rounds), see ``make_law``.

    Returns:
        Positions, shape (steps + 1, n, d) (or a :class:`SimResult`).

    Warns:
        StabilityWarning: the chosen dt (or eps) makes the closed loop unstable; the
            message gives the spectral radius.
    """
    x = as_array(x0, "x0", ndim=2)
    part = Partition(omega, leaders)
    n = part.n
    if x.shape[0] != n:
        raise ControlDimension(f"x0 must have one row per agent ({n}), got shape {x.shape}")
    dyn = dynamics if dynamics is not None else LinearDynamics.single_integrator(x.shape[1])
    if x.shape[1] == dyn.d and dyn.q != dyn.d:
        x = dyn.state_from_position(x)
    if x.shape[1] != dyn.q:
        raise ControlDimension(f"x0 must have shape ({n}, {dyn.d}) or ({n}, {dyn.q}) for {dyn.name}, got {x.shape}")
    if int(steps) != steps or steps < 0:
        raise FormationError(f"steps must be a non-negative integer, got {steps}")
    the_law = make_law(law, part, dyn, dt, **params)
    if not the_law.tracks_targets:
        warnings.warn(
            f"law {law} is the paper's literal eq. 25, kept for comparison: it does not converge to the affine "
            "targets (use law='linear')",
            StabilityWarning,
            stacklevel=2,
        )
    else:
        if require_stable_law:
            require_stable(the_law)
        elif n <= 3000 or law in ("dynamic", "dynamic_distributed"):
            rho = the_law.spectral_radius()
            if rho >= 1.0:
                warnings.warn(
                    f"law {law} at T = {dt:g} s is unstable (closed-loop spectral radius {rho:.6g} >= 1); "
                    "see stability_report() for the admissible range",
                    StabilityWarning,
                    stacklevel=2,
                )
    a_d, b_d = the_law.A_d, the_law.B_d
    b_pinv = np.linalg.pinv(b_d)
    n_l = part.n_l
    steps = int(steps)
    states = np.empty((steps + 1, n, dyn.q))
    inputs = np.zeros((steps, n, dyn.p))
    states[0] = x
    memory = the_law.initial_memory()
    nxt = _leader_states(leader_path(0), n_l, dyn, 0) if leader_path is not None else None
    if nxt is not None:
        states[0, part.leaders] = nxt
    for k in range(steps):
        xk = states[k]
        if leader_path is None:
            u_l = np.zeros((n_l, dyn.p))
            xl_next = None
        else:
            pos_next = leader_path(k + 1)
            xl_next = _leader_states(pos_next, n_l, dyn, k + 1)
            if dyn.q != dyn.d and np.shape(pos_next)[-1] == dyn.d:
                xl_next = _finite_difference_state(dyn, xk[part.leaders], xl_next @ dyn.C.T, dt)
            u_l = (xl_next - xk[part.leaders] @ a_d.T) @ b_pinv.T
        states[k + 1], memory = the_law.step(xk, u_l, memory)
        if xl_next is not None:
            states[k + 1, part.leaders] = xl_next
        inputs[k, part.leaders] = u_l
        inputs[k, part.followers] = (states[k + 1, part.followers] - xk[part.followers] @ a_d.T) @ b_pinv.T
    positions = dyn.position(states)
    if not return_result:
        return positions
    tgt_states = part.targets(states[:, part.leaders])
    with np.errstate(over="ignore", invalid="ignore"):  # a diverging run was already warned about
        err = np.linalg.norm((states[:, part.followers] - tgt_states).reshape(steps + 1, -1), axis=1)
    return SimResult(
        positions=positions,
        states=states,
        inputs=inputs,
        targets=dyn.position(tgt_states),
        errors=err,
        law=the_law,
        dt=float(dt),
    )


def _finite_difference_state(dyn: LinearDynamics, cur: Array, pos_next: Array, dt: float) -> Array:
    """Leader state at k+1 from its next position: position set, velocity = forward difference (double integrator)."""
    out = dyn.state_from_position(pos_next)
    d = dyn.d
    if dyn.q == 2 * d:
        out[:, d:] = (pos_next - dyn.position(cur)) / dt
    return out
