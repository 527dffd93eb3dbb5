"""``simulate``: run a follower law on a stress matrix for a number of samples."""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Literal, overload

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .analysis import require_stable
from .dynamics import LinearDynamics, c2d_zoh, check_dynamics
from .errors import ControlDimension, LawAssumptionWarning, ReachabilityWarning, StabilityWarning
from .laws import FollowerLaw, make_law
from .network import Network, NetworkLoop, check_network, check_network_law
from .stress import DEFAULT_RTOL, Partition, check_partition
from .validation import as_array, check_bool, check_dt, check_int, check_rtol, check_seed

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
        dt: sampling period (s) (the nominal one under jitter).
        network: the communication network simulated (None: perfect).
        periods: with a network, the period of each sample (s), shape (steps,).
        delivered: with a network, which links delivered at each sample, shape (steps, m), links in the
            order of :func:`~formation_env.core.network.network_links`.
    """

    positions: Array
    states: Array
    inputs: Array
    targets: Array
    errors: Array
    law: FollowerLaw
    dt: float
    network: Network | None = None
    periods: Array | None = None
    delivered: NDArray[np.bool_] | None = None

    @property
    def times(self) -> Array:
        """Sample times (s), shape (steps + 1,)."""
        if self.periods is not None:
            return np.concatenate([[0.0], np.cumsum(self.periods)])
        return np.arange(self.positions.shape[0], dtype=np.float64) * self.dt


class _PathStates:
    """Leader states from a leader path through the dynamics' output matrix C (any state order).

    Positions p (n_l, d) become x = C^+ p + N z, N a basis of null(C), with z the
    least-squares fit of the position rate C A x (continuous A) to the forward difference
    (p(k) - p(k-1)) / T (zero at k = 0: at rest). For [p, v] double integrators this is the
    forward-difference velocity; for single integrators x = p. Full states (n_l, q) are used
    as given.
    """

    def __init__(self, dyn: LinearDynamics, n_l: int, dt: float) -> None:
        self.dyn, self.n_l, self.dt = dyn, n_l, dt
        c = dyn.C
        self.c_pinv = np.linalg.pinv(c)  # (q, d)
        _, s, vt = np.linalg.svd(c)
        rank = int(np.sum(s > 1e-12 * max(s[0], 1.0)))
        self.null = vt[rank:].T  # (q, q - rank)
        ca = c @ dyn.A
        self.ca = ca
        self.fit = None if self.null.shape[1] == 0 else np.linalg.pinv(ca @ self.null)  # (q - r, d)

    def __call__(self, value: ArrayLike, k: int, prev_pos: Array | None) -> tuple[Array, bool]:
        """(states (n_l, q), True if the path gave positions)."""
        dyn, n_l = self.dyn, self.n_l
        v = as_array(value, f"leader_path({k})", ndim=2)
        if v.shape == (n_l, dyn.q) and dyn.q != dyn.d:
            return v, False
        if v.shape != (n_l, dyn.d):
            raise ControlDimension(
                f"leader_path({k}) must return shape ({n_l}, {dyn.d}) or ({n_l}, {dyn.q}) (leader positions or full "
                f"states), got {v.shape}"
            )
        x = v @ self.c_pinv.T
        if self.fit is not None:
            rate = np.zeros_like(v) if prev_pos is None else (v - prev_pos) / self.dt
            z = (rate - x @ self.ca.T) @ self.fit.T
            x = x + z @ self.null.T
        return x, True


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
    check: bool = ...,
    rtol: float = ...,
    network: Network | dict[str, Any] | None = ...,
    seed: int | None = ...,
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
    check: bool = ...,
    rtol: float = ...,
    network: Network | dict[str, Any] | None = ...,
    seed: int | None = ...,
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
    check: bool = True,
    rtol: float = DEFAULT_RTOL,
    network: Network | dict[str, Any] | None = None,
    seed: int | None = None,
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
            integrators), or k -> leader positions (n_l, d) or full states (n_l, q) at
            sample k. Positions are mapped to states through the dynamics' output
            matrix C, whatever the state order (x = C^+ p + N z, the unobserved part z
            fitted so that the rate C A x matches the forward difference of the path;
            at rest at k = 0). Leaders are placed on the path exactly; their input,
            fed forward to the dynamic laws, is the least-squares
            B_d^+ (x_l(k+1) - A_d x_l(k)). When that leaves a residual (no input
            reaches the next state) a :class:`ReachabilityWarning` gives the largest.
        dynamics: agent dynamics; default single integrators in R^d.
        require_stable_law: raise ``UnstableParameterError`` instead of warning when the
            closed loop is not Schur.
        return_result: return a :class:`SimResult` instead of the positions.
        check: validate omega (:func:`~formation_env.core.stress.check_partition`: symmetric,
            zero row sums, Omega_ff positive definite) at ``rtol``; ``check=False`` skips it.
        rtol: relative tolerance of that check (``1e-3`` accepts a rounded matrix such as the paper's printed
            one, ``paper_omega(exact=False)``).
        network: a :class:`~formation_env.core.network.Network` (or its dict form): delay, packet loss,
            jitter and quantisation between the agents (laws ``stationary`` and ``linear``; the others
            are refused with the reason). None: the perfect network, exactly the loop above.
            Under jitter ``dt`` is the nominal period the law is designed for, and a ``leader_path``
            is read per sample index.
        seed: seeds ``np.random.default_rng`` for the network's draws (required when it draws: loss or
            jitter); the same seed gives the same losses and periods.
        **params: law parameters (gain, eps, K, Q, rounds), see ``make_law``.

    Returns:
        Positions, shape (steps + 1, n, d) (or a :class:`SimResult`).

    Warns:
        StabilityWarning: the chosen dt (or eps) makes the closed loop unstable; the
            message gives the spectral radius.
        ReachabilityWarning: the leader path is not reachable by the dynamics (residual given).
        LawAssumptionWarning: ``linear`` with non-integrator dynamics (A != 0) while the leaders
            are steered off their free trajectories (u_l != 0): it then keeps a tracking error.
    """
    part = Partition(omega, leaders)
    rtol = check_rtol(rtol)
    if check_bool(check, "check"):
        check_partition(part, rtol)
    x = as_array(x0, "x0", ndim=2)
    dt = check_dt(dt)
    steps = check_int(steps, "steps", low=0, what="a non-negative integer number of samples")
    if dynamics is not None:
        check_dynamics(dynamics)
    if leader_path is not None and not callable(leader_path):
        raise TypeError(
            f"leader_path must be None or a callable k -> leader positions, got {type(leader_path).__name__}"
        )
    require_stable_law = check_bool(require_stable_law, "require_stable_law")
    return_result = check_bool(return_result, "return_result")
    n = part.n
    if x.shape[0] != n:
        raise ControlDimension(f"x0 must have one row per agent ({n}), got shape {x.shape}")
    dyn = dynamics if dynamics is not None else LinearDynamics.single_integrator(x.shape[1])
    if x.shape[1] == dyn.d and dyn.q != dyn.d:
        x = dyn.state_from_position(x)
    if x.shape[1] != dyn.q:
        raise ControlDimension(f"x0 must have shape ({n}, {dyn.d}) or ({n}, {dyn.q}) for {dyn.name}, got {x.shape}")
    net = check_network(network)
    if seed is not None:
        seed = check_seed(seed)
    the_law = make_law(law, part, dyn, dt, **params)
    if net is not None:
        check_network_law(law)
        if net.random and seed is None:
            raise TypeError(
                "seed must be given (a non-negative integer) when the network draws random losses or periods; "
                "the same seed gives the same draws"
            )
        return _simulate_network(
            part, dyn, x, the_law, net, seed, steps, leader_path, require_stable_law, return_result
        )
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
    unreach = np.eye(dyn.q) - b_d @ b_pinv  # projector onto what no input reaches
    n_l = part.n_l
    states = np.empty((steps + 1, n, dyn.q))
    inputs = np.zeros((steps, n, dyn.p))
    states[0] = x
    memory = the_law.initial_memory()
    path = _PathStates(dyn, n_l, dt) if leader_path is not None else None
    prev_pos = None
    if path is not None and leader_path is not None:
        xl0, _ = path(leader_path(0), 0, None)
        states[0, part.leaders] = xl0
        prev_pos = dyn.position(xl0)
    worst_res, worst_k, scale, u_max = 0.0, -1, 1.0, 0.0
    for k in range(steps):
        xk = states[k]
        if path is None or leader_path is None:
            u_l = np.zeros((n_l, dyn.p))
            xl_next = None
        else:
            xl_next, _ = path(leader_path(k + 1), k + 1, prev_pos)
            prev_pos = dyn.position(xl_next)
            step = xl_next - xk[part.leaders] @ a_d.T
            u_l = step @ b_pinv.T
            res = float(np.max(np.abs(step @ unreach.T))) if step.size else 0.0
            scale = max(scale, float(np.max(np.abs(xl_next))))
            if res > worst_res:
                worst_res, worst_k = res, k
            u_max = max(u_max, float(np.max(np.abs(u_l))))
        states[k + 1], memory = the_law.step(xk, u_l, memory)
        if xl_next is not None:
            states[k + 1, part.leaders] = xl_next
        inputs[k, part.leaders] = u_l
        inputs[k, part.followers] = (states[k + 1, part.followers] - xk[part.followers] @ a_d.T) @ b_pinv.T
    if worst_res > 1e-9 * scale:
        warnings.warn(
            f"leader_path is not reachable by the {dyn.name} dynamics: no input moves the leaders from x_l(k) to "
            f"x_l(k+1); largest residual |(I - B_d B_d^+)(x_l(k+1) - A_d x_l(k))| = {worst_res:.3g} at k = "
            f"{worst_k}. The leaders are put on the path anyway (a jump the followers' law does not see); pass full "
            f"leader states ({n_l}, {dyn.q}) that obey x(k+1) = A_d x(k) + B_d u(k)",
            ReachabilityWarning,
            stacklevel=2,
        )
    if law == "linear" and np.any(dyn.A) and u_max > 1e-12 * scale:
        warnings.warn(
            f"law linear with {dyn.name} dynamics (A != 0): the leaders leave their free trajectories "
            f"x_l(k+1) = A_d x_l(k) (largest leader input |u_l| = {u_max:.3g}), so the followers keep a tracking "
            "error; the linear law tracks the affine targets only for u_l = 0; use law='dynamic'",
            LawAssumptionWarning,
            stacklevel=2,
        )
    return _result(part, dyn, states, inputs, the_law, dt, return_result)


def _result(
    part: Partition,
    dyn: LinearDynamics,
    states: Array,
    inputs: Array,
    the_law: FollowerLaw,
    dt: float,
    return_result: bool,
    **network: Any,
) -> Array | SimResult:
    """The positions of a run's ``states`` (steps + 1, n, state), or its :class:`SimResult` with the followers'
    targets and errors (``network``: the result's network fields)."""
    positions = dyn.position(states)
    if not return_result:
        return positions
    tgt_states = part.targets(states[:, part.leaders])
    with np.errstate(over="ignore", invalid="ignore"):  # a diverging run was already warned about
        err = np.linalg.norm((states[:, part.followers] - tgt_states).reshape(len(states), -1), axis=1)
    return SimResult(
        positions=positions,
        states=states,
        inputs=inputs,
        targets=dyn.position(tgt_states),
        errors=err,
        law=the_law,
        dt=float(dt),
        **network,
    )


def _simulate_network(
    part: Partition,
    dyn: LinearDynamics,
    x: Array,
    the_law: FollowerLaw,
    net: Network,
    seed: int | None,
    steps: int,
    leader_path: Callable[[int], ArrayLike] | None,
    require_stable_law: bool,
    return_result: bool,
) -> Array | SimResult:
    """``simulate`` over a network: the :class:`NetworkLoop` step, the draws of :meth:`Network.draw`."""
    from .analysis import network_stability

    dt = the_law.dt
    G = the_law.eps * the_law.K  # type: ignore[attr-defined]
    rho = network_stability(part, dyn, dt, G, net)
    if rho is not None and rho >= 1.0:
        msg = (
            f"law {the_law.name} at T = {dt:g} s over {net} is unstable (decay factor per sample {rho:.6g} >= 1); "
            "see stability_report(..., network=)"
        )
        if require_stable_law:
            from .errors import UnstableParameterError

            raise UnstableParameterError(msg)
        warnings.warn(msg, StabilityWarning, stacklevel=3)
    loop = NetworkLoop(part, G, net)
    rng = np.random.default_rng(seed) if net.random else None
    n, n_l = part.n, part.n_l
    states = np.empty((steps + 1, n, dyn.q))
    inputs = np.zeros((steps, n, dyn.p))
    periods = np.empty(steps)
    delivered = np.ones((steps, loop.m), dtype=bool)
    path = _PathStates(dyn, n_l, dt) if leader_path is not None else None
    prev_pos = None
    if path is not None:
        xl0, _ = path(leader_path(0), 0, None)  # type: ignore[misc]
        x = x.copy()
        x[part.leaders] = xl0
        prev_pos = dyn.position(xl0)
    states[0] = x
    st = loop.initial_state(x)
    eye_q = np.eye(dyn.q)
    for k in range(steps):
        if rng is not None:
            t_k, delivered[k] = net.draw(rng, dt, loop.m)
        else:
            t_k = dt
        periods[k] = t_k
        if net.jitter is None or dyn.discrete:
            a_d, b_d = dyn.zoh(t_k)
        elif not np.any(dyn.A):  # integrators: exp(0) = I, B_d = T B, no matrix exponential per sample
            a_d, b_d = eye_q, t_k * dyn.B
        else:
            a_d, b_d = c2d_zoh(dyn.A, dyn.B, t_k)
        if path is None:
            u_l = np.zeros((n_l, dyn.p))
            xl_next = None
        else:
            xl_next, _ = path(leader_path(k + 1), k + 1, prev_pos)  # type: ignore[misc]
            prev_pos = dyn.position(xl_next)
            u_l = (xl_next - st.x[part.leaders] @ a_d.T) @ np.linalg.pinv(b_d).T
        st, u_f = loop.step(st, delivered[k], a_d, b_d, u_l)
        if xl_next is not None:
            st.x[part.leaders] = xl_next
        states[k + 1] = st.x
        inputs[k, part.leaders] = u_l
        inputs[k, part.followers] = u_f
    return _result(part, dyn, states, inputs, the_law, dt, return_result, network=net, periods=periods,
                   delivered=delivered)  # fmt: skip
