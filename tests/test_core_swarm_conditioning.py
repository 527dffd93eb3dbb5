"""Issue 21 (core): well-conditioned large swarms, cond(Omega_ff) <= 1e3 at n = 10,000 with 100 leaders."""

from __future__ import annotations

import time

import numpy as np
import pytest

from formation_env.core import Partition, design_stress, extreme_eigenvalues, stability_report
from formation_env.core.errors import FormationError
from formation_env.core.frameworks import trilateration


@pytest.mark.parametrize("d", [2, 3])
def test_hierarchical_trilateration_is_valid_and_better_conditioned(d):
    fw = trilateration(300, d, seed=1, n_leaders=3 * (d + 1))
    assert fw.leaders == tuple(range(3 * (d + 1))) and fw.cliques is not None
    om = design_stress(fw, "constructive")  # checked by check_stress
    lo, hi = extreme_eigenvalues(Partition(om, fw.leaders))
    base = design_stress(trilateration(300, d, seed=1), "constructive")
    blo, bhi = extreme_eigenvalues(Partition(base, range(d + 1)))
    assert hi / lo < 0.5 * bhi / blo


def test_n10000_k100_cond_below_1e3_in_under_10_s():
    t0 = time.perf_counter()
    fw = trilateration(10_000, 2, seed=0, n_leaders=100)
    om = design_stress(fw, "constructive")
    rep = stability_report(om, fw.leaders, 1.0)
    elapsed = time.perf_counter() - t0
    assert rep.cond <= 1e3
    assert elapsed < 10.0
    assert rep.dt_opt == pytest.approx(2 / (-rep.mu_max - rep.mu_min))
    assert fw.degree().max() < 100  # sparse: bounded degree
    assert om.nnz < 20 * fw.n


def test_n_leaders_validated():
    with pytest.raises(FormationError, match="n_leaders must be an integer >= 3"):
        trilateration(50, 2, n_leaders=2)
    with pytest.raises(FormationError, match="n_leaders"):
        trilateration(50, 2, n_leaders=7.5)
    with pytest.raises(FormationError, match="seed must be an integer >= 0"):
        trilateration(50, 2, seed=-1)
    np.testing.assert_array_equal(trilateration(20, 2, seed=3).positions, trilateration(20, 2, seed=3).positions)
