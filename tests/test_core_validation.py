"""Issue 21 (core): bad input is refused with an error naming the argument; nothing silently wrong."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from formation_env.core import (
    ControlDimension,
    FormationError,
    Framework,
    LawAssumptionWarning,
    LinearDynamics,
    Partition,
    ReachabilityWarning,
    StabilityWarning,
    StressMatrixError,
    UnknownNameError,
    check_stress,
    design_stress,
    dlqr,
    equilibrium_stress_basis,
    follower_targets,
    hold,
    make_law,
    paper_example,
    paper_omega,
    riccati_gain,
    rotate,
    rotation,
    scale,
    scaling,
    shear,
    shear_matrix,
    simulate,
    stability_report,
    stress_from_weights,
    translate,
)
from formation_env.core import frameworks as lib
from formation_env.core.frameworks import farthest_point_leaders, trilateration

LEADERS = [0, 1, 2]
X0 = np.array([[1.0, 0.0], [0.0, 1.0], [0.0, -1.0], [-0.3, 0.4], [-1.7, -0.2]])


def oscillator(c: float = 0.2) -> LinearDynamics:
    """Damped oscillator per axis, state [px, py, vx, vy]: pdd = -p - c pd + u."""
    return LinearDynamics(
        np.kron([[0, 1], [-1, -c]], np.eye(2)), np.kron([[0], [1]], np.eye(2)), np.kron([[1, 0]], np.eye(2))
    )


def interleaved_double_integrator() -> LinearDynamics:
    """Double integrator with state [px, vx, py, vy]; C picks the positions."""
    a = np.kron(np.eye(2), [[0, 1], [0, 0]])
    b = np.kron(np.eye(2), [[0], [1]])
    c = np.kron(np.eye(2), [[1, 0]])
    return LinearDynamics(a, b, c)


# ------------------------------------------------------------------ omega validated where it is used
def asymmetric() -> np.ndarray:
    om = paper_omega().copy()
    om[3, 4] += 3
    return om


def test_stability_report_refuses_asymmetric_omega():
    with pytest.raises(StressMatrixError, match=r"omega must be symmetric.*max \|omega - omega\^T\| = 3"):
        stability_report(asymmetric(), LEADERS, 1.0)


def test_simulate_refuses_asymmetric_omega():
    with pytest.raises(StressMatrixError, match="omega must be symmetric"):
        simulate(asymmetric(), LEADERS, X0, 1.0, 10)


def test_follower_targets_refuses_small_asymmetry_and_zeros():
    om = paper_omega().copy()
    om[3, 4] += 1e-4
    with pytest.raises(StressMatrixError, match="symmetric"):
        follower_targets(om, LEADERS, X0[:3])
    with pytest.raises(StressMatrixError, match="zero matrix"):
        follower_targets(np.zeros((5, 5)), LEADERS, X0[:3])
    # check=False is the documented fast path
    out = follower_targets(paper_omega(), LEADERS, X0[:3], check=False)
    np.testing.assert_allclose(out, follower_targets(paper_omega(), LEADERS, X0[:3]))


def test_row_sums_and_indefinite_omega_ff_refused():
    om = paper_omega() + 0.01 * np.eye(5)
    with pytest.raises(StressMatrixError, match="rows must sum to zero"):
        stability_report(om, LEADERS)
    with pytest.raises(StressMatrixError, match="Omega_ff is not positive definite"):
        follower_targets(-paper_omega(), LEADERS, X0[:3])


def test_printed_omega_passes_at_its_tolerance():
    printed = paper_omega(exact=False)
    with pytest.raises(StressMatrixError, match="rows must sum to zero"):
        stability_report(printed, LEADERS)
    assert stability_report(printed, LEADERS, rtol=1e-3).stable


# ------------------------------------------------------------------ indices, None, strings, complex
@pytest.mark.parametrize("bad", [(0.7, 3.9), [0.0, 1.0, 2.0], np.array([0.5, 1, 2])])
def test_float_leader_indices_refused_not_truncated(bad):
    with pytest.raises(FormationError, match=r"leaders.*integer agent indices.*not truncated"):
        Partition(paper_omega(), bad)
    with pytest.raises(FormationError, match="leaders"):
        Framework(X0, paper_example().edges, bad)


def test_float_edges_refused():
    with pytest.raises(FormationError, match=r"edges.*integer"):
        Framework(X0, [(0.7, 3.9), (0, 1)], LEADERS)
    with pytest.raises(FormationError, match=r"edges.*integer"):
        stress_from_weights(5, [(0.7, 3.9)], [1.0])


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: Partition(paper_omega(), None), "leaders must be .*got None"),
        (lambda: Framework(X0, None, LEADERS), "edges must be .*got None"),
        (lambda: Framework(X0, paper_example().edges, None), "leaders must be .*got None"),
        (lambda: check_stress(paper_omega(), None), "fw must be a Framework, got None"),
        (lambda: design_stress(None, "constructive"), "fw must be a Framework"),
        (lambda: simulate(paper_omega(), LEADERS, X0, "0.1", 5), "dt must be a real number"),
        (lambda: stability_report(paper_omega(), LEADERS, "1"), "dt must be a real number"),
        (lambda: simulate(paper_omega(), LEADERS, X0 + 0j, 1.0, 5), "x0 must be real, got a complex"),
        (lambda: Partition(paper_omega() + 0j, LEADERS), "omega must be real"),
        (lambda: riccati_gain(np.eye(2) * 1j, np.eye(2)), "A must be real"),
        (lambda: simulate(paper_omega(), LEADERS, X0, 1.0, 5, dynamics="double"), "dynamics must be a LinearDynamics"),
    ],
)
def test_type_errors_name_the_argument(call, match):
    with pytest.raises(TypeError, match=match):
        call()


@pytest.mark.parametrize("steps", [float("nan"), float("inf"), -1, 2.5])
def test_simulate_steps_refused(steps):
    with pytest.raises(FormationError, match="steps must be a non-negative integer number of samples"):
        simulate(paper_omega(), LEADERS, X0, 1.0, steps)


@pytest.mark.parametrize("rtol", [float("nan"), -1e-3, 1.5])
def test_rtol_refused(rtol):
    fw = paper_example()
    with pytest.raises(FormationError, match="rtol must be"):
        check_stress(paper_omega(), fw, rtol=rtol)
    with pytest.raises(FormationError, match="rtol must be"):
        stability_report(paper_omega(), LEADERS, rtol=rtol)


def test_stress_from_weights_edge_out_of_range_and_self_loop():
    with pytest.raises(FormationError, match=r"edges must be agent indices in 0..4, got 7"):
        stress_from_weights(5, [(0, 7)], [1.0])
    with pytest.raises(FormationError, match="self-loop"):
        stress_from_weights(5, [(2, 2)], [1.0])
    with pytest.raises(ControlDimension, match=r"weights must have one entry per edge"):
        stress_from_weights(5, [(0, 1), (1, 2)], [1.0])


def test_dlqr_needs_r_and_spd_weights():
    a, b = np.eye(2), np.eye(2)
    with pytest.raises(TypeError, match="dlqr\\(\\) needs R"):
        dlqr(a, b, np.eye(2), None)
    with pytest.raises(FormationError, match="R must be symmetric positive definite"):
        dlqr(a, b, np.eye(2), -np.eye(2))
    _, _, e = dlqr(a, b, np.eye(2), np.eye(2))
    assert np.all(np.abs(e) < 1)


@pytest.mark.parametrize("d", [0, -1])
def test_dynamics_constructors_refuse_bad_d(d):
    with pytest.raises(FormationError, match="d must be an integer >= 1"):
        LinearDynamics.double_integrator(d)
    with pytest.raises(FormationError, match="d must be an integer >= 1"):
        LinearDynamics.single_integrator(d)
    with pytest.raises(FormationError, match="d must be an integer"):
        LinearDynamics.double_integrator(2.0)


@pytest.mark.parametrize("law", ["stationary", "dynamic", "dynamic_distributed"])
@pytest.mark.parametrize("gain", [-1.0, float("nan"), 0.0, float("inf")])
@pytest.mark.parametrize("double", [False, True])
def test_bad_gain_refused_for_every_law(law, gain, double):
    part = Partition(paper_omega(), LEADERS)
    dyn = LinearDynamics.double_integrator(2) if double else LinearDynamics.single_integrator(2)
    if law == "stationary" and double:
        law = "dynamic"
    with pytest.raises(FormationError, match="gain must be positive and finite"):
        make_law(law, part, dyn, 0.1, gain=gain)


@pytest.mark.parametrize("eps", [-0.1, float("nan")])
def test_bad_eps_refused(eps):
    part = Partition(paper_omega(), LEADERS)
    with pytest.raises(FormationError, match="eps must be a positive finite number"):
        make_law("linear", part, LinearDynamics.double_integrator(2), 0.1, eps=eps)


def test_bad_k_shape_refused():
    part = Partition(paper_omega(), LEADERS)
    with pytest.raises(ControlDimension, match=r"K must have shape \(2, 4\)"):
        make_law("dynamic", part, LinearDynamics.double_integrator(2), 0.1, K=np.eye(2))


# ------------------------------------------------------------------ simulate: leader states through C
def test_leader_path_through_c_for_any_state_order():
    dyn = interleaved_double_integrator()
    fw = paper_example()
    path = lambda k: fw.positions[:3] + 0.05 * k * np.array([1.0, 0.5])  # noqa: E731
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ReachabilityWarning)
        res = simulate(paper_omega(), LEADERS, X0, 0.1, 20, "dynamic", path, dyn, return_result=True)
    for k in range(21):
        np.testing.assert_allclose(res.positions[k, :3], path(k), atol=1e-12)


def test_full_leader_states_reachable_no_warning():
    dyn = LinearDynamics.double_integrator(2)
    fw = paper_example()
    vel = np.array([0.3, -0.1])

    def path(k):  # constant velocity: exactly reachable with u = 0
        return np.hstack([fw.positions[:3] + vel * k * 1.0, np.tile(vel, (3, 1))])

    x0 = np.hstack([X0, np.zeros((5, 2))])
    x0[:3, 2:] = vel
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        res = simulate(paper_omega(), LEADERS, x0, 1.0, 40, "dynamic", path, dyn, return_result=True)
    assert res.errors[-1] < 1e-6 * res.errors[0]


def test_unreachable_position_path_warns_with_the_residual():
    dyn = LinearDynamics.double_integrator(2)
    fw = paper_example()
    path = lambda k: fw.positions[:3] * (1 + 0.1 * np.sin(0.3 * k))  # noqa: E731
    with pytest.warns(ReachabilityWarning, match=r"not reachable.*largest residual .* = [0-9.e-]+ at k = \d+"):
        simulate(paper_omega(), LEADERS, X0, 0.1, 30, "dynamic", path, dyn)
    assert issubclass(ReachabilityWarning, StabilityWarning)


def test_linear_law_warns_when_leaders_are_held_on_oscillator():
    fw = paper_example()
    hold = lambda k: fw.positions[:3]  # noqa: E731
    with pytest.warns(LawAssumptionWarning, match="leave their free trajectories"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ReachabilityWarning)
            simulate(paper_omega(), LEADERS, X0, 0.1, 10, "linear", hold, oscillator())
    with warnings.catch_warnings():  # free leaders: no warning
        warnings.simplefilter("error")
        simulate(paper_omega(), LEADERS, X0, 0.1, 10, "linear", None, oscillator())


# ------------------------------------------------------------------ stability windows
def test_dynamic_distributed_windows_on_damped_oscillator():
    rep = stability_report(paper_omega(), LEADERS, 0.05, "dynamic_distributed", oscillator())
    assert not rep.stable
    assert rep.windows, "stable windows must be found away from the asked dt"
    lo, hi = rep.windows[0]
    assert lo == pytest.approx(2.178, abs=5e-3) and hi == pytest.approx(4.307, abs=5e-3)
    assert len(rep.windows) > 1
    assert rep.dt_range == rep.windows[0]
    assert rep.jacobi_radius < 1 and any("rho(J)" in n for n in rep.notes)
    assert rep.dt_opt is not None and rep.rho_opt < 1


def test_stationary_t_opt():
    rep = stability_report(paper_omega(), LEADERS, 0.5)
    lam = np.linalg.eigvalsh(paper_omega()[3:, 3:])
    assert rep.dt_opt == pytest.approx(2 / (lam[0] + lam[-1]))
    assert rep.rho_opt == pytest.approx((rep.cond - 1) / (rep.cond + 1))
    assert rep.windows == [(rep.dt_search[0], pytest.approx(2 / lam[-1]))]


def test_dynamic_distributed_says_plainly_when_nothing_works():
    # a stress whose Jacobi matrix has a mode at or beyond -1: a follower pair with a strong coupling
    r = np.array([[0.0, 0.0], [4.0, 0.0], [0.0, 4.0], [1.0, 1.0], [1.1, 1.0], [1.0, 1.1]])
    fw = Framework(r, [(i, j) for i in range(6) for j in range(i + 1, 6)], LEADERS)
    om = design_stress(fw, "sdp")
    part = Partition(om, LEADERS)
    law = make_law("dynamic_distributed", part, LinearDynamics.single_integrator(2), 0.1)
    rho_j = float(np.max(np.abs(law.jacobi_eigenvalues())))
    rep = stability_report(om, LEADERS, 0.1, "dynamic_distributed")
    assert rep.jacobi_radius == pytest.approx(rho_j)
    if rho_j >= 1:
        assert any("no T and no number of rounds m" in n for n in rep.notes)
        assert rep.windows == []
    else:
        assert rep.windows


def test_dt_search_validated():
    with pytest.raises(FormationError, match="dt_search must be increasing"):
        stability_report(paper_omega(), LEADERS, dt_search=(1.0, 0.1))
    with pytest.raises(FormationError, match=r"dt_search\[0\] must be a positive finite"):
        stability_report(paper_omega(), LEADERS, dt_search=(-1.0, 1.0))


# ------------------------------------------------------------------ hypothesis: malformed inputs
BAD = st.sampled_from(
    [None, "x", float("nan"), float("inf"), -1, 0.5, 1 + 2j, [1.0, float("nan")], np.zeros((2, 3)), [[1, 2], [3]]]
)


def _calls(bad):
    om, fw = paper_omega(), paper_example()
    part = Partition(om, LEADERS)
    si = LinearDynamics.single_integrator(2)
    return {
        "omega": lambda: stability_report(bad, LEADERS),
        "leaders": lambda: follower_targets(om, bad, X0[:3]),
        "x_leaders": lambda: follower_targets(om, LEADERS, bad),
        "x0": lambda: simulate(om, LEADERS, bad, 1.0, 3),
        "dt": lambda: simulate(om, LEADERS, X0, bad, 3),
        "steps": lambda: simulate(om, LEADERS, X0, 1.0, bad),
        "rtol": lambda: check_stress(om, fw, rtol=bad),
        "edges": lambda: stress_from_weights(5, bad, [1.0]),
        "weights": lambda: stress_from_weights(5, [(0, 1)], bad),
        "gain": lambda: make_law("stationary", part, si, 0.1, gain=bad),
        "d": lambda: LinearDynamics.double_integrator(bad),
        "positions": lambda: Framework(bad, fw.edges, LEADERS),
        "A": lambda: riccati_gain(bad, np.eye(2)),
        "n_leaders": lambda: trilateration(30, 2, seed=0, n_leaders=bad),
        "seed": lambda: trilateration(30, 2, seed=bad),
    }


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(bad=BAD, which=st.sampled_from(sorted(_calls(None))))
def test_malformed_inputs_name_the_argument(bad, which):
    call = _calls(bad)[which]
    if (which, repr(bad)) in VALID:  # a legitimate value: it may pass, or fail on its consequences
        return
    try:
        call()
    except (FormationError, ValueError, TypeError) as exc:
        msg = str(exc)
        assert which in msg or which.lower() in msg.lower(), f"{which}: {type(exc).__name__}: {msg}"
    else:  # only a value that is valid for this argument may pass
        assert (which, repr(bad)) in VALID, f"{which}={bad!r} silently accepted"


#: values in BAD that are legitimate for the argument
VALID = {("dt", "0.5"), ("gain", "0.5"), ("rtol", "0.5"), ("n_leaders", "None")}


def test_farthest_point_leaders_spread():
    r = np.random.default_rng(0).uniform(size=(500, 2))
    lead = farthest_point_leaders(r, 10)
    assert len(set(lead)) == 10
    dmin = min(np.linalg.norm(r[a] - r[b]) for i, a in enumerate(lead) for b in lead[:i])
    assert dmin > 0.15
    with pytest.raises(FormationError, match="count must be"):
        farthest_point_leaders(r, 0)


def test_sparse_omega_validated_too():
    om = sp.csr_matrix(asymmetric())
    with pytest.raises(StressMatrixError, match="symmetric"):
        follower_targets(om, LEADERS, X0[:3])


# ------------------------------------------------------------------ the frameworks library and the affine helpers
@pytest.mark.parametrize(
    ("call", "error", "match"),
    [
        (lambda: lib.hexagon(radius=-1.0), FormationError, "radius must be a positive finite length in metres, got -1"),
        (lambda: lib.hexagon(radius="1"), TypeError, r"radius must be a real number \(m\), got '1'"),
        (lambda: lib.square_grid(spacing=0.0), FormationError, "spacing must be a positive finite length"),
        (lambda: lib.triangle_formation(spacing=-1.0), FormationError, "spacing must be a positive finite length"),
        (lambda: lib.bipyramid(height=float("inf")), FormationError, "height must be a positive finite length"),
        (lambda: lib.cube_with_center(side=0.0), FormationError, "side must be a positive finite length"),
        (lambda: lib.helix(per_turn=0.0), FormationError, "per_turn must be a positive finite number of agents"),
        (lambda: lib.random_knn(seed=-1), FormationError, "seed must be an integer >= 0, got -1"),
        (lambda: lib.farthest_point_leaders(X0, 3, [9]), FormationError, r"fixed must be agent indices in 0..4, got 9"),
        (lambda: lib.get_framework("pentagon"), UnknownNameError, "name must be a registered framework"),
        (lambda: design_stress(paper_example(), "sdp", sparse="yes"), TypeError, "sparse must be True or False"),
        (lambda: design_stress(paper_example(), "sdp", verbose="x"), TypeError, "verbose must be True or False"),
        (lambda: equilibrium_stress_basis(None), TypeError, "fw must be a Framework, got None"),
        (lambda: equilibrium_stress_basis(paper_example(), -1.0), FormationError, "rtol must be"),
        (lambda: rotation(float("nan")), FormationError, "angle must be a finite number, got nan"),
        (lambda: rotation(None), TypeError, r"angle must be a real number \(rad\), got None"),
        (lambda: scaling(float("nan"), 1.0), FormationError, "factors holds 1 non-finite value"),
        (lambda: shear_matrix(float("nan")), FormationError, "amount must be a finite number, got nan"),
        (lambda: shear_matrix(0.5, 1.5), FormationError, "d must be an integer >= 2, got the float 1.5"),
        (lambda: translate([1.0, 0.0], 0.0, float("nan")), FormationError, "stop must be a finite number, got nan"),
        (lambda: translate([1.0, 0.0], "0"), TypeError, r"start must be a real number \(s\)"),
        (lambda: rotate(float("inf")), FormationError, "angle must be a finite number, got inf"),
        (lambda: scale(float("nan")), FormationError, "factors must be a finite number, got nan"),
        (lambda: scale(2.0, d=0), FormationError, "d must be an integer >= 1, got 0"),
        (lambda: shear(float("nan")), FormationError, "amount must be a finite number"),
        (lambda: hold(0), FormationError, "d must be an integer >= 1, got 0"),
        (lambda: hold(2, np.eye(3)), ControlDimension, r"theta must have shape \(2, 2\), got \(3, 3\)"),
        (lambda: translate([1.0, 0.0]).leader_path(X0[:3], 0.0), FormationError, "dt must be a positive finite"),
    ],
)
def test_library_and_affine_helpers_name_the_argument(call, error, match):
    with pytest.raises(error, match=match):
        call()


def test_get_framework_error_is_a_key_error_too():
    with pytest.raises(KeyError, match="unknown framework 'pentagon'"):
        lib.get_framework("pentagon")
