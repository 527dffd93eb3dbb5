"""The follower laws against their theory: Theorems 1-3, the mode decomposition, and measured decay.

Every law's follower error obeys a linear recursion z(k+1) = M z(k) (``closed_loop()``), which
decouples into small per-mode matrices (``mode_matrices()``) whose spectral radius is the
closed loop's and is what ``stability_report`` reports. The tests check each link: the
simulated error equals M^k z(0), rho(M) equals the modes' rho, and the measured decay (or
growth) of the error matches rho per step; plus the stability bounds of Theorems 1 and 2, just
inside and just outside, measured in simulation.
"""

from __future__ import annotations

import math
import warnings
from typing import Any

import numpy as np
import pytest
import scipy.sparse as sp
from conftest import RandomFramework, random_framework, random_frameworks
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from formation_env.core import (
    LinearDynamics,
    Partition,
    SimResult,
    StabilityWarning,
    make_law,
    paper_omega,
    rotate,
    scale,
    simulate,
    stability_report,
)
from formation_env.core.laws import DynamicLeaderLaw, FollowerLaw

PAPER_LEADERS = [0, 1, 2]
PAPER_X0 = np.array([[1.0, 0.0], [0.0, 1.0], [0.0, -1.0], [-4.0, 3.0], [-3.0, -2.0]])

# (law, dynamics, params). "single"/"double": single or double integrators in R^d.
CASES = {
    "stationary": ("stationary", "single", {}),
    "dynamic-single": ("dynamic", "single", {}),
    "dynamic-double": ("dynamic", "double", {}),
    "distributed1-single": ("dynamic_distributed", "single", {"rounds": 1}),
    "distributed2-single": ("dynamic_distributed", "single", {"rounds": 2}),
    "distributed3-single": ("dynamic_distributed", "single", {"rounds": 3}),
    "distributed2-double": ("dynamic_distributed", "double", {"rounds": 2}),
    "linear-single": ("linear", "single", {}),
    "linear-double": ("linear", "double", {}),
}
ALL_CASES = {**CASES, "linear_paper-double": ("linear_paper", "double", {})}


def _dynamics(kind: str, d: int) -> LinearDynamics:
    return LinearDynamics.single_integrator(d) if kind == "single" else LinearDynamics.double_integrator(d)


def _random_start(rng: np.random.Generator, fw_n: int, dyn: LinearDynamics, leaders: list[int]) -> np.ndarray:
    """Random full states; leaders at rest (zero velocity), so they are stationary."""
    x0 = rng.normal(size=(fw_n, dyn.q))
    x0[np.ix_(leaders, range(dyn.d, dyn.q))] = 0.0
    return x0


def _run(omega: Any, leaders, x0, dt, steps, law, dyn, **params) -> SimResult:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", StabilityWarning)  # unstable runs are asked for on purpose
        res = simulate(omega, leaders, x0, dt, steps, law, dynamics=dyn, return_result=True, **params)
    assert isinstance(res, SimResult)
    return res


def _state_errors(res: SimResult, part: Partition) -> np.ndarray:
    """Follower state errors x_f - L x_l, shape (steps + 1, n_f, q)."""
    return res.states[:, part.followers] - part.targets(res.states[:, part.leaders])


def _log_rate(errors: np.ndarray, growing: bool, start: float = 1e-7) -> float:
    """Measured log error change per step, fitted on a late window.

    Decaying runs: the window where the error has fallen from ``start`` to 1e-12 of its
    first value (after the transients of the other modes, before round-off at ~1e-16).
    Growing runs: from 1 / ``start`` / 100 to 1e12 times it.
    """
    e = errors / errors[0]
    inside = (e > 1e-2 / start) & (e < 1e12) if growing else (e < start) & (e > 1e-12)
    k = np.flatnonzero(inside)
    assert k.size >= 3, "the run did not reach the measurement window"
    k = np.arange(k[0], k[-1] + 1)
    return float(np.polyfit(k, np.log(e[k]), 1)[0])


# ---------------------------------------------------------------------- simulation == closed loop


def _closed_loop_trajectory(law: FollowerLaw, z0: np.ndarray, steps: int) -> np.ndarray:
    m = law.closed_loop()
    out = [z0]
    for _ in range(steps):
        out.append(m @ out[-1])
    return np.array(out)


@pytest.mark.parametrize("case", list(ALL_CASES))
@settings(max_examples=10, deadline=None)
@given(rf=random_frameworks(), seed=st.integers(0, 2**32 - 1), dt=st.floats(0.05, 2.5))
def test_simulated_error_is_the_closed_loop(case, rf: RandomFramework, seed, dt):
    law_name, kind, params = ALL_CASES[case]
    fw = rf.fw
    dyn = _dynamics(kind, fw.d)
    part = Partition(rf.omega, fw.leaders)
    rng = np.random.default_rng(seed)
    steps = 25
    res = _run(
        rf.omega, fw.leaders, _random_start(rng, fw.n, dyn, list(fw.leaders)), dt, steps, law_name, dyn, **params
    )
    law = res.law
    nf = part.n_f
    if law_name == "linear_paper":
        # Not an error recursion (the followers settle off target): increments obey x_f's own matrix.
        xf = res.states[:, part.followers].reshape(steps + 1, -1)
        actual = np.diff(xf, axis=0)
        predicted = _closed_loop_trajectory(law, actual[0], steps - 1)
    else:
        actual = _state_errors(res, part).reshape(steps + 1, -1)
        z0 = actual[0]
        if isinstance(law, DynamicLeaderLaw) and law.rounds is not None:
            z0 = np.concatenate([z0, np.zeros(nf * dyn.p)])  # the memory u(k-1) starts at zero
        predicted = _closed_loop_trajectory(law, z0, steps)[:, : actual.shape[1]]
    scale_ = np.maximum.accumulate(np.linalg.norm(predicted, axis=1)) + 1.0
    dev = np.linalg.norm(actual - predicted, axis=1)
    assert np.all(dev <= 1e-9 * scale_), (dev / scale_).max()


@pytest.mark.parametrize("case", list(ALL_CASES))
@settings(max_examples=10, deadline=None)
@given(rf=random_frameworks(max_followers=3), dt=st.floats(0.05, 2.5))
def test_closed_loop_spectrum_is_the_modes_spectrum(case, rf: RandomFramework, dt):
    law_name, kind, params = ALL_CASES[case]
    dyn = _dynamics(kind, rf.fw.d)
    law = make_law(law_name, Partition(rf.omega, rf.fw.leaders), dyn, dt, **params)
    full = np.linalg.eigvals(law.closed_loop())
    modes = np.linalg.eigvals(law.mode_matrices()).ravel()
    rho = law.spectral_radius()
    # Defective eigenvalues are computed only to eps^(1/s) for an s-fold Jordan block (the
    # double integrator's deadbeat gain at large T is nilpotent), hence the absolute tolerance.
    tol = 1e-4 * max(1.0, rho)
    assert np.max(np.abs(full)) == pytest.approx(rho, rel=1e-6, abs=tol)
    assert np.max(np.abs(modes)) == pytest.approx(rho, rel=1e-12, abs=1e-15)
    # Each mode eigenvalue is a closed-loop eigenvalue and vice versa (the exact dynamic law has
    # one mode shared by every follower).
    assert np.max(np.min(np.abs(full[:, None] - modes[None, :]), axis=1)) < tol
    assert np.max(np.min(np.abs(modes[:, None] - full[None, :]), axis=1)) < tol
    if not (law_name == "dynamic"):
        assert full.size == modes.size


# ---------------------------------------------------------------------- measured decay vs rho

# Laws whose dominant modes are real and semisimple: over a late window of a simulation the
# fitted log-rate is within a few percent of log(rho) (the residual is the next mode's share,
# which the late window makes small). The others have complex dominant pairs (distributed) or,
# at the default eps that minimises the worst mode, a double eigenvalue (linear, double
# integrators): the error norm then oscillates, or carries a factor k, which biases a rate fitted
# over the ~25 nats that double precision allows by up to ~15%. For those the run goes on with
# the error rescaled (the law is linear in the error and its memory), over 100 nats.
REAL_MODES = {"stationary", "dynamic-single", "dynamic-double", "linear-single"}


def _renormalised_log_rate(law: FollowerLaw, part: Partition, x0: np.ndarray, nats: float = 100.0) -> float:
    """Log error change per step of a long run of ``law.step`` with stationary leaders.

    After a burn-in of 8 decades, the error (and the law's memory) is rescaled whenever it leaves
    [1e-4, 1e4], and log ||e(k)|| plus the accumulated scale is fitted over ``nats`` / |ln rho| steps.
    """
    lr = abs(math.log(law.spectral_radius()))
    burn, window = math.ceil(8 * math.log(10) / lr), math.ceil(nats / lr)
    x, mem = x0.copy(), law.initial_memory()
    targets = part.targets(x[part.leaders])
    u_l = np.zeros((part.n_l, law.dynamics.p))
    offset, logs = 0.0, []
    for k in range(burn + window + 1):
        e = x[part.followers] - targets
        norm = float(np.linalg.norm(e))
        if k >= burn:
            logs.append(math.log(norm) + offset)
        if not 1e-4 < norm < 1e4:
            x[part.followers] = targets + e / norm
            mem = None if mem is None else mem / norm
            offset += math.log(norm)
        x, mem = law.step(x, u_l, mem)
    return float(np.polyfit(np.arange(len(logs)), logs, 1)[0])


def _pick_dt(case: str, part: Partition, u: float) -> float:
    if case == "stationary":
        lam_max = float(np.linalg.eigvalsh(part.omega_ff_dense)[-1])
        return (0.3 + u) * 2.0 / lam_max  # 0.3 to 1.3 times the Theorem 1 bound
    return 0.05 + 2.45 * u


@pytest.mark.parametrize("case", list(CASES))
@settings(max_examples=20, deadline=None)
@given(rf=random_frameworks(), seed=st.integers(0, 2**32 - 1), u=st.floats(0.0, 1.0))
def test_measured_decay_matches_spectral_radius(case, rf: RandomFramework, seed, u):
    law_name, kind, params = CASES[case]
    fw = rf.fw
    dyn = _dynamics(kind, fw.d)
    part = Partition(rf.omega, fw.leaders)
    dt = _pick_dt(case, part, u)
    rho = make_law(law_name, part, dyn, dt, **params).spectral_radius()
    # Rates too close to 1 need too many steps; deadbeat rates leave no window to measure.
    assume(0.3 <= rho <= 0.985 or 1.02 <= rho <= 20.0)
    growing = rho > 1
    steps = math.ceil(math.log(1e12) / abs(math.log(rho))) + 10
    x0 = _random_start(np.random.default_rng(seed), fw.n, dyn, list(fw.leaders))
    res = _run(rf.omega, fw.leaders, x0, dt, steps, law_name, dyn, **params)
    assert res.law.spectral_radius() == rho
    if growing:
        assert res.errors[-1] > 1e6 * res.errors[0]  # unstable: the error grows
    else:
        assert res.errors[-1] < 1e-6 * res.errors[0]
    if case in REAL_MODES:
        rate = _log_rate(res.errors, growing)
    else:
        rate = _renormalised_log_rate(res.law, part, x0)
    assert rate == pytest.approx(math.log(rho), rel=0.05)


def test_measured_decay_ratio_over_a_window_on_the_paper_example():
    # The paper's example at T = 1 s: rho = max |1 - T lambda_i| = 0.951127; errors[k + w] / errors[k]
    # equals rho^w once the faster mode (|1 - 1.493| = 0.493) has died out.
    rep = stability_report(paper_omega(), PAPER_LEADERS, 1.0)
    res = _run(paper_omega(), PAPER_LEADERS, PAPER_X0, 1.0, 300, "stationary", LinearDynamics.single_integrator(2))
    k, w = 100, 100
    assert res.errors[k + w] / res.errors[k] == pytest.approx(rep.spectral_radius**w, rel=1e-6)


# ---------------------------------------------------------------------- Theorem 1 (stationary leaders)


def test_theorem1_paper_numbers():
    rep = stability_report(paper_omega(), PAPER_LEADERS, dt=1.0)
    assert rep.mu_min == pytest.approx(-1.49, abs=0.005)  # the paper's "mu_min = -1.49"
    assert rep.mu_min == pytest.approx(-1.4931124, rel=1e-6)
    assert rep.mu_max == pytest.approx(-0.0488727, rel=1e-5)
    assert rep.cond == pytest.approx(rep.mu_min / rep.mu_max)
    assert rep.spectral_radius == pytest.approx(1 + rep.mu_max * 1.0)  # the slow mode dominates at T = 1
    assert rep.stable
    assert rep.dt_max == pytest.approx(-2.0 / rep.mu_min)
    assert rep.dt_range == (0.0, rep.dt_max)
    assert rep.decay_rate == pytest.approx(-math.log(rep.spectral_radius))
    assert rep.steps_to_1e6 == pytest.approx(math.log(1e-6) / math.log(rep.spectral_radius))
    assert rep.eps is None and rep.eps_range is None
    text = str(rep)
    assert "stable" in text and "Theorem 1" in text
    d = rep.as_dict()
    assert d["dt_max"] == rep.dt_max and d["law"] == "stationary"


@settings(max_examples=25, deadline=None)
@given(rf=random_frameworks(), frac=st.floats(0.05, 3.0), gain=st.floats(0.2, 5.0))
def test_theorem1_bound_is_exact(rf: RandomFramework, frac, gain):
    # Stable iff T g mu_min > -2, i.e. T < 2 / (g lambda_max(Omega_ff)).
    lam = np.linalg.eigvalsh(Partition(rf.omega, rf.fw.leaders).omega_ff_dense)
    dt = frac * 2.0 / (gain * lam[-1])
    assume(abs(frac - 1.0) > 1e-9)
    rep = stability_report(rf.omega, rf.fw.leaders, dt, "stationary", gain=gain)
    assert rep.stable == (dt * gain * rep.mu_min > -2.0)
    assert rep.dt_max == pytest.approx(2.0 / (gain * lam[-1]), rel=1e-12)
    assert rep.spectral_radius == pytest.approx(np.max(np.abs(1.0 - dt * gain * lam)), rel=1e-10)


@pytest.mark.parametrize("rf", [random_framework(s, 4 + s % 3, 2 + s % 2) for s in range(3)] + [None])
def test_theorem1_measured_just_inside_and_outside(rf):
    omega, leaders, n = (paper_omega(), PAPER_LEADERS, 5) if rf is None else (rf.omega, list(rf.fw.leaders), rf.fw.n)
    d = 2 if rf is None else rf.fw.d
    dt_max = stability_report(omega, leaders, 1.0).dt_max
    dyn = LinearDynamics.single_integrator(d)
    x0 = _random_start(np.random.default_rng(0), n, dyn, leaders)
    inside = _run(omega, leaders, x0, 0.99 * dt_max, 1200, "stationary", dyn)
    outside = _run(omega, leaders, x0, 1.01 * dt_max, 1200, "stationary", dyn)
    assert stability_report(omega, leaders, 0.99 * dt_max).stable
    assert not stability_report(omega, leaders, 1.01 * dt_max).stable
    # rho = 0.98 inside, 1.02 outside (the fastest mode dominates near the bound).
    assert inside.errors[-1] < 1e-6 * inside.errors[0]
    assert outside.errors[-1] > 1e6 * outside.errors[0]
    assert _log_rate(outside.errors, growing=True) == pytest.approx(math.log(1.02), rel=1e-3)


# ---------------------------------------------------------------------- Theorem 2 (dynamic leaders)


def _maneuver_path(fw_positions: np.ndarray, leaders, dt: float):
    m = scale(1.8, start=0.0, stop=15.0) @ rotate(1.2, start=0.0, stop=20.0)
    return m.leader_path(fw_positions[list(leaders)], dt)


@pytest.mark.parametrize("dt", [0.3, 1.0, 1.5, 1.99, 2.01])
@pytest.mark.parametrize("gain", [1.0, 0.5])
def test_theorem2_error_contracts_by_one_minus_gT_with_moving_leaders(dt, gain):
    rf = random_framework(11, 7, 2)
    fw = rf.fw
    part = Partition(rf.omega, fw.leaders)
    dyn = LinearDynamics.single_integrator(2)
    x0 = _random_start(np.random.default_rng(1), fw.n, dyn, list(fw.leaders))
    path = _maneuver_path(fw.positions, fw.leaders, dt)
    factor = 1.0 - gain * dt
    if abs(factor) < 1.0:
        res = simulate(rf.omega, fw.leaders, x0, dt, 40, "dynamic", path, dyn, return_result=True, gain=gain)
    else:
        with pytest.warns(StabilityWarning, match=f"spectral radius {abs(factor):.6g}"):
            res = simulate(rf.omega, fw.leaders, x0, dt, 40, "dynamic", path, dyn, return_result=True, gain=gain)
    e = _state_errors(res, part)
    assert np.max(np.abs(res.positions[1:, list(fw.leaders)] - np.array([path(k) for k in range(1, 41)]))) < 1e-12
    # The targets really move (else this would be the stationary case).
    assert np.linalg.norm(res.targets[20] - res.targets[0]) > 0.5
    # e(k+1) = (1 - g T) e(k), exactly, whatever the leaders do.
    for k in range(40):
        np.testing.assert_allclose(e[k + 1], factor * e[k], atol=1e-11 * (1 + np.abs(e[k]).max()))
    assert res.law.spectral_radius() == pytest.approx(abs(factor), rel=1e-12)


def test_theorem2_deadbeat_at_T_equals_one_with_moving_leaders():
    for rf in (random_framework(3, 6, 2), random_framework(4, 7, 3)):
        fw = rf.fw
        dyn = LinearDynamics.single_integrator(fw.d)
        x0 = _random_start(np.random.default_rng(2), fw.n, dyn, list(fw.leaders))
        m = rotate(0.9, 0.0, 10.0, axis=None if fw.d == 2 else [1.0, 2.0, 0.5]) @ scale(1.5, 0.0, 8.0, d=fw.d)
        res = simulate(
            rf.omega,
            fw.leaders,
            x0,
            1.0,
            12,
            "dynamic",
            m.leader_path(fw.positions[list(fw.leaders)], 1.0),
            dyn,
            return_result=True,
        )
        assert res.errors[0] > 0.5
        assert np.all(res.errors[1:] < 1e-12 * (1 + np.abs(res.positions).max()))
        # The stationary law on the same manoeuvre lags behind: the difference is the dynamic law.
        lag = simulate(
            rf.omega,
            fw.leaders,
            x0,
            0.5 * stability_report(rf.omega, fw.leaders).dt_max,
            12,
            "stationary",
            m.leader_path(fw.positions[list(fw.leaders)], 1.0),
            dyn,
            return_result=True,
        )
        assert lag.errors[-1] > 1e-3


def test_theorem2_report_bounds():
    rep = stability_report(paper_omega(), PAPER_LEADERS, 1.0, "dynamic")
    assert rep.spectral_radius == pytest.approx(0.0, abs=1e-15)
    assert rep.stable
    lo, hi = rep.dt_range
    assert lo == 0.0
    assert hi == pytest.approx(2.0, rel=1e-8)
    assert any("Theorem 2" in n for n in rep.notes)
    assert stability_report(paper_omega(), PAPER_LEADERS, 1.99, "dynamic").stable
    assert not stability_report(paper_omega(), PAPER_LEADERS, 2.01, "dynamic").stable
    assert stability_report(paper_omega(), PAPER_LEADERS, 0.5, "dynamic", gain=2.0).dt_max == pytest.approx(
        1.0, rel=1e-8
    )


@pytest.mark.parametrize(("dt", "stable"), [(1.99, True), (2.01, False)])
def test_theorem2_measured_just_inside_and_outside(dt, stable):
    dyn = LinearDynamics.single_integrator(2)
    res = _run(paper_omega(), PAPER_LEADERS, PAPER_X0, dt, 1000, "dynamic", dyn)
    if stable:
        assert res.errors[-1] < 1e-4 * res.errors[0]
    else:
        assert res.errors[-1] > 1e4 * res.errors[0]
    assert res.errors[-1] / res.errors[-101] == pytest.approx(0.99**100 if stable else 1.01**100, rel=1e-8)


def test_dynamic_law_double_integrators_with_leaders_on_any_input():
    # Our extension: leaders driven by arbitrary accelerations (states given in full, so the fed-forward
    # input is exact); the error still obeys e(k+1) = (A_d + B_d K) e(k).
    rf = random_framework(8, 6, 2)
    fw = rf.fw
    dyn = LinearDynamics.double_integrator(2)
    dt, steps = 0.4, 30
    part = Partition(rf.omega, fw.leaders)
    rng = np.random.default_rng(5)
    xl = [dyn.state_from_position(fw.positions[list(fw.leaders)])]
    for _ in range(steps):
        xl.append(dyn.step(xl[-1], rng.normal(size=(part.n_l, 2)), dt))
    x0 = _random_start(rng, fw.n, dyn, list(fw.leaders))
    res = simulate(rf.omega, fw.leaders, x0, dt, steps, "dynamic", lambda k: xl[k], dyn, return_result=True)
    e = _state_errors(res, part)
    m = res.law.A_d + res.law.B_d @ res.law.K
    for k in range(steps):
        np.testing.assert_allclose(e[k + 1], e[k] @ m.T, atol=1e-10)
    assert res.errors[-1] < 1e-3 * res.errors[0]


# ---------------------------------------------------------------------- the distributed variant


def test_distributed_paper_example_diverges_at_T1_and_converges_at_T01():
    dyn = LinearDynamics.single_integrator(2)
    rep1 = stability_report(paper_omega(), PAPER_LEADERS, 1.0, "dynamic_distributed", rounds=1)
    rep01 = stability_report(paper_omega(), PAPER_LEADERS, 0.1, "dynamic_distributed", rounds=1)
    assert not rep1.stable and rep01.stable
    fast = _run(paper_omega(), PAPER_LEADERS, PAPER_X0, 1.0, 40, "dynamic_distributed", dyn, rounds=1)
    slow = _run(paper_omega(), PAPER_LEADERS, PAPER_X0, 0.1, 800, "dynamic_distributed", dyn, rounds=1)
    assert fast.errors[-1] > 1e6 * fast.errors[0]
    assert slow.errors[-1] < 1e-6 * slow.errors[0]
    np.testing.assert_allclose(slow.positions[-1, 3:], [[-1.0, 0.0], [-2.0, 0.0]], atol=1e-5)
    # Exact (infinitely many rounds) converges at T = 1 in one step.
    assert stability_report(paper_omega(), PAPER_LEADERS, 1.0, "dynamic").stable


@pytest.mark.parametrize("rounds", [1, 3])
def test_distributed_dt_range_holds_just_inside_and_outside(rounds):
    dyn = LinearDynamics.single_integrator(2)
    rep = stability_report(paper_omega(), PAPER_LEADERS, 0.1, "dynamic_distributed", rounds=rounds)
    lo, hi = rep.dt_range
    assert lo == 0.0 and 0.1 < hi < 1.0
    for dt, stable in ((0.97 * hi, True), (1.03 * hi, False)):
        law = make_law("dynamic_distributed", Partition(paper_omega(), PAPER_LEADERS), dyn, dt, rounds=rounds)
        rho = law.spectral_radius()
        assert (rho < 1.0) == stable
        steps = math.ceil(math.log(1e8) / abs(math.log(rho))) + 50
        res = _run(paper_omega(), PAPER_LEADERS, PAPER_X0, dt, steps, "dynamic_distributed", dyn, rounds=rounds)
        if stable:
            assert res.errors[-1] < 1e-6 * res.errors[0]
        else:
            assert res.errors[-1] > 1e6 * res.errors[0]


def test_distributed_rounds_approach_the_exact_law():
    # More Jacobi rounds shrink c = nu^m; the mode radius tends to the exact law's |1 - T|.
    part = Partition(paper_omega(), PAPER_LEADERS)
    dyn = LinearDynamics.single_integrator(2)
    law = make_law("dynamic_distributed", part, dyn, 0.5, rounds=200)
    assert law.spectral_radius() == pytest.approx(0.5, abs=1e-6)
    nu = law.jacobi_eigenvalues()
    d = np.diag(part.omega_ff_dense)
    j = -(part.omega_ff_dense - np.diag(d)) / d[:, None]
    np.testing.assert_allclose(np.sort(nu), np.sort(np.linalg.eigvals(j).real), atol=1e-12)


# ---------------------------------------------------------------------- Theorem 3 (general linear agents)


def test_corrected_linear_law_reaches_targets_and_the_literal_one_does_not():
    dyn = LinearDynamics.double_integrator(2)
    part = Partition(paper_omega(), PAPER_LEADERS)
    dt, steps = 0.5, 1500
    good = _run(paper_omega(), PAPER_LEADERS, PAPER_X0, dt, steps, "linear", dyn)
    with pytest.warns(StabilityWarning, match="literal eq. 25"):
        bad = simulate(
            paper_omega(), PAPER_LEADERS, PAPER_X0, dt, steps, "linear_paper", dynamics=dyn, return_result=True
        )
    targets = np.array([[-1.0, 0.0], [-2.0, 0.0]])
    np.testing.assert_allclose(good.positions[-1, 3:], targets, atol=1e-8)
    assert good.errors[-1] < 1e-8
    # The literal law converges (its matrix is Schur) ... to the wrong place.
    assert bad.law.spectral_radius() < 1.0
    assert np.max(np.abs(bad.positions[-1] - bad.positions[-2])) < 1e-12
    assert np.max(np.abs(bad.positions[-1, 3:] - targets)) > 0.3
    assert bad.errors[-1] > 0.3
    # Its rest point solves x_f = M x_f - eps (Omega_fl kron B K) x_l (the "+ x_i" term pulls it away).
    law = bad.law
    bk = law.B_d @ law.K
    m = law.closed_loop()
    xl = bad.states[-1, part.leaders].ravel()
    rest = np.linalg.solve(np.eye(m.shape[0]) - m, -law.eps * np.kron(part.omega_fl, bk) @ xl)
    np.testing.assert_allclose(bad.states[-1, part.followers].ravel(), rest, atol=1e-9)
    rep = stability_report(paper_omega(), PAPER_LEADERS, dt, "linear_paper", dyn)
    assert any("literal eq. 25" in n for n in rep.notes)


@settings(max_examples=10, deadline=None)
@given(rf=random_frameworks(max_followers=3), dt=st.floats(0.1, 1.5))
def test_linear_eps_range_bounds_are_sharp(rf: RandomFramework, dt):
    dyn = LinearDynamics.double_integrator(rf.fw.d)
    rep = stability_report(rf.omega, rf.fw.leaders, dt, "linear", dyn)
    lo, hi = rep.eps_range
    assert rep.stable and lo < rep.eps < hi
    part = Partition(rf.omega, rf.fw.leaders)
    assert make_law("linear", part, dyn, dt, eps=0.999 * hi).spectral_radius() < 1.0
    assert make_law("linear", part, dyn, dt, eps=1.001 * hi).spectral_radius() >= 1.0
    # The default eps is the best one: no better eps on a grid.
    grid = np.linspace(lo, hi, 41)[1:-1]
    best = min(make_law("linear", part, dyn, dt, eps=e).spectral_radius() for e in grid)
    assert rep.spectral_radius <= best + 1e-6


def test_linear_eps_just_outside_the_range_diverges_measured():
    dyn = LinearDynamics.double_integrator(2)
    rep = stability_report(paper_omega(), PAPER_LEADERS, 0.5, "linear", dyn)
    hi = rep.eps_range[1]
    for eps, stable in ((0.97 * hi, True), (1.03 * hi, False)):
        law = make_law("linear", Partition(paper_omega(), PAPER_LEADERS), dyn, 0.5, eps=eps)
        rho = law.spectral_radius()
        steps = math.ceil(math.log(1e8) / abs(math.log(rho))) + 50
        res = _run(paper_omega(), PAPER_LEADERS, PAPER_X0, 0.5, steps, "linear", dyn, eps=eps)
        if stable:
            assert res.errors[-1] < 1e-6 * res.errors[0]
        else:
            assert res.errors[-1] > 1e6 * res.errors[0]


# ---------------------------------------------------------------------- the report agrees with the laws


@pytest.mark.parametrize("case", list(ALL_CASES))
@pytest.mark.parametrize("dt", [0.3, 1.2])
def test_report_spectral_radius_is_the_laws(case, dt):
    law_name, kind, params = ALL_CASES[case]
    rf = random_framework(21, 6, 2)
    dyn = _dynamics(kind, 2)
    rep = stability_report(rf.omega, rf.fw.leaders, dt, law_name, dyn, **params)
    law = make_law(law_name, Partition(rf.omega, rf.fw.leaders), dyn, dt, **params)
    assert rep.spectral_radius == law.spectral_radius()
    assert rep.stable == (rep.spectral_radius < 1.0)
    assert rep.law == law_name and rep.dt == dt
    lam = np.linalg.eigvalsh(Partition(rf.omega, rf.fw.leaders).omega_ff_dense)
    assert (rep.mu_min, rep.mu_max) == pytest.approx((-lam[-1], -lam[0]))
    if rep.dt_range is not None:
        lo, hi = rep.dt_range
        assert lo < dt < hi or not rep.stable
    if rep.stable and rep.spectral_radius > 0:
        assert rep.decay_rate == pytest.approx(-math.log(rep.spectral_radius) / dt)


# ---------------------------------------------------------------------- batched stepping


@pytest.mark.parametrize("case", list(ALL_CASES))
@pytest.mark.parametrize("sparse", [False, True])
def test_batched_step_equals_a_loop(case, sparse):
    law_name, kind, params = ALL_CASES[case]
    rf = random_framework(2, 7, 3)
    fw = rf.fw
    dyn = _dynamics(kind, 3)
    omega = sp.csr_matrix(rf.omega) if sparse else rf.omega
    law = make_law(law_name, Partition(omega, fw.leaders), dyn, 0.4, **params)
    rng = np.random.default_rng(0)
    batch = 4
    x = rng.normal(size=(batch, fw.n, dyn.q))
    mem = law.initial_memory((batch,))
    mems = [law.initial_memory() for _ in range(batch)]
    for _ in range(3):  # a few steps, so the distributed law's memory is exercised
        u_l = rng.normal(size=(batch, len(fw.leaders), dyn.p))
        x_next, mem = law.step(x, u_l, mem)
        for b in range(batch):
            xb, mems[b] = law.step(x[b], u_l[b], mems[b])
            np.testing.assert_allclose(x_next[b], xb, rtol=1e-12, atol=1e-12)
            if mem is not None:
                np.testing.assert_allclose(mem[b], mems[b], rtol=1e-12, atol=1e-12)
        x = x_next
    # Sparse and dense stresses step alike.
    if sparse:
        dense = make_law(law_name, Partition(rf.omega, fw.leaders), dyn, 0.4, **params)
        x0 = rng.normal(size=(batch, fw.n, dyn.q))
        u_l = rng.normal(size=(batch, len(fw.leaders), dyn.p))
        a, _ = law.step(x0, u_l, law.initial_memory((batch,)))
        b, _ = dense.step(x0, u_l, dense.initial_memory((batch,)))
        np.testing.assert_allclose(a, b, rtol=1e-10, atol=1e-12)
