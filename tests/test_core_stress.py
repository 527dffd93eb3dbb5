"""Stress matrices and frameworks: every check of ``check_stress``, ``Framework`` and the helpers."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from conftest import RandomFramework, clique_edges, clique_stress, random_framework, random_frameworks
from hypothesis import given, settings
from hypothesis import strategies as st

from formation_env.core import (
    ControlDimension,
    FormationError,
    Framework,
    FrameworkError,
    Partition,
    StressMatrixError,
    check_stress,
    equilibrium_stress_basis,
    follower_targets,
    paper_example,
    paper_omega,
    project_stress,
    stress_from_weights,
)
from formation_env.core.frameworks import PAPER_OMEGA_PRINTED
from formation_env.core.stress import weights_from_stress

SPARSE_KINDS = [sp.csr_matrix, sp.csc_matrix, sp.coo_matrix, sp.csr_array]


# ---------------------------------------------------------------------- valid stresses


@pytest.mark.parametrize("kind", [np.asarray, *SPARSE_KINDS], ids=lambda k: k.__name__)
def test_paper_stress_passes(kind):
    check_stress(kind(paper_omega()), paper_example())


@settings(max_examples=25, deadline=None)
@given(random_frameworks())
def test_random_stress_passes_dense_and_sparse(rf: RandomFramework):
    check_stress(rf.omega, rf.fw)
    check_stress(sp.csr_matrix(rf.omega), rf.fw)
    check_stress(3.7 * rf.omega, rf.fw)  # any positive multiple is a stress too


# Mutations of a valid stress; each either keeps it valid or breaks one property.
def _mutations(rf: RandomFramework, rng: np.random.Generator) -> dict[str, tuple[np.ndarray, bool]]:
    om = rf.omega
    v = rf.clique_vectors[rng.integers(len(rf.clique_vectors))]
    i, j = rf.fw.edges[rng.integers(len(rf.fw.edges))]
    lap = np.zeros_like(om)
    lap[[i, j], [i, j]] = 1.0
    lap[i, j] = lap[j, i] = -1.0
    asym = om.copy()
    asym[i, j] += 0.1
    # Re-weighting the cliques by positive factors keeps a valid stress.
    reweighted = sum(
        w * np.outer(a, a)
        for w, a in zip(rng.uniform(0.2, 5.0, len(rf.clique_vectors)), rf.clique_vectors, strict=True)
    )
    return {
        "valid": (om, True),
        "reweighted": (reweighted, True),
        "negated_clique": (om - 2 * np.outer(v, v), False),  # one negative eigenvalue
        "dropped_clique": (om - np.outer(v, v), False),  # rank n - d - 2 (zero matrix if one clique)
        "not_equilibrium": (om + 0.1 * lap, False),
        "asymmetric": (asym, False),
        "negated": (-om, False),
    }


@settings(max_examples=25, deadline=None)
@given(random_frameworks(), st.integers(0, 2**32 - 1))
def test_sparse_and_dense_checks_agree(rf: RandomFramework, seed: int):
    rng = np.random.default_rng(seed)
    for name, (om, valid) in _mutations(rf, rng).items():
        outcomes = []
        for mat in (om, sp.csr_matrix(om)):
            try:
                check_stress(mat, rf.fw)
                outcomes.append(True)
            except StressMatrixError:
                outcomes.append(False)
        assert outcomes == [valid, valid], name


@settings(max_examples=25, deadline=None)
@given(random_frameworks(max_followers=5).filter(lambda rf: rf.fw.n >= rf.fw.d + 3))
def test_extra_leaders_put_failures_in_the_schur_complement(rf: RandomFramework):
    # Leaders = the first clique (d + 2 agents, affinely spanning): Omega_ff stays positive definite
    # when that clique's term is negated or dropped, so the sparse check must find the failure in
    # the leaders' Schur complement S = Omega_ll - Omega_lf Omega_ff^-1 Omega_fl (rank n_l - d - 1 = 1).
    fw = Framework(rf.fw.positions, rf.fw.edges, rf.cliques[0])
    a = rf.clique_vectors[0]
    assert np.all(a[list(fw.followers)] == 0.0)
    check_stress(rf.omega, fw)
    check_stress(sp.csr_matrix(rf.omega), fw)
    for om, match in (
        (rf.omega - 2 * np.outer(a, a), "not positive semi-definite"),
        (rf.omega - np.outer(a, a), rf"rank n - d - 1 = {fw.n - fw.d - 1}"),
    ):
        with pytest.raises(StressMatrixError, match=match):
            check_stress(om, fw)
        with pytest.raises(StressMatrixError, match=match):
            check_stress(sp.csr_matrix(om), fw)


# ---------------------------------------------------------------------- each failed property


def _edge_laplacian(n: int, i: int, j: int) -> np.ndarray:
    e = np.zeros(n)
    e[i], e[j] = 1.0, -1.0
    return np.outer(e, e)


def _rank_one_paper_stress() -> np.ndarray:
    # a = (1, -1, -1, 1, 0) is an affine dependency of agents 1-4 of the paper's framework:
    # a a^T is an equilibrium stress on its edges, PSD, but of rank 1 < n - d - 1 = 2.
    a = np.array([1.0, -1.0, -1.0, 1.0, 0.0])
    return np.outer(a, a)


def _perturbed(om: np.ndarray, i: int, j: int, delta: float) -> np.ndarray:
    out = om.copy()
    out[i, j] += delta
    return out


FAILURES = {
    "asymmetric": (lambda om: _perturbed(om, 3, 4, 1e-3), "not symmetric"),
    "row_sums": (lambda om: _perturbed(om, 3, 3, 1e-3), "rows must sum to zero"),
    "not_equilibrium": (lambda om: om + 0.1 * _edge_laplacian(5, 3, 4), "not an equilibrium stress"),
    "not_psd": (lambda om: -om, "not positive semi-definite"),
    "wrong_rank": (lambda om: _rank_one_paper_stress(), r"rank n - d - 1 = 2 .*got rank 1"),
    "zero": (lambda om: np.zeros_like(om), "zero matrix"),
    "wrong_shape": (lambda om: om[:4, :4], r"shape \(5, 5\)"),
}


@pytest.mark.parametrize("name", list(FAILURES))
def test_each_failed_property_is_named(name):
    make, match = FAILURES[name]
    with pytest.raises(StressMatrixError, match=match):
        check_stress(make(paper_omega()), paper_example())


@pytest.mark.parametrize("name", ["asymmetric", "row_sums", "not_equilibrium", "zero", "wrong_shape"])
def test_each_failed_property_is_named_sparse(name):
    # These checks share code between the dense and sparse paths: same message.
    make, match = FAILURES[name]
    with pytest.raises(StressMatrixError, match=match):
        check_stress(sp.csr_matrix(make(paper_omega())), paper_example())


@pytest.mark.parametrize("name", ["not_psd", "wrong_rank"])
def test_spectral_failures_sparse(name):
    # The sparse path infers PSD and rank from Omega_ff's LDL^T and the leaders' Schur complement.
    make, _ = FAILURES[name]
    with pytest.raises(StressMatrixError, match=r"positive definite|positive semi-definite|rank|Omega_ff"):
        check_stress(sp.csr_matrix(make(paper_omega())), paper_example())


def test_entry_off_the_graph():
    fw = paper_example()
    without = Framework(fw.positions, [e for e in fw.edges if e != (3, 4)], fw.leaders)
    # The message names the offending entry and its value (Omega[3, 4] = -w_34 = -0.5).
    with pytest.raises(StressMatrixError, match=r"Omega\[3, 4\] = -0\.5 but \(3, 4\) is not an edge"):
        check_stress(paper_omega(), without)
    with pytest.raises(StressMatrixError, match=r"Omega\[3, 4\] = -0\.5 but \(3, 4\) is not an edge"):
        check_stress(sp.csr_matrix(paper_omega()), without)
    check_stress(paper_omega(), without, check_graph=False)


def _near_collinear_leaders(thickness: float) -> tuple[np.ndarray, Framework]:
    # Leaders 0, 1, 2 span R^2 only by ``thickness``; followers 3, 4 are generic, and every
    # clique holds a follower, so Omega has rank n - d - 1 = 2 however thin the leaders are.
    r = np.array([[1.0, 0.0], [0.0, thickness], [-1.0, 0.0], [0.3, 1.1], [-0.4, -0.8]])
    cliques = [(0, 1, 3, 4), (1, 2, 3, 4)]
    return clique_stress(r, cliques), Framework(r, clique_edges(cliques), [0, 1, 2])


def test_near_collinear_leaders_make_omega_ff_singular():
    om, fw = _near_collinear_leaders(1e-7)
    with pytest.raises(StressMatrixError, match="Omega_ff is singular"):
        check_stress(om, fw)
    with pytest.raises(StressMatrixError, match="Omega_ff"):
        check_stress(sp.csr_matrix(om), fw)
    om_ok, fw_ok = _near_collinear_leaders(0.5)  # the same construction with well-spread leaders passes
    check_stress(om_ok, fw_ok)
    check_stress(sp.csr_matrix(om_ok), fw_ok)


def test_omega_ff_singular_by_tolerance():
    # lambda_min(Omega_ff) = 0.0489 lies below lambda_{d+2}(Omega) = 0.454 (interlacing), so a
    # tolerance between them keeps rank n - d - 1 but declares Omega_ff singular.
    om = paper_omega()
    rtol = 0.1  # eigenvalue tolerance 0.1 * 2.088 = 0.209
    with pytest.raises(StressMatrixError, match="Omega_ff is singular"):
        check_stress(om, paper_example(), rtol=rtol)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_stress(bad):
    om = paper_omega()
    om[3, 4] = om[4, 3] = bad
    with pytest.raises(FormationError, match="NaN or inf"):
        check_stress(om, paper_example())
    with pytest.raises(FormationError, match="NaN or inf"):
        check_stress(sp.csr_matrix(om), paper_example())


def test_dimension_mismatch_is_control_dimension():
    with pytest.raises(ControlDimension, match="2 dimensions"):
        check_stress(np.ones(5), paper_example())
    with pytest.raises(ControlDimension, match="2 dimensions"):
        Framework(np.ones(5), [(0, 1)], [0])
    with pytest.raises(ControlDimension, match="one entry per edge"):
        stress_from_weights(5, [(0, 1), (1, 2)], [1.0])
    with pytest.raises(ControlDimension, match=r"x_leaders must have shape \(\.\.\., 3, d\)"):
        follower_targets(paper_omega(), [0, 1, 2], np.zeros((4, 2)))
    with pytest.raises(ControlDimension, match="square"):
        Partition(np.zeros((5, 4)), [0, 1, 2])


# ---------------------------------------------------------------------- frameworks


def _square_with_centre() -> tuple[np.ndarray, list[tuple[int, int]]]:
    r = np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [0.0, -1.0], [0.1, 0.2]])
    edges = [(i, j) for i in range(5) for j in range(i + 1, 5)]
    return r, edges


def test_framework_basics():
    r, edges = _square_with_centre()
    fw = Framework(r, [(j, i) for i, j in reversed(edges)], [4, 0, 1], name="sq")
    assert (fw.n, fw.d) == (5, 2)
    assert fw.edges == tuple(edges)  # normalised (i < j) and sorted
    assert fw.followers == (2, 3)
    assert fw.neighbours(2) == [0, 1, 3, 4]
    np.testing.assert_array_equal(fw.degree(), [4, 4, 4, 4, 4])
    assert fw.edge_array().shape == (10, 2)
    with pytest.raises(ValueError, match="read-only"):
        fw.positions[0, 0] = 5.0


FRAMEWORK_ERRORS = {
    "collinear_leaders_2d": (
        dict(positions=[[0, 0], [1, 1], [2, 2], [0, 1], [1, 0]], leaders=[0, 1, 2]),
        "do not affinely span R\\^2",
    ),
    "coplanar_leaders_3d": (
        dict(
            positions=[[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [0, 0, 1], [1, 0, 1]],
            leaders=[0, 1, 2, 3],
        ),
        "do not affinely span R\\^3",
    ),
    "too_few_leaders": (dict(leaders=[0, 1]), "at least d \\+ 1 = 3"),
    "duplicate_leaders": (dict(leaders=[0, 1, 1]), "duplicates"),
    "leader_out_of_range": (dict(leaders=[0, 1, 7]), "outside 0..4"),
    "all_leaders": (dict(leaders=[0, 1, 2, 3, 4]), "leaders must leave at least one follower"),
    "self_loop": (dict(edges=[(0, 1), (2, 2)]), "edges must join two distinct agents.*self-loop"),
    "duplicate_edge": (dict(edges=[(0, 1), (1, 0)]), r"edges must list each pair once.*\(0, 1\) twice"),
    "edge_out_of_range": (dict(edges=[(0, 5)]), "outside 0..4"),
    "edge_not_a_pair": (dict(edges=[(0, 1, 2)]), r"edges must be \(i, j\) pairs.*\(0, 1, 2\)"),
    "too_few_agents": (dict(positions=[[0, 0], [1, 0], [0, 1]], leaders=[0, 1, 2]), "at least d \\+ 2 = 4 agents"),
}


@pytest.mark.parametrize("name", list(FRAMEWORK_ERRORS))
def test_framework_errors(name):
    r, edges = _square_with_centre()
    kwargs = dict(positions=r, edges=edges, leaders=[0, 1, 2])
    change, match = FRAMEWORK_ERRORS[name]
    kwargs.update(change)
    if "edges" not in change:
        n = len(kwargs["positions"])
        kwargs["edges"] = [(i, j) for i in range(n) for j in range(i + 1, n)]
    with pytest.raises(FrameworkError, match=match):
        Framework(**kwargs)


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_framework_non_finite(bad):
    r, edges = _square_with_centre()
    r[4, 1] = bad
    with pytest.raises(FormationError, match="NaN or inf"):
        Framework(r, edges, [0, 1, 2])


def test_partition_rejects_bad_leaders():
    with pytest.raises(FrameworkError, match="distinct indices"):
        Partition(paper_omega(), [0, 1, 1])
    with pytest.raises(FrameworkError, match="distinct indices"):
        Partition(paper_omega(), [0, 1, 5])
    with pytest.raises(FrameworkError, match="distinct indices"):
        Partition(paper_omega(), [])


# ---------------------------------------------------------------------- the paper's matrix


def test_printed_paper_matrix_needs_loose_tolerance():
    fw = paper_example()
    with pytest.raises(StressMatrixError, match="rows must sum to zero"):
        check_stress(PAPER_OMEGA_PRINTED, fw)
    check_stress(PAPER_OMEGA_PRINTED, fw, rtol=1e-3)
    np.testing.assert_array_equal(paper_omega(exact=False), PAPER_OMEGA_PRINTED)


@pytest.mark.parametrize("call", ["simulate", "stability_report", "follower_targets", "check_stress"])
def test_printed_paper_matrix_error_names_both_remedies_and_rtol_reaches_the_check(call: str) -> None:
    """The refusal of the rounded matrix says how to accept it (``rtol=1e-3``) and how to fix it (``project_stress``,
    ``paper_omega()``); ``rtol=1e-3`` passed to the same call accepts it."""
    from formation_env.core import simulate, stability_report

    fw = paper_example()
    om = PAPER_OMEGA_PRINTED
    calls = {
        "simulate": lambda **kw: simulate(om, [0, 1, 2], fw.positions, dt=1.0, steps=3, **kw),
        "stability_report": lambda **kw: stability_report(om, [0, 1, 2], dt=1.0, **kw),
        "follower_targets": lambda **kw: follower_targets(om, [0, 1, 2], fw.positions[:3], **kw),
        "check_stress": lambda **kw: check_stress(om, fw, **kw),
    }
    with pytest.raises(StressMatrixError, match=r"rows must sum to zero.*rtol=1e-3.*project_stress.*paper_omega\(\)"):
        calls[call]()
    calls[call](rtol=1e-3)


def test_project_stress_gives_an_exact_stress_with_the_paper_targets():
    fw = paper_example()
    om = project_stress(PAPER_OMEGA_PRINTED, fw)
    np.testing.assert_allclose(om, paper_omega())
    check_stress(om, fw)  # default tolerance
    np.testing.assert_allclose(om, om.T, atol=0)
    assert np.max(np.abs(om.sum(axis=1))) < 1e-14
    assert np.max(np.abs(om @ fw.positions)) < 1e-14
    assert np.max(np.abs(om - PAPER_OMEGA_PRINTED)) < 1e-3  # only the rounding moved
    assert om[0, 4] == 0.0  # no weight off the graph
    targets = follower_targets(om, [0, 1, 2], fw.positions[:3])
    np.testing.assert_allclose(targets, [[-1.0, 0.0], [-2.0, 0.0]], atol=1e-12)


def test_project_stress_errors():
    fw = paper_example()
    with pytest.raises(StressMatrixError, match=r"shape \(5, 5\)"):
        project_stress(np.eye(4), fw)
    # A framework with too few edges has no equilibrium stress at all.
    tree = Framework(fw.positions, [(0, 1), (1, 2), (2, 3), (3, 4)], [0, 1, 2])
    with pytest.raises(StressMatrixError, match="no nonzero equilibrium stress"):
        project_stress(PAPER_OMEGA_PRINTED, tree)


# ---------------------------------------------------------------------- helpers


@settings(max_examples=25, deadline=None)
@given(random_frameworks())
def test_equilibrium_stress_basis(rf: RandomFramework):
    fw = rf.fw
    basis = equilibrium_stress_basis(fw)
    # Generic infinitesimally rigid frameworks have m - n d + d (d + 1) / 2 independent stresses,
    # at least the n - d - 1 cliques' (more where cliques add edges among earlier agents).
    m, n, d = len(fw.edges), fw.n, fw.d
    assert basis.shape == (m, m - n * d + d * (d + 1) // 2)
    assert basis.shape[1] >= n - d - 1
    np.testing.assert_allclose(basis.T @ basis, np.eye(basis.shape[1]), atol=1e-10)
    for k in range(basis.shape[1]):
        om = stress_from_weights(fw.n, fw.edges, basis[:, k])
        assert np.max(np.abs(om @ fw.positions)) < 1e-10
    # The construction's stress lies in the span.
    w = weights_from_stress(rf.omega, fw.edges)
    np.testing.assert_allclose(basis @ (basis.T @ w), w, atol=1e-10)


@settings(max_examples=25, deadline=None)
@given(random_frameworks())
def test_weights_round_trip_dense_and_sparse(rf: RandomFramework):
    fw = rf.fw
    w = weights_from_stress(rf.omega, fw.edges)
    dense = stress_from_weights(fw.n, fw.edges, w)
    sparse = stress_from_weights(fw.n, fw.edges, w, sparse=True)
    assert sp.issparse(sparse)
    np.testing.assert_allclose(dense, rf.omega, atol=1e-12)
    np.testing.assert_allclose(sparse.toarray(), dense, atol=0)
    np.testing.assert_allclose(weights_from_stress(sparse, fw.edges), w, atol=0)


@settings(max_examples=25, deadline=None)
@given(random_frameworks(), st.integers(0, 2**32 - 1))
def test_follower_targets_are_the_affine_image(rf: RandomFramework, seed: int):
    # Lemma 2: leaders at an affine image Theta r_l + b put the followers' targets at Theta r_f + b.
    rng = np.random.default_rng(seed)
    fw = rf.fw
    d, lead, fol = fw.d, list(fw.leaders), list(fw.followers)
    theta = rng.normal(size=(3, d, d))
    b = rng.normal(size=(3, d))
    images = np.einsum("bij,nj->bni", theta, fw.positions) + b[:, None, :]  # (3, n, d)
    for omega in (rf.omega, sp.csr_matrix(rf.omega)):
        batched = follower_targets(omega, lead, images[:, lead])
        assert batched.shape == (3, len(fol), d)
        np.testing.assert_allclose(batched, images[:, fol], atol=1e-9)
        single = follower_targets(omega, lead, images[1, lead])
        assert single.shape == (len(fol), d)
        np.testing.assert_allclose(single, batched[1], atol=1e-12)


def test_follower_targets_batched_shapes_match_a_loop():
    rng = np.random.default_rng(0)
    xl = rng.normal(size=(2, 4, 3, 2))  # (batch..., n_l, d)
    out = follower_targets(paper_omega(), [0, 1, 2], xl)
    assert out.shape == (2, 4, 2, 2)
    for i in range(2):
        for j in range(4):
            np.testing.assert_allclose(out[i, j], follower_targets(paper_omega(), [0, 1, 2], xl[i, j]), atol=1e-14)
    # The state dimension need not be d: targets of velocities, or of full double-integrator states.
    assert follower_targets(paper_omega(), [0, 1, 2], rng.normal(size=(3, 4))).shape == (2, 4)


def test_partition_blocks_and_localisation():
    om = paper_omega()
    part = Partition(om, [2, 0, 1])  # leader order is kept
    np.testing.assert_array_equal(part.leaders, [2, 0, 1])
    np.testing.assert_array_equal(part.followers, [3, 4])
    np.testing.assert_allclose(part.omega_fl, om[np.ix_([3, 4], [2, 0, 1])])
    np.testing.assert_allclose(part.localisation @ np.ones(3), np.ones(2), atol=1e-12)  # rows sum to 1
    # Schur complement on the leaders is PSD with rank n_l - d - 1 = 0: zero for d + 1 leaders.
    np.testing.assert_allclose(part.schur_complement(), 0.0, atol=1e-12)
    sparse = Partition(sp.csr_matrix(om), [2, 0, 1])
    np.testing.assert_allclose(sparse.localisation, part.localisation, atol=1e-12)


def test_random_framework_helper_is_deterministic():
    a, b = random_framework(5, 7, 3), random_framework(5, 7, 3)
    np.testing.assert_array_equal(a.omega, b.omega)
    assert a.fw.leaders == b.fw.leaders
