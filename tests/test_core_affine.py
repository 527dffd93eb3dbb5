"""Affine targets, manoeuvres, the affine-image fit, and the paper's simulation study (Section 4.3)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from formation_env.core import (
    AffineImage,
    ControlDimension,
    FormationError,
    Maneuver,
    affine_targets,
    follower_targets,
    hold,
    paper_example,
    paper_omega,
    rotate,
    rotation,
    scale,
    scaling,
    shear,
    shear_matrix,
    simulate,
    translate,
)

seeds = st.integers(0, 2**32 - 1)
PAPER_X0 = np.array([[1.0, 0.0], [0.0, 1.0], [0.0, -1.0], [-4.0, 3.0], [-3.0, -2.0]])


# ---------------------------------------------------------------------- affine_targets and matrices


def test_affine_targets_values_and_shapes():
    r = np.array([[1.0, 0.0], [0.0, 1.0], [2.0, 3.0]])
    theta = np.array([[2.0, 1.0], [0.0, -1.0]])
    b = np.array([0.5, -1.0])
    out = affine_targets(r, theta, b)
    assert out.shape == (3, 2)
    np.testing.assert_allclose(out, [[2.5, -1.0], [1.5, -2.0], [7.5, -4.0]])
    # Batched Theta and b: (..., n, d), each slice the unbatched answer.
    rng = np.random.default_rng(0)
    thetas, bs = rng.normal(size=(4, 5, 2, 2)), rng.normal(size=(4, 5, 2))
    batched = affine_targets(r, thetas, bs)
    assert batched.shape == (4, 5, 3, 2)
    np.testing.assert_allclose(batched[2, 3], affine_targets(r, thetas[2, 3], bs[2, 3]))
    # Batched Theta with one shared b broadcasts.
    assert affine_targets(r, thetas[0], b).shape == (5, 3, 2)


def test_affine_targets_errors():
    r = np.zeros((3, 2))
    with pytest.raises(ControlDimension, match=r"theta must be \(\.\.\., 2, 2\)"):
        affine_targets(r, np.eye(3), np.zeros(2))
    with pytest.raises(ControlDimension, match=r"b \(\.\.\., 2\)"):
        affine_targets(r, np.eye(2), np.zeros(3))
    with pytest.raises(ControlDimension, match="r must have 2 dimensions"):
        affine_targets(np.zeros(3), np.eye(2), np.zeros(2))
    with pytest.raises(FormationError, match="NaN or inf"):
        affine_targets(r, [[1.0, np.nan], [0.0, 1.0]], np.zeros(2))


@settings(max_examples=25, deadline=None)
@given(st.floats(-10, 10), st.none() | st.tuples(st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1)))
def test_rotation_is_orthogonal_with_det_one(angle, axis):
    if axis is not None and np.linalg.norm(axis) < 1e-3:
        axis = (0.0, 0.0, 1.0)
    R = rotation(angle, axis)
    d = 2 if axis is None else 3
    assert R.shape == (d, d)
    np.testing.assert_allclose(R @ R.T, np.eye(d), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-12)
    if axis is not None:  # the axis is fixed
        np.testing.assert_allclose(R @ np.asarray(axis), np.asarray(axis), atol=1e-12)


def test_rotation_direction_and_3d_axis_errors():
    np.testing.assert_allclose(rotation(np.pi / 2) @ [1.0, 0.0], [0.0, 1.0], atol=1e-15)  # counter-clockwise
    np.testing.assert_allclose(rotation(np.pi / 2, axis=[0, 0, 1]) @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(rotation(0.3, axis=[0, 0, 2])[:2, :2], rotation(0.3), atol=1e-15)
    with pytest.raises(ControlDimension, match="nonzero 3-vector"):
        rotation(0.1, axis=[0.0, 0.0, 0.0])
    with pytest.raises(ControlDimension, match="nonzero 3-vector"):
        rotation(0.1, axis=[1.0, 0.0])


def test_scaling_and_shear_matrices():
    np.testing.assert_array_equal(scaling(2.0, 3.0), np.diag([2.0, 3.0]))
    np.testing.assert_array_equal(shear_matrix(0.5, d=3, i=0, j=2), [[1, 0, 0.5], [0, 1, 0], [0, 0, 1]])
    with pytest.raises(FormationError, match="scaling factors must be nonzero"):
        scaling(1.0, 0.0)
    with pytest.raises(FormationError, match="scaling factors must be nonzero"):
        scaling()
    with pytest.raises(FormationError, match="shear axes must be distinct"):
        shear_matrix(0.5, d=2, i=1, j=1)
    with pytest.raises(FormationError, match=r"shear axes must be distinct in 0\.\.1"):
        shear_matrix(0.5, d=2, i=0, j=2)


# ---------------------------------------------------------------------- manoeuvres


def test_primitives_ramp_and_hold():
    r = paper_example().positions
    m = scale(2.0, start=1.0, stop=3.0)
    np.testing.assert_allclose(m(0.0)[0], np.eye(2))  # before start
    np.testing.assert_allclose(m(2.0)[0], 1.5 * np.eye(2))  # smoothstep midpoint
    np.testing.assert_allclose(m(10.0)[0], 2.0 * np.eye(2))  # held after stop
    lin = translate([4.0, -2.0], start=0.0, stop=4.0, smooth=False)
    np.testing.assert_allclose(lin(1.0)[1], [1.0, -0.5])
    np.testing.assert_allclose(lin.targets(r, 9.0), r + [4.0, -2.0])
    np.testing.assert_allclose(rotate(np.pi / 2, 0.0, 1.0)(5.0)[0], rotation(np.pi / 2), atol=1e-15)
    np.testing.assert_allclose(shear(0.5, 0.0, 1.0)(1.0)[0], shear_matrix(0.5))
    np.testing.assert_allclose(scale([2.0, 3.0, 4.0], 0.0, 1.0)(1.0)[0], np.diag([2.0, 3.0, 4.0]))
    assert rotate(0.3, axis=[1, 0, 0]).d == 3
    th, b = hold(2, theta=2 * np.eye(2), b=[1.0, 1.0])(7.0)
    np.testing.assert_array_equal(th, 2 * np.eye(2))
    np.testing.assert_array_equal(b, [1.0, 1.0])
    with pytest.raises(FormationError, match="scale factors must be positive"):
        scale(0.0)
    with pytest.raises(FormationError, match="shear axes must be distinct"):
        shear(0.5, i=0, j=0)


def test_composition_applies_the_right_operand_first():
    m1 = translate([1.0, 0.0], 0.0, 1.0)
    m2 = rotate(np.pi / 2, 0.0, 1.0)
    r = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    # (m2 @ m1): translate by (1, 0), then rotate by 90 degrees.
    np.testing.assert_allclose((m2 @ m1).targets(r, 1.0), [[0.0, 1.0], [0.0, 2.0], [-1.0, 1.0]], atol=1e-15)
    # (m1 @ m2): rotate, then translate: not the same.
    np.testing.assert_allclose((m1 @ m2).targets(r, 1.0), [[1.0, 0.0], [1.0, 1.0], [0.0, 0.0]], atol=1e-15)
    # Non-commuting Thetas: (rotate @ shear) has Theta = R S, not S R.
    sh = shear(1.0, 0.0, 1.0)
    rs = (m2 @ sh)(1.0)[0]
    np.testing.assert_allclose(rs, rotation(np.pi / 2) @ shear_matrix(1.0), atol=1e-15)
    assert np.abs(rs - shear_matrix(1.0) @ rotation(np.pi / 2)).max() > 0.5
    # Three-fold composition is associative and matches nested affine_targets.
    m3 = scale([2.0, 0.5], 0.0, 1.0) @ sh
    for t in (0.0, 0.4, 1.0):
        a = (m3 @ (m2 @ m1)).targets(r, t)
        b = ((m3 @ m2) @ m1).targets(r, t)
        nested = m3.targets(m2.targets(m1.targets(r, t), t), t)
        np.testing.assert_allclose(a, b, atol=1e-14)
        np.testing.assert_allclose(a, nested, atol=1e-14)
    with pytest.raises(ControlDimension, match="cannot compose a 3D and a 2D"):
        rotate(0.1, axis=[0, 0, 1]) @ m1


def test_leader_path_samples_the_manoeuvre():
    r = paper_example().positions[:3]
    m = rotate(np.pi, 0.0, 10.0, smooth=False)
    path = m.leader_path(r, dt=0.5)
    np.testing.assert_allclose(path(10), r @ rotation(np.pi / 2).T, atol=1e-14)  # t = 5 s: halfway
    np.testing.assert_allclose(path(0), r)


# ---------------------------------------------------------------------- affine image


@settings(max_examples=25, deadline=None)
@given(seeds, st.sampled_from([2, 3]), st.integers(0, 4))
def test_affine_image_error_and_fit(seed, d, extra):
    rng = np.random.default_rng(seed)
    n = d + 2 + extra
    r = rng.normal(size=(n, d))
    img = AffineImage(r)
    theta, b = rng.normal(size=(d, d)), rng.normal(size=d)
    x = affine_targets(r, theta, b)
    assert img.error(x) < 1e-10
    th_fit, b_fit = img.fit(x)
    np.testing.assert_allclose(th_fit, theta, atol=1e-9)
    np.testing.assert_allclose(b_fit, b, atol=1e-9)
    # A displacement orthogonal to every affine image of r is all error.
    noise = img.residual(rng.normal(size=(n, d)))
    assert np.linalg.norm(noise) > 1e-6
    expected = np.sqrt(np.mean(np.sum(noise**2, axis=-1)))
    assert img.error(x + noise) == pytest.approx(expected, rel=1e-9)
    # Batched.
    batch = np.stack([x, x + noise, 2 * x])
    np.testing.assert_allclose(img.error(batch), [0.0, expected, 0.0], atol=1e-9)
    assert img.fit(batch)[0].shape == (3, d, d)


def test_affine_image_needs_a_spanning_configuration():
    with pytest.raises(FormationError, match=r"r \(the nominal configuration\) must affinely span R\^2.*dimension 1"):
        AffineImage([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0], [3.0, 3.0]])


def test_maneuver_targets_keep_stress_targets_consistent():
    # Moving the leaders along any manoeuvre puts the followers' stress targets on the same manoeuvre.
    fw = paper_example()
    m = shear(0.7, 0.0, 1.0) @ rotate(0.4, 0.0, 1.0) @ translate([1.0, 2.0], 0.0, 1.0)
    for t in (0.0, 0.5, 1.0):
        tg = m.targets(fw.positions, t)
        np.testing.assert_allclose(follower_targets(paper_omega(), [0, 1, 2], tg[:3]), tg[3:], atol=1e-12)


def test_maneuver_is_a_dataclass_of_functions():
    m = Maneuver(2, lambda t: t * np.eye(2), lambda t: np.array([t, 0.0]), "custom")
    np.testing.assert_allclose(m.targets([[1.0, 1.0]], 2.0), [[4.0, 2.0]])


# ---------------------------------------------------------------------- the paper's simulation study


def test_paper_reproduction_stationary_leaders():
    # Section 4.3: the printed stress (rounded to 3 decimals: checked at rtol 1e-3), T = 1 s, 180 samples (3 min).
    omega = paper_omega(exact=False)
    pos = simulate(omega, [0, 1, 2], PAPER_X0, dt=1.0, steps=180, law="stationary", rtol=1e-3)
    assert pos.shape == (181, 5, 2)
    np.testing.assert_array_equal(pos[:, :3], np.broadcast_to(PAPER_X0[:3], (181, 3, 2)))  # leaders stay
    np.testing.assert_allclose(pos[-1, 3:], [[-1.0, 0.0], [-2.0, 0.0]], atol=1e-3)
    # ... and not already at step 20: the followers really moved there.
    assert np.max(np.abs(pos[20, 3:] - [[-1.0, 0.0], [-2.0, 0.0]])) > 0.1


def test_paper_reproduction_scaling_manoeuvre():
    # After reaching the formation the leaders scale it (to avoid an obstacle); the followers track it.
    omega = paper_omega()
    r = paper_example().positions
    m = scale([0.5, 2.0], start=180.0, stop=220.0)
    steps = 500
    res = simulate(omega, [0, 1, 2], PAPER_X0, 1.0, steps, "stationary", m.leader_path(r[:3], 1.0), return_result=True)
    pos = res.positions
    np.testing.assert_allclose(pos[180, 3:], r[3:], atol=1e-3)
    scaled = m.targets(r, 10_000.0)
    np.testing.assert_allclose(pos[-1, :3], scaled[:3], atol=1e-12)  # leaders are placed on the path
    np.testing.assert_allclose(pos[-1, 3:], scaled[3:], atol=1e-6)
    np.testing.assert_allclose(res.targets[-1], scaled[3:], atol=1e-12)
    # During the manoeuvre the stationary law lags behind the moving targets.
    assert res.errors[200] > 1e-3
