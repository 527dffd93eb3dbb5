"""Shared helpers for the maths-core tests: random generic frameworks with exact stresses.

``random_framework`` builds a "trilateration" framework without any solver:
agents 0..d form a simplex, and each agent i > d joins d + 1 earlier agents
(drawn at random), so {i} and its earlier neighbours form a clique K_{d+2}.
Each clique carries the rank-one stress a a^T with a spanning the null space
of [[p_1 .. p_{d+2}], [1 .. 1]] (:func:`clique_stress`); the sum is an
equilibrium stress, PSD, of rank n - d - 1 (the a's are independent: each has
a nonzero entry at its clique's newest agent and none after it), and Omega_ff
is positive definite for leaders 0..d (the same triangular argument). Agent
labels are then shuffled, so leaders are arbitrary indices.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

# The core works on tiny matrices, where OpenBLAS threads only add contention (10x slower
# on a loaded 2-core machine). Set before numpy is first imported.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np
import scipy.linalg as sla
from hypothesis import settings
from hypothesis import strategies as st

try:  # the package is not installed in every checkout: import it from the repository
    import formation_env  # noqa: F401
except ImportError:  # pragma: no cover
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from formation_env.core import Framework

# Property tests draw the same examples on every run (a CI run is reproducible; a failure found by a random
# search is then a test to add, not a flake): HYPOTHESIS_PROFILE=random searches afresh.
settings.register_profile("repro", derandomize=True, print_blob=True)
settings.register_profile("random", print_blob=True)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "repro"))


def crowded_followers() -> Framework:
    """10 agents in 2D (3 leaders, 7 followers close together, complete graph): with follower noise, many
    start draws are too crowded and drawn again, many are fine."""
    ang = np.linspace(0, 2 * np.pi, 8)[:-1] + 0.3
    r = np.concatenate([[[1.0, 0.0], [-0.5, 0.9], [-0.5, -0.9]], 0.6 * np.stack([np.cos(ang), np.sin(ang)], 1)])
    return Framework(r, [(i, j) for i in range(10) for j in range(i + 1, 10)], leaders=[0, 1, 2], name="ten")


def clique_vector(points: np.ndarray, clique: Sequence[int], n: int) -> np.ndarray:
    """The unit a in R^n supported on ``clique`` (d + 2 agents) with sum a_i = 0, sum a_i p_i = 0."""
    d = points.shape[1]
    h = np.vstack([points[list(clique)].T, np.ones(len(clique))])  # (d + 1, d + 2)
    a = sla.null_space(h)
    if a.shape[1] != 1:
        raise ValueError(f"clique {clique} is not in general position in R^{d}")
    full = np.zeros(n)
    full[list(clique)] = a[:, 0]
    return full


def clique_stress(points: np.ndarray, cliques: Sequence[Sequence[int]]) -> np.ndarray:
    """sum over cliques of a a^T: an exact PSD equilibrium stress of ``points``, shape (n, n)."""
    n = points.shape[0]
    vecs = [clique_vector(points, c, n) for c in cliques]
    return sum(np.outer(v, v) for v in vecs)


def clique_edges(cliques: Sequence[Sequence[int]]) -> list[tuple[int, int]]:
    """Every pair inside some clique, as sorted (i, j), i < j."""
    return sorted({(min(a, b), max(a, b)) for c in cliques for a in c for b in c if a != b})


@dataclass(frozen=True)
class RandomFramework:
    """A framework, its exact stress matrix, and the cliques that built it."""

    fw: Framework
    omega: np.ndarray
    cliques: tuple[tuple[int, ...], ...]
    clique_vectors: tuple[np.ndarray, ...]  # the a of each clique in R^n; sum of a a^T is omega


def random_framework(seed: int, n: int, d: int, max_cond: float = 40.0) -> RandomFramework:
    """A random generic trilateration framework in R^d with n agents and an exact stress.

    Draws points uniformly in [-1, 1]^d until every clique is well conditioned and
    cond(Omega_ff) <= ``max_cond`` (so the laws converge in a few hundred steps).
    Deterministic in ``seed``.
    """
    if n < d + 2:
        raise ValueError(f"need n >= d + 2, got n={n}, d={d}")
    rng = np.random.default_rng(seed)
    for _ in range(10_000):
        p = rng.uniform(-1.0, 1.0, size=(n, d))
        cliques = [tuple(sorted(rng.choice(i, d + 1, replace=False).tolist()) + [i]) for i in range(d + 1, n)]
        if any(np.linalg.svd(np.vstack([p[list(c)].T, np.ones(d + 2)]), compute_uv=False)[-1] < 0.1 for c in cliques):
            continue  # a nearly degenerate clique: not generic enough
        vecs = [clique_vector(p, c, n) for c in cliques]
        if any(abs(v[c[-1]]) < 0.1 for v, c in zip(vecs, cliques, strict=True)):
            continue
        omega = sum(np.outer(v, v) for v in vecs)
        lam = np.linalg.eigvalsh(omega[d + 1 :, d + 1 :])
        if lam[-1] / lam[0] > max_cond:
            continue
        perm = rng.permutation(n)  # old label i -> new label perm[i]
        r = np.empty_like(p)
        r[perm] = p
        om = np.empty_like(omega)
        om[np.ix_(perm, perm)] = omega
        new_cliques = tuple(tuple(int(perm[i]) for i in c) for c in cliques)
        new_vecs = []
        for v in vecs:
            w = np.empty_like(v)
            w[perm] = v
            new_vecs.append(w)
        leaders = [int(perm[i]) for i in range(d + 1)]
        fw = Framework(r, clique_edges(new_cliques), leaders, name=f"trilateration-{d}d-{n}-{seed}")
        return RandomFramework(fw, (om + om.T) / 2, new_cliques, tuple(new_vecs))
    raise RuntimeError("no well-conditioned framework found")  # pragma: no cover


def random_frameworks(dims: Sequence[int] = (2, 3), max_followers: int = 4) -> st.SearchStrategy[RandomFramework]:
    """Hypothesis strategy: random generic frameworks in R^d, d in ``dims``, with 1..max_followers followers."""
    return st.builds(
        lambda seed, d, nf: random_framework(seed, d + 1 + nf, d),
        st.integers(0, 2**32 - 1),
        st.sampled_from(list(dims)),
        st.integers(1, max_followers),
    )
