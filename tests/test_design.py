"""Stress design: every method gives a checked PSD stress of rank n - d - 1; min_cond beats sdp; error paths."""

from __future__ import annotations

import cvxpy as cp
import numpy as np
import pytest
import scipy.sparse as sp
from conftest import random_framework
from hypothesis import given, settings
from hypothesis import strategies as st

from formation_env.core import ControlDimension, Framework, FrameworkError, StressMatrixError, check_stress
from formation_env.core import design as design_mod
from formation_env.core.design import clique_stress, condition_number, design_stress, trilateration_cliques
from formation_env.core.frameworks import hexagon, random_knn, trilateration


def assert_valid(omega: np.ndarray | sp.csr_matrix, fw: Framework) -> None:
    """Independent of check_stress: symmetric, Omega [r, 1] = 0, PSD of rank n - d - 1, lambda_max(Omega_ff) = 1."""
    om = omega.toarray() if sp.issparse(omega) else np.asarray(omega)
    n, d = fw.n, fw.d
    np.testing.assert_allclose(om, om.T, atol=1e-12)
    np.testing.assert_allclose(om @ np.c_[fw.positions, np.ones(n)], 0.0, atol=1e-9 * (1 + np.abs(fw.positions).max()))
    eig = np.linalg.eigvalsh(om)
    assert eig[0] > -1e-9 * eig[-1]
    assert np.sum(eig > 1e-9 * eig[-1]) == n - d - 1
    f = list(fw.followers)
    assert np.linalg.eigvalsh(om[np.ix_(f, f)])[-1] == pytest.approx(1.0)
    for i, j in zip(*np.nonzero(np.triu(om, 1)), strict=True):
        assert (i, j) in fw.edges


# ------------------------------------------------------------------------------------------- valid stresses
@settings(max_examples=12, deadline=None)
@given(st.sampled_from([(2, 8), (3, 12)]), st.integers(6, 14), st.integers(0, 10_000), st.sampled_from(["sdp", "fast"]))
def test_sdp_methods_on_random_knn(dk: tuple[int, int], n: int, seed: int, method: str) -> None:
    d, k = dk
    fw = random_knn(n, d, k, seed)
    omega = design_stress(fw, method)
    assert isinstance(omega, np.ndarray)
    check_stress(omega, fw)
    assert_valid(omega, fw)


@settings(max_examples=12, deadline=None)
@given(st.integers(0, 2**32 - 1), st.sampled_from([2, 3]), st.integers(1, 6))
def test_all_methods_on_shuffled_trilateration(seed: int, d: int, nf: int) -> None:
    # conftest's frameworks have shuffled labels: the cliques come from the builder, not from index order.
    rf = random_framework(seed, d + 1 + nf, d)
    for method in ("sdp", "min_cond"):
        assert_valid(design_stress(rf.fw, method), rf.fw)
    omega = design_stress(rf.fw, "constructive", cliques=np.array(rf.cliques))
    assert sp.issparse(omega)
    assert_valid(omega, rf.fw)
    # The constructive stress is the builder's sum of a a^T, up to the scale.
    ref = rf.omega / np.linalg.eigvalsh(rf.omega[np.ix_(rf.fw.followers, rf.fw.followers)])[-1]
    np.testing.assert_allclose(omega.toarray(), ref, atol=1e-9)


@settings(max_examples=15, deadline=None)
@given(st.integers(0, 10_000), st.sampled_from([2, 3]), st.integers(5, 60))
def test_constructive_on_trilateration(seed: int, d: int, n: int) -> None:
    fw = trilateration(max(n, d + 2), d, seed)
    cliques = trilateration_cliques(fw)
    assert cliques.shape == (fw.n - d - 1, d + 2)
    np.testing.assert_array_equal(cliques[:, -1], np.arange(d + 1, fw.n))
    assert np.all(cliques[:, :-1] < cliques[:, -1:])
    for sparse in (True, False):
        omega = design_stress(fw, "constructive", sparse=sparse)
        assert sp.issparse(omega) == sparse
        assert_valid(omega, fw)


def test_constructive_at_n_2000_passes_the_sparse_check() -> None:
    fw = trilateration(2000, 2, seed=3)
    omega = design_stress(fw, "constructive")
    assert isinstance(omega, sp.csr_matrix)
    check_stress(omega, fw)
    f = np.setdiff1d(np.arange(fw.n), fw.leaders)
    lam = np.linalg.eigvalsh(omega.toarray()[np.ix_(f, f)])  # the dense reference for ARPACK
    assert lam[0] > 0
    np.testing.assert_allclose(condition_number(omega, fw.leaders), lam[-1] / lam[0], rtol=1e-6)


def test_sparse_check_rejects_an_indefinite_constructive_stress() -> None:
    fw = trilateration(500, 2, seed=1)
    cl = trilateration_cliques(fw)
    good = clique_stress(fw.positions, cl)
    check_stress(good, fw)
    bad = good - 2 * clique_stress(fw.positions, cl[100:101])  # one clique with a negative weight
    with pytest.raises(StressMatrixError, match=r"not positive definite|not positive semi-definite"):
        check_stress(bad, fw)


@pytest.mark.parametrize("n", [10, 16, 24])
@pytest.mark.parametrize("seed", [0, 1])
def test_min_cond_beats_sdp(n: int, seed: int) -> None:
    fw = random_knn(n, 2, 8, seed)
    kappa_sdp = condition_number(design_stress(fw, "sdp"), fw.leaders)
    kappa_fast = condition_number(design_stress(fw, "fast"), fw.leaders)
    assert kappa_fast <= kappa_sdp * (1 + 1e-3)


def test_fast_is_min_cond() -> None:
    fw = random_knn(12, 2, 8, 5)
    np.testing.assert_allclose(design_stress(fw, "fast"), design_stress(fw, "min_cond"), atol=1e-6)


def test_min_cond_with_more_than_d_plus_1_leaders() -> None:
    base = random_knn(14, 2, 8, 2)
    extra = next(i for i in range(base.n) if i not in base.leaders)
    fw = Framework(base.positions, base.edges, [*base.leaders, extra])
    for method in ("sdp", "min_cond"):
        assert_valid(design_stress(fw, method), fw)


def test_sparse_output_of_sdp() -> None:
    fw = random_knn(10, 2, 8, 0)
    omega = design_stress(fw, sparse=True)
    assert isinstance(omega, sp.csr_matrix)
    np.testing.assert_array_equal(omega.toarray(), design_stress(fw))


def test_scs_takes_over_when_clarabel_fails(monkeypatch: pytest.MonkeyPatch) -> None:
    solve = cp.Problem.solve

    def clarabel_fails(self: cp.Problem, *args: object, solver: str | None = None, **kwargs: object) -> object:
        if solver == "CLARABEL":
            raise cp.error.SolverError("simulated failure")
        return solve(self, *args, solver=solver, **kwargs)

    monkeypatch.setattr(cp.Problem, "solve", clarabel_fails)
    fw = random_knn(10, 2, 8, 0)
    for method in ("sdp", "min_cond"):
        assert_valid(design_stress(fw, method), fw)
    with pytest.raises(StressMatrixError, match=r"CLARABEL: solver error \(simulated failure\)"):
        design_stress(_fw(FOLDING_PTS, FOLDING_EDGES, [0, 2, 3]), solver="CLARABEL")


def test_polish_repairs_a_slightly_indefinite_answer() -> None:
    fw = random_knn(12, 2, 8, 4)
    basis = design_mod.equilibrium_stress_basis(fw)
    q = design_mod.sla.null_space(np.c_[fw.positions, np.ones(fw.n)].T)
    g = design_mod._congruence(fw.edge_array(), basis, q)
    good = np.linalg.lstsq(basis, -design_stress(fw)[tuple(fw.edge_array().T)], rcond=None)[0]
    m_good = np.tensordot(good, g, axes=1)
    lam, vec = np.linalg.eigh(m_good)
    # Push the smallest eigenvalue below zero inside the stress space (least squares), as SCS sometimes does.
    target = m_good - 2 * lam[0] * np.outer(vec[:, 0], vec[:, 0])
    bad = np.linalg.lstsq(g.reshape(len(good), -1).T, target.ravel(), rcond=None)[0]
    assert np.linalg.eigvalsh(np.tensordot(bad, g, axes=1))[0] < 0
    fixed = design_mod._polish(g, bad, 1e-8)
    assert fixed is not None
    assert np.linalg.eigvalsh(np.tensordot(fixed, g, axes=1))[0] > 0


def test_condition_number_sparse_matches_dense() -> None:
    fw = trilateration(400, 2, seed=0)  # 397 followers: the sparse path uses ARPACK
    omega = design_stress(fw, "constructive")
    assert condition_number(omega, fw.leaders) == pytest.approx(condition_number(omega.toarray(), fw.leaders), rel=1e-6)


# ------------------------------------------------------------------------------------------- error paths
def _fw(points: list[list[float]], edges: list[tuple[int, int]], leaders: list[int]) -> Framework:
    return Framework(np.array(points, dtype=float), edges, leaders)


GENERIC6 = [[0.0, 0.0], [3.1, 0.2], [1.4, 2.9], [1.1, 0.9], [2.2, 0.8], [1.6, 1.7]]
GENERIC7 = [*GENERIC6, [2.7, 2.1]]
K4 = [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]


def test_agent_with_too_few_neighbours() -> None:
    fw = _fw(GENERIC6, [*K4, (3, 4), (1, 4), (0, 4), (4, 5), (2, 5)], [0, 1, 2])
    with pytest.raises(StressMatrixError, match=r"agent 5 has 2 neighbour\(s\), fewer than d \+ 1 = 3"):
        design_stress(fw)


def test_framework_without_equilibrium_stress() -> None:
    # Triangular prism: 3-regular, 9 = 2n - 3 edges, generic positions: isostatic, no stress at all.
    prism = [(0, 1), (1, 2), (0, 2), (3, 4), (4, 5), (3, 5), (0, 3), (1, 4), (2, 5)]
    with pytest.raises(StressMatrixError, match="no nonzero equilibrium stress"):
        design_stress(_fw(GENERIC6, prism, [0, 1, 2]))


def test_stress_that_is_never_psd_hexagon_wheel() -> None:
    wheel = hexagon()
    fw = Framework(wheel.positions, [e for e in wheel.edges if e not in {(0, 3), (1, 4), (2, 5)}], wheel.leaders)
    for method in ("sdp", "min_cond"):
        with pytest.raises(StressMatrixError, match="not universally rigid"):
            design_stress(fw, method)


# Two braced squares sharing an edge: infinitesimally rigid, but they fold about the shared edge in R^3.
FOLDING_PTS = [[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [0.0, 1.0], [1.0, 1.0], [2.0, 1.0]]
FOLDING_EDGES = [(0, 1), (1, 2), (3, 4), (4, 5), (0, 3), (1, 4), (2, 5), (0, 4), (1, 3), (1, 5), (2, 4)]


def test_grid_that_folds_is_not_universally_rigid() -> None:
    with pytest.raises(StressMatrixError, match="not universally rigid"):
        design_stress(_fw(FOLDING_PTS, FOLDING_EDGES, [0, 2, 3]))


def test_every_solver_failing_is_reported(monkeypatch: pytest.MonkeyPatch) -> None:
    # Solvers stopped early give no verdict, and polishing cannot repair a framework with no PSD stress.
    monkeypatch.setitem(design_mod.SOLVER_SETTINGS, "CLARABEL", {"max_iter": 1})
    monkeypatch.setitem(design_mod.SOLVER_SETTINGS, "SCS", {"max_iters": 1})
    with pytest.raises(StressMatrixError, match=r"found no valid stress.*CLARABEL.*SCS"):
        design_stress(_fw(FOLDING_PTS, FOLDING_EDGES, [0, 2, 3]))


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"method": "best"}, "unknown method 'best'"),
        ({"solver": "NOT_A_SOLVER"}, "not an installed cvxpy solver"),
        ({"method": "constructive", "solver": "SCS"}, "solver applies to the SDP methods"),
        ({"method": "sdp", "cliques": [[0, 1, 2, 3]]}, "cliques applies to method 'constructive' only"),
    ],
)
def test_bad_arguments(kwargs: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        design_stress(trilateration(8, 2), **kwargs)


def test_constructive_needs_a_trilateration_ordering() -> None:
    with pytest.raises(FrameworkError, match=r"agent 3 has 2 neighbour.*needs a trilateration ordering"):
        design_stress(hexagon(), "constructive")
    # Agent 3 has exactly d + 1 = 3 earlier neighbours, but 1-2 is not an edge.
    fw = _fw(GENERIC6[:5], [e for e in K4 if e != (1, 2)] + [(1, 4), (2, 4), (3, 4)], [0, 1, 2])
    with pytest.raises(FrameworkError, match="earlier neighbours of agent 3 are not pairwise joined"):
        design_stress(fw, "constructive")
    # Agent 4 has four earlier neighbours: a triangle among them is found.
    k5 = _fw(GENERIC6[:5], [*K4, (0, 4), (1, 4), (2, 4), (3, 4)], [0, 1, 2])
    assert_valid(design_stress(k5, "constructive"), k5)
    # Agent 6's earlier neighbours 0, 3, 4, 5 hold no triangle.
    edges = [*K4, (1, 4), (2, 4), (3, 4), (0, 5), (1, 5), (2, 5), (0, 6), (3, 6), (4, 6), (5, 6)]
    with pytest.raises(FrameworkError, match=r"no d \+ 1 of the earlier neighbours \[0, 3, 4, 5\] of agent 6"):
        design_stress(_fw(GENERIC7, edges, [0, 1, 2]), "constructive")


def test_constructive_bad_cliques() -> None:
    fw = trilateration(8, 2)
    with pytest.raises(ControlDimension, match=r"shape \(N, d \+ 2 = 4\)"):
        design_stress(fw, "constructive", cliques=[[0, 1, 2]])
    with pytest.raises(FrameworkError, match=r"outside 0..7"):
        design_stress(fw, "constructive", cliques=[[0, 1, 2, 9]])
    # A clique on pairs that are not edges: the stress is not supported on the graph.
    with pytest.raises(StressMatrixError, match=r"fails its check.*not an edge"):
        design_stress(
            fw, "constructive", cliques=np.array([[0, 1, 2, 3], [1, 2, 3, 4], [0, 1, 4, 5], [2, 3, 5, 6], [0, 4, 6, 7]])
        )
    # Too few cliques: the last agent gets no stress, Omega_ff is singular (rank n - d - 2).
    with pytest.raises(StressMatrixError, match=r"fails its check: Omega_ff is singular"):
        design_stress(fw, "constructive", cliques=trilateration_cliques(fw)[:-1])


def test_constructive_clique_not_in_general_position() -> None:
    # Agent 3 is on the segment 0-1, so agent 4's partners 0, 1, 3 are collinear.
    pts = [[0.0, 0.0], [2.0, 0.0], [0.0, 2.0], [1.0, 0.0], [1.0, 1.0]]
    edges = [(0, 1), (0, 2), (1, 2), (0, 3), (1, 3), (2, 3), (0, 4), (1, 4), (3, 4)]
    with pytest.raises(StressMatrixError, match=r"clique \[0, 1, 3, 4\] is not in general position"):
        design_stress(_fw(pts, edges, [0, 1, 2]), "constructive")


def test_condition_number_of_a_singular_block() -> None:
    omega = np.zeros((5, 5))
    omega[3, 3] = 1.0
    with pytest.raises(StressMatrixError, match="not positive definite"):
        condition_number(omega, [0, 1, 2])


def test_design_bench_smoke() -> None:
    from benchmarks import design_bench

    rows = design_bench.run(quick=True, sdp_sizes=(8,), constructive_sizes=(50,))
    assert [r["method"] for r in rows] == ["sdp", "fast", "constructive"]
    assert all(r["cond"] >= 1.0 and r["median_s"] > 0 for r in rows)
    assert design_bench.markdown(rows).count("\n") == len(rows) + 1


def test_large_sdp_warns(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(design_mod, "_SLOW_SDP_N", 8)
    fw = random_knn(10, 2, 8, 0)
    with pytest.warns(UserWarning, match=r"with n = 10: the SDP's cost grows like n\^6"):
        design_stress(fw)
