"""The framework library: every registered framework builds, its leaders span, and a stress can be designed for it."""

from __future__ import annotations

import inspect

import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import given, settings
from hypothesis import strategies as st

from formation_env.core import Framework, FrameworkError, check_stress
from formation_env.core import frameworks as lib
from formation_env.core.design import condition_number, design_stress, trilateration_cliques
from formation_env.core.framework import affine_rank

#: Smaller sizes for the random generators, so that the SDP runs in a fraction of a second.
SMALL = {"random_knn": {"n": 14}, "trilateration": {"n": 20}}

#: Frameworks whose edges are a union of cliques K_{d+2} in index order.
TRILATERATION = {"trilateration", "helix"}


def test_registry_holds_every_builder() -> None:
    builders = {
        name
        for name, fn in inspect.getmembers(lib, inspect.isfunction)
        if fn.__module__ == lib.__name__
        and not name.startswith("_")
        and inspect.signature(fn).return_annotation == "Framework"
    }
    assert builders - {"get_framework"} == set(lib.REGISTRY)


@pytest.mark.parametrize("name", sorted(lib.REGISTRY))
def test_registered_framework_builds_and_gets_a_stress(name: str) -> None:
    fw = lib.get_framework(name, **SMALL.get(name, {}))
    assert isinstance(fw, Framework)
    assert fw.name
    assert len(fw.leaders) == fw.d + 1
    assert affine_rank(fw.positions[list(fw.leaders)]) == fw.d
    assert affine_rank(fw.positions) == fw.d
    for method in ("sdp", "min_cond") + (("constructive",) if name in TRILATERATION else ()):
        omega = design_stress(fw, method)
        check_stress(omega, fw)
        assert condition_number(omega, fw.leaders) >= 1.0


def test_default_arguments_build() -> None:
    # The env looks builders up by name and calls them without arguments.
    for name, builder in lib.REGISTRY.items():
        assert isinstance(builder(), Framework), name


def test_get_framework_errors() -> None:
    with pytest.raises(KeyError, match=r"unknown framework 'pentagon'; registered: .*hexagon"):
        lib.get_framework("pentagon")
    with pytest.raises(TypeError, match="unexpected keyword argument"):
        lib.get_framework("hexagon", sides=5)


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: lib.square_grid(1, 3), "rows must be an integer >= 2"),
        (lambda: lib.triangle_formation(2), "rows must be an integer >= 3"),
        (lambda: lib.bipyramid(3), "k must be an integer >= 4"),
        (lambda: lib.helix(4), "n must be an integer >= 5"),
        (lambda: lib.random_knn(10, 2, k=2), "k must be an integer >= 3"),
        (lambda: lib.random_knn(3, 2), "n must be an integer >= 4"),
        (lambda: lib.trilateration(20, 0), "d must be an integer >= 1"),
        (lambda: lib.trilateration(2.5, 2), r"n must be an integer >= 4, got 2\.5"),
        (lambda: lib.spread_leaders(np.zeros((5, 2)), 2), r"count must lie in d \+ 1 = 3 \.\. n = 5"),
    ],
)
def test_bad_sizes(call: object, match: str) -> None:
    with pytest.raises(FrameworkError, match=match):
        call()  # type: ignore[operator]


@pytest.mark.parametrize(("rows", "cols"), [(2, 2), (2, 5), (4, 3)])
def test_square_grid_shape(rows: int, cols: int) -> None:
    fw = lib.square_grid(rows, cols, spacing=2.0)
    assert fw.n == rows * cols
    assert np.ptp(fw.positions, axis=0).tolist() == [2.0 * (cols - 1), 2.0 * (rows - 1)]
    check_stress(design_stress(fw), fw)


def test_named_shapes_sizes() -> None:
    assert (lib.hexagon().n, len(lib.hexagon().edges)) == (7, 15)
    assert (lib.octahedron().n, len(lib.octahedron().edges)) == (6, 15)
    assert (lib.cube_with_center().n, len(lib.cube_with_center().edges)) == (9, 32)
    assert (lib.square_grid().n, len(lib.square_grid().edges)) == (9, 26)
    assert (lib.triangle_formation().n, len(lib.triangle_formation().edges)) == (10, 27)
    assert lib.triangle_formation(5).n == 15
    assert lib.bipyramid(7).n == 9


@settings(max_examples=10, deadline=None)
@given(st.integers(4, 300), st.sampled_from([1, 2, 3]), st.integers(0, 10_000))
def test_trilateration_structure(n: int, d: int, seed: int) -> None:
    n = max(n, d + 2)
    fw = lib.trilateration(n, d, seed)
    assert fw.leaders == tuple(range(d + 1))
    cliques = trilateration_cliques(fw)
    # The edges are exactly the union of the cliques K_{d+2}.
    pairs = {(int(a), int(b)) for c in cliques for i, a in enumerate(c) for b in c[i + 1 :]}
    assert pairs == set(fw.edges)
    # Every agent lies strictly inside the simplex of its d + 1 partners (interpolation, not extrapolation).
    h = np.concatenate([fw.positions[cliques[:, :-1]].transpose(0, 2, 1), np.ones((len(cliques), 1, d + 1))], axis=1)
    beta = np.linalg.solve(h, np.c_[fw.positions[cliques[:, -1]], np.ones(len(cliques))][..., None])[..., 0]
    assert np.all(beta > 0)
    # Deterministic in its seed.
    np.testing.assert_array_equal(lib.trilateration(n, d, seed).positions, fw.positions)


def test_trilateration_10000_is_fast_and_valid() -> None:
    fw = lib.trilateration(10_000, 2, seed=0)
    omega = design_stress(fw, "constructive")
    assert isinstance(omega, sp.csr_matrix)
    assert omega.nnz <= fw.n + 2 * len(fw.edges)


@pytest.mark.parametrize("d", [1, 2, 3])
def test_random_knn_is_deterministic_and_symmetric(d: int) -> None:
    a, b = lib.random_knn(25, d, k=d + 4, seed=7), lib.random_knn(25, d, k=d + 4, seed=7)
    np.testing.assert_array_equal(a.positions, b.positions)
    assert a.edges == b.edges
    assert a.leaders == b.leaders
    assert np.all(a.degree() >= d + 4)
    assert not np.array_equal(lib.random_knn(25, d, k=d + 4, seed=8).positions, a.positions)


def test_spread_leaders_pick_extremes() -> None:
    square = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0], [0.5, 0.5], [0.4, 0.6]])
    chosen = lib.spread_leaders(square)
    assert len(chosen) == 3
    assert set(chosen) <= {0, 1, 2, 3}
    assert len(lib.spread_leaders(square, 4)) == 4


def test_named_frameworks_live_in_the_core_with_their_stress() -> None:
    """``NAMED_FRAMEWORKS`` (name -> (Framework, omega)) is the core's; the env's scenarios re-export the same dict."""
    from formation_env.env.scenarios import NAMED_FRAMEWORKS as env_named

    assert env_named is lib.NAMED_FRAMEWORKS
    assert set(lib.NAMED_FRAMEWORKS) == {"paper", "bipyramid_3d"}
    for name, make in lib.NAMED_FRAMEWORKS.items():
        fw, omega = make()
        check_stress(omega, fw)
        assert fw.name == {"paper": "paper_example"}.get(name, name)
    fw = lib.bipyramid_3d()
    np.testing.assert_allclose(lib.gram_stress(fw), lib.NAMED_FRAMEWORKS["bipyramid_3d"]()[1])
    assert fw.d == 3 and fw.leaders == (0, 1, 2, 3)


def test_named_frameworks_import_without_the_env() -> None:
    """The core stays numpy/scipy only: the named frameworks import without gymnasium, pettingzoo, numba or pygame."""
    import json
    import subprocess
    import sys
    from pathlib import Path

    code = (
        "import json, sys\n"
        "from formation_env.core.frameworks import NAMED_FRAMEWORKS, bipyramid_3d, gram_stress\n"
        "NAMED_FRAMEWORKS['bipyramid_3d']()\n"
        "print(json.dumps([m for m in ('gymnasium', 'pettingzoo', 'numba', 'pygame', 'torch') if m in sys.modules]))\n"
    )
    root = Path(__file__).resolve().parents[1]
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=root, timeout=120)
    assert res.returncode == 0, res.stderr
    assert json.loads(res.stdout.strip().splitlines()[-1]) == []
