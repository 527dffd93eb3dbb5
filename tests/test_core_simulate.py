"""``simulate``, ``make_law`` and ``stability_report``: results, determinism, and every error path."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import scipy.sparse as sp
from conftest import random_framework

from formation_env.core import (
    LAWS,
    ControlDimension,
    FormationError,
    LinearDynamics,
    Partition,
    SimResult,
    StabilityWarning,
    UnstableParameterError,
    make_law,
    paper_omega,
    scale,
    simulate,
    stability_report,
)

LEADERS = [0, 1, 2]
X0 = np.array([[1.0, 0.0], [0.0, 1.0], [0.0, -1.0], [-4.0, 3.0], [-3.0, -2.0]])
SI, DI = LinearDynamics.single_integrator(2), LinearDynamics.double_integrator(2)
# The paper's example at T = 1.5 s: rho = |1 - 1.5 * 1.49311| = 1.23967 > 1 (Theorem 1 bound 1.3395 s).
UNSTABLE_DT = 1.5
UNSTABLE_RHO = abs(1 - UNSTABLE_DT * 1.4931123637)


def _sim(**kw):
    args = dict(omega=paper_omega(), leaders=LEADERS, x0=X0, dt=1.0, steps=5, law="stationary")
    args.update(kw)
    return simulate(**args)


# ---------------------------------------------------------------------- results


def test_positions_and_result_shapes():
    pos = _sim(steps=7)
    assert isinstance(pos, np.ndarray) and pos.shape == (8, 5, 2)
    res = _sim(steps=7, law="linear", dynamics=DI, return_result=True)
    assert isinstance(res, SimResult)
    assert res.positions.shape == (8, 5, 2)
    assert res.states.shape == (8, 5, 4)
    assert res.inputs.shape == (7, 5, 2)
    assert res.targets.shape == (8, 2, 2)
    assert res.errors.shape == (8,)
    np.testing.assert_allclose(res.times, np.arange(8.0))
    np.testing.assert_allclose(res.states[0, :, :2], X0)  # x0 positions: states at rest
    np.testing.assert_allclose(res.states[0, :, 2:], 0.0)
    # inputs are the ones that produced the states.
    ad, bd = DI.zoh(1.0)
    np.testing.assert_allclose(res.states[1:], res.states[:-1] @ ad.T + res.inputs @ bd.T, atol=1e-12)
    assert _sim(steps=0).shape == (1, 5, 2)


def test_many_step_determinism_and_purity():
    kw = dict(law="dynamic_distributed", rounds=2, dt=0.1, steps=300, return_result=True)
    a, b = _sim(**kw), _sim(**kw)
    np.testing.assert_array_equal(a.states, b.states)
    np.testing.assert_array_equal(a.errors, b.errors)
    x0 = X0.copy()
    _sim(x0=x0, steps=3)
    np.testing.assert_array_equal(x0, X0)  # the input is not modified


@pytest.mark.parametrize("law", LAWS)
def test_sparse_and_dense_simulations_agree(law):
    dyn = SI if law in ("stationary", "dynamic", "dynamic_distributed") else DI
    rf = random_framework(3, 7, 2)
    x0 = np.random.default_rng(0).normal(size=(7, 2))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", StabilityWarning)
        a = simulate(rf.omega, rf.fw.leaders, x0, 0.3, 60, law, dynamics=dyn)
        b = simulate(sp.csr_matrix(rf.omega), rf.fw.leaders, x0, 0.3, 60, law, dynamics=dyn)
    np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-11)


def test_default_dynamics_follow_x0_dimension():
    rf = random_framework(4, 6, 3)
    pos = simulate(rf.omega, rf.fw.leaders, rf.fw.positions + 0.1, dt=0.2, steps=3)
    assert pos.shape == (4, 6, 3)


def test_double_integrator_leader_path_velocity_is_the_forward_difference():
    m = scale(2.0, 0.0, 5.0)
    r = np.array([[1.0, 0.0], [0.0, 1.0], [0.0, -1.0]])
    dt = 0.5
    res = _sim(law="dynamic", dynamics=DI, dt=dt, steps=12, leader_path=m.leader_path(r, dt), return_result=True)
    p = res.states[:, :3, :2]
    np.testing.assert_allclose(p, np.array([m.targets(r, k * dt) for k in range(13)]), atol=1e-14)
    np.testing.assert_allclose(res.states[1:, :3, 2:], (p[1:] - p[:-1]) / dt, atol=1e-12)


def test_stable_settings_do_not_warn():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        _sim(dt=1.0)
        _sim(law="dynamic", dt=1.9)
        _sim(law="linear", dynamics=DI, dt=0.5)


# ---------------------------------------------------------------------- stability warnings and errors


def test_unstable_dt_warns_with_the_spectral_radius():
    with pytest.warns(
        StabilityWarning, match=rf"T = 1\.5 s is unstable \(closed-loop spectral radius {UNSTABLE_RHO:.6g}"
    ):
        pos = _sim(dt=UNSTABLE_DT, steps=50)
    assert np.abs(pos[-1, 3:]).max() > 100  # and it does diverge
    with pytest.warns(StabilityWarning, match=r"spectral radius 1\.01 >= 1"):
        _sim(law="dynamic", dt=2.01)


def test_require_stable_law_raises():
    with pytest.raises(UnstableParameterError, match=rf"unstable: closed-loop spectral radius {UNSTABLE_RHO:.6g} >= 1"):
        _sim(dt=UNSTABLE_DT, require_stable_law=True)
    with pytest.raises(UnstableParameterError, match="dynamic_distributed at T = 1 s is unstable"):
        _sim(law="dynamic_distributed", dt=1.0, rounds=1, require_stable_law=True)
    _sim(dt=1.0, require_stable_law=True)  # stable: fine


def test_literal_paper_law_always_warns():
    with pytest.warns(StabilityWarning, match=r"literal eq\. 25.*use law='linear'"):
        _sim(law="linear_paper", dynamics=DI, dt=0.5)


def test_report_of_an_unstable_setting():
    rep = stability_report(paper_omega(), LEADERS, UNSTABLE_DT)
    assert not rep.stable
    assert rep.spectral_radius == pytest.approx(UNSTABLE_RHO, rel=1e-8)
    assert rep.steps_to_1e6 == float("inf")
    assert rep.decay_rate == 0.0
    assert "UNSTABLE" in str(rep)
    assert rep.as_dict()["steps_to_1e6"] == "inf"


ERRORS = {
    "unknown_law": (dict(law="nope"), FormationError, r"unknown law 'nope'; choose one of stationary, linear"),
    "unknown_param": (dict(foo=1.0), TypeError, r"law 'stationary' got unexpected parameter\(s\): foo"),
    "param_of_another_law": (dict(law="dynamic", rounds=2), TypeError, r"unexpected parameter\(s\): rounds"),
    "stationary_double": (dict(dynamics=DI), FormationError, r"single integrators.*use law='linear'.*law='dynamic'"),
    "rounds_zero": (dict(law="dynamic_distributed", rounds=0), FormationError, "rounds must be a positive integer"),
    "rounds_fraction": (
        dict(law="dynamic_distributed", rounds=1.5),
        FormationError,
        "rounds must be a positive integer",
    ),
    "x0_rows": (dict(x0=X0[:4]), ControlDimension, r"x0 must have one row per agent \(5\)"),
    "x0_columns": (
        dict(x0=np.zeros((5, 3)), dynamics=DI, law="linear"),
        ControlDimension,
        r"x0 must have shape \(5, 2\) or \(5, 4\) for double_integrator",
    ),
    "x0_ndim": (dict(x0=np.zeros(10)), ControlDimension, "x0 must have 2 dimensions"),
    "x0_nan": (dict(x0=np.where(X0 == 3.0, np.nan, X0)), FormationError, "x0 holds 1 non-finite value"),
    "steps_negative": (dict(steps=-1), FormationError, "steps must be a non-negative integer"),
    "steps_fraction": (dict(steps=2.5), FormationError, "steps must be a non-negative integer"),
    "dt_zero": (dict(dt=0.0), FormationError, "dt must be a positive finite"),
    "dt_nan": (dict(dt=float("nan")), FormationError, "dt must be a positive finite"),
    "gain_negative": (dict(gain=-1.0), FormationError, "gain must be positive"),
    "gain_dynamic": (dict(law="dynamic", gain=0.0), FormationError, "gain must be positive"),
    "eps_negative": (dict(law="linear", dynamics=DI, eps=-0.1), FormationError, "eps must be a positive finite"),
    "K_shape": (dict(law="linear", dynamics=DI, K=np.zeros((2, 2))), ControlDimension, r"K must have shape \(2, 4\)"),
    "K_shape_dynamic": (dict(law="dynamic", K=np.zeros((2, 3))), ControlDimension, r"K must have shape \(2, 2\)"),
    "K_not_stabilising": (
        dict(law="linear", dynamics=DI, K=np.zeros((2, 4))),
        UnstableParameterError,
        "does not stabilise one agent",
    ),
    "leader_path_shape": (
        dict(leader_path=lambda k: np.zeros((3, 3))),
        ControlDimension,
        r"leader_path\(0\) must return shape \(3, 2\) or \(3, 2\)",
    ),
    "bad_leaders": (dict(leaders=[0, 1, 1]), FormationError, "distinct indices"),
}


@pytest.mark.parametrize("name", list(ERRORS))
def test_simulate_errors(name):
    kw, exc, match = ERRORS[name]
    with pytest.raises(exc, match=match):
        _sim(**kw)


@pytest.mark.parametrize(
    ("kw", "exc", "match"),
    [
        (dict(law="nope"), FormationError, "unknown law 'nope'"),
        (dict(law="stationary", rounds=1), TypeError, r"unexpected parameter\(s\): rounds"),
        (dict(law="stationary", dynamics=DI), FormationError, "use law='linear'"),
        (dict(law="dynamic_distributed", rounds=0), FormationError, "rounds must be a positive integer"),
        (dict(law="stationary", dt=-1.0), FormationError, "dt must be a positive finite"),
    ],
)
def test_make_law_and_report_errors(kw, exc, match):
    part = Partition(paper_omega(), LEADERS)
    args = dict(kw)
    law = args.pop("law")
    dyn = args.pop("dynamics", SI)
    dt = args.pop("dt", 1.0)
    with pytest.raises(exc, match=match):
        make_law(law, part, dyn, dt, **args)
    with pytest.raises(exc, match=match):
        stability_report(paper_omega(), LEADERS, dt, law, dyn, **args)


def test_report_refuses_an_indefinite_omega_ff():
    with pytest.raises(FormationError, match="Omega_ff is not positive definite"):
        stability_report(-paper_omega(), LEADERS, 1.0)


def test_unknown_simulate_keyword_is_refused():
    with pytest.raises(TypeError, match="unexpected"):
        simulate(paper_omega(), LEADERS, X0, 1.0, 5, "stationary", None, None, bogus=True)
