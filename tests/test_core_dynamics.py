"""Agent dynamics: exact ZOH sampling, integrators, and the (modified) Riccati equation."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal
from hypothesis import given, settings
from hypothesis import strategies as st

from formation_env.core import ControlDimension, FormationError, LinearDynamics, c2d_zoh, dare, dlqr, riccati_gain

seeds = st.integers(0, 2**32 - 1)


def _random_pair(rng: np.random.Generator, q: int, p: int) -> tuple[np.ndarray, np.ndarray]:
    return rng.normal(size=(q, q)), rng.normal(size=(q, p))


@settings(max_examples=25, deadline=None)
@given(seeds, st.integers(1, 5), st.integers(1, 3), st.floats(1e-3, 3.0))
def test_c2d_zoh_matches_scipy(seed, q, p, dt):
    rng = np.random.default_rng(seed)
    A, B = _random_pair(rng, q, p)
    ad, bd = c2d_zoh(A, B, dt)
    ref = scipy.signal.cont2discrete((A, B, np.eye(q), np.zeros((q, p))), dt, method="zoh")
    np.testing.assert_allclose(ad, ref[0], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(bd, ref[1], rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("d", [1, 2, 3])
@pytest.mark.parametrize("dt", [0.01, 0.5, 2.0])
def test_single_integrator_is_identity_plus_dt(d, dt):
    dyn = LinearDynamics.single_integrator(d)
    ad, bd = dyn.zoh(dt)
    np.testing.assert_allclose(ad, np.eye(d), atol=1e-15)
    np.testing.assert_allclose(bd, dt * np.eye(d), rtol=1e-14)
    assert dyn.is_single_integrator
    assert (dyn.q, dyn.p, dyn.d) == (d, d, d)


@pytest.mark.parametrize("d", [1, 2, 3])
@pytest.mark.parametrize("dt", [0.01, 0.5, 2.0])
def test_double_integrator_blocks(d, dt):
    dyn = LinearDynamics.double_integrator(d)
    ad, bd = dyn.zoh(dt)
    eye, zero = np.eye(d), np.zeros((d, d))
    np.testing.assert_allclose(ad, np.block([[eye, dt * eye], [zero, eye]]), atol=1e-14)
    np.testing.assert_allclose(bd, np.vstack([dt**2 / 2 * eye, dt * eye]), rtol=1e-13, atol=1e-15)
    assert not dyn.is_single_integrator
    assert (dyn.q, dyn.p, dyn.d) == (2 * d, d, d)
    # Position output and states at rest.
    x = dyn.state_from_position(np.arange(2 * d, dtype=float).reshape(2, d))
    np.testing.assert_allclose(x[:, d:], 0.0)
    np.testing.assert_allclose(dyn.position(x), np.arange(2 * d, dtype=float).reshape(2, d))


def test_step_is_batched_and_exact():
    dyn = LinearDynamics.double_integrator(2)
    rng = np.random.default_rng(1)
    x, u = rng.normal(size=(3, 5, 4)), rng.normal(size=(3, 5, 2))
    out = dyn.step(x, u, 0.3)
    ad, bd = dyn.zoh(0.3)
    for i in range(3):
        for j in range(5):
            np.testing.assert_allclose(out[i, j], ad @ x[i, j] + bd @ u[i, j], atol=1e-14)
    # Position after holding acceleration a for T from rest: a T^2 / 2.
    np.testing.assert_allclose(dyn.position(dyn.step(np.zeros(4), np.array([2.0, -4.0]), 0.5)), [0.25, -0.5])


def test_discrete_dynamics_are_used_as_given():
    A, B = np.array([[0.5, 0.1], [0.0, 0.9]]), np.array([[0.0], [1.0]])
    dyn = LinearDynamics(A, B, discrete=True)
    ad, bd = dyn.zoh(123.0)
    np.testing.assert_array_equal(ad, A)
    np.testing.assert_array_equal(bd, B)


def _residual(A, B, Q, R, P):
    g = R + B.T @ P @ B
    return A.T @ P @ A - P - A.T @ P @ B @ np.linalg.solve(g, B.T @ P @ A) + Q


@settings(max_examples=25, deadline=None)
@given(seeds, st.integers(1, 4), st.integers(1, 3), st.booleans())
def test_dare_residual_and_stabilising_gain(seed, q, p, cheap):
    rng = np.random.default_rng(seed)
    p = min(p, q)
    A, B = _random_pair(rng, q, p)  # generic: controllable, B full column rank
    Q = np.eye(q) + 0.1 * (lambda m: m @ m.T)(rng.normal(size=(q, q)))
    R = None if cheap else np.diag(rng.uniform(0.1, 2.0, p))
    P = dare(A, B, Q, R)
    Rm = np.zeros((p, p)) if R is None else R
    np.testing.assert_allclose(P, P.T, atol=0)
    assert np.min(np.linalg.eigvalsh(P)) > 0
    scale = max(1.0, float(np.max(np.abs(P))))
    assert np.max(np.abs(_residual(A, B, Q, Rm, P))) < 1e-8 * scale
    # R = None is the paper's modified Riccati gain K = -(B'PB)^-1 B'PA (Theorem 3); A + B K is Schur.
    K = riccati_gain(A, B, Q, R)
    np.testing.assert_allclose(K, -np.linalg.solve(Rm + B.T @ P @ B, B.T @ P @ A), rtol=1e-10, atol=1e-12)
    assert np.max(np.abs(np.linalg.eigvals(A + B @ K))) < 1.0


def test_dlqr_matches_riccati_gain():
    dyn = LinearDynamics.double_integrator(1)
    ad, bd = dyn.zoh(0.5)
    K, P, E = dlqr(ad, bd, np.eye(2), np.eye(1))
    np.testing.assert_allclose(P, dare(ad, bd, np.eye(2), np.eye(1)))
    np.testing.assert_allclose(-K, riccati_gain(ad, bd, np.eye(2), np.eye(1)))
    np.testing.assert_allclose(np.sort_complex(E), np.sort_complex(np.linalg.eigvals(ad - bd @ K)))
    assert np.all(np.abs(E) < 1)


def test_modified_riccati_on_the_double_integrator():
    # The cheap-control gain for the sampled double integrator is real and Schur at every T.
    for dt in (0.01, 0.1, 0.5, 1.0, 2.0, 5.0):
        ad, bd = LinearDynamics.double_integrator(1).zoh(dt)
        ev = np.linalg.eigvals(ad + bd @ riccati_gain(ad, bd))
        assert np.max(np.abs(ev)) < 1.0


@pytest.mark.parametrize(
    ("call", "exc", "match"),
    [
        (lambda: c2d_zoh(np.ones((2, 3)), np.ones((2, 1)), 0.1), ControlDimension, r"A must have shape \(2, 2\)"),
        (lambda: c2d_zoh(np.eye(2), np.ones((3, 1)), 0.1), ControlDimension, r"B must have shape \(2, \*\)"),
        (lambda: c2d_zoh(np.eye(2), np.ones(2), 0.1), ControlDimension, "B must have 2 dimensions"),
        (lambda: c2d_zoh(np.eye(2), np.ones((2, 1)), 0.0), FormationError, "dt must be a positive finite"),
        (lambda: c2d_zoh(np.eye(2), np.ones((2, 1)), -1.0), FormationError, "dt must be a positive finite"),
        (lambda: c2d_zoh(np.eye(2), np.ones((2, 1)), float("nan")), FormationError, "dt must be a positive finite"),
        (lambda: c2d_zoh(np.eye(2), np.ones((2, 1)), float("inf")), FormationError, "dt must be a positive finite"),
        (lambda: c2d_zoh([[np.nan, 0], [0, 0]], np.ones((2, 1)), 0.1), FormationError, "NaN or inf"),
        (lambda: LinearDynamics(np.ones((2, 3)), np.ones((2, 1))), ControlDimension, r"A must have shape"),
        (lambda: LinearDynamics(np.eye(2), [[1.0, 2.0], [2.0, 4.0]]), FormationError, "B must have full column rank"),
        (lambda: LinearDynamics(np.eye(2), np.eye(2), C=np.ones((1, 3))), ControlDimension, r"C must have shape"),
        (lambda: LinearDynamics.single_integrator(2).zoh(-0.1), FormationError, "dt must be a positive finite"),
        (lambda: LinearDynamics.double_integrator(2).state_from_position(np.ones(3)), ControlDimension, "d = 2"),
        (lambda: dare(np.ones((2, 3)), np.ones((2, 1))), ControlDimension, r"A must have shape"),
        (lambda: dare(np.eye(2), [[1.0, 2.0], [2.0, 4.0]]), FormationError, "B must have full column rank"),
        (
            lambda: dare(np.eye(2), np.ones((2, 1)), Q=-np.eye(2)),
            FormationError,
            "Q must be symmetric positive definite",
        ),
        (lambda: dare(np.eye(2), np.ones((2, 1)), Q=np.eye(3)), ControlDimension, r"Q must have shape \(2, 2\)"),
        (lambda: dare(np.eye(2), np.ones((2, 1)), R=np.eye(2)), ControlDimension, r"R must have shape \(1, 1\)"),
        # An unstable mode the input cannot reach: not stabilisable.
        (lambda: dare(np.diag([2.0, 0.5]), [[0.0], [1.0]], R=np.eye(1)), FormationError, "no stabilising solution"),
    ],
)
def test_errors(call, exc, match):
    with pytest.raises(exc, match=match):
        call()
