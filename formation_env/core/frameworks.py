"""A library of named frameworks: the paper's 5-agent example, classic shapes in 2D and 3D, random generators.

Every builder returns a :class:`Framework` with d + 1 affinely spanning leaders
and is listed in :data:`REGISTRY` (:func:`get_framework` builds one by name).
Each is universally rigid with a designable stress
(:func:`formation_env.core.design.design_stress`); the paper's printed matrix is
:func:`paper_omega`. ``trilateration`` and ``helix`` also admit the solver-free
``design_stress(fw, "constructive")``. :data:`NAMED_FRAMEWORKS` are the frameworks
that come with their own stress matrix (the env's ``framework="paper"`` and
``"bipyramid_3d"``): the paper's, and :func:`gram_stress` of the complete graph.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from .errors import FrameworkError, UnknownNameError
from .framework import Framework
from .validation import as_array, as_index_array, check_int, check_real_scalar, check_seed

__all__ = [
    "NAMED_FRAMEWORKS",
    "PAPER_OMEGA_PRINTED",
    "REGISTRY",
    "bipyramid",
    "bipyramid_3d",
    "cube_with_center",
    "farthest_point_leaders",
    "get_framework",
    "gram_stress",
    "helix",
    "hexagon",
    "octahedron",
    "paper_example",
    "paper_omega",
    "random_knn",
    "spread_leaders",
    "square_grid",
    "triangle_formation",
    "trilateration",
]

#: The stress matrix exactly as printed in the paper (Section 4.3), rounded to 3 decimals.
#: Agents 1-3 (indices 0-2) are leaders, 4-5 (indices 3-4) followers. Its rows sum to
#: about -0.001 and one eigenvalue is about -4.6e-4, so it passes :func:`check_stress`
#: only with ``rtol=1e-3``; :func:`paper_omega` with ``exact=True`` projects it.
PAPER_OMEGA_PRINTED: NDArray[np.float64] = np.array(
    [
        [0.292, -0.292, -0.292, 0.292, 0.0],
        [-0.292, 0.354, 0.354, -0.542, 0.125],
        [-0.292, 0.354, 0.354, -0.542, 0.125],
        [0.292, -0.542, -0.542, 1.292, -0.500],
        [0.0, 0.125, 0.125, -0.500, 0.250],
    ]
)
PAPER_OMEGA_PRINTED.setflags(write=False)


def paper_example() -> Framework:
    """The paper's 5-agent framework (Fig. 1): leaders (1,0), (0,1), (0,-1); followers (-1,0), (-2,0).

    The edges are the nonzero off-diagonal entries of the printed stress matrix
    (every pair but agents 1 and 5).
    """
    r = np.array([[1.0, 0.0], [0.0, 1.0], [0.0, -1.0], [-1.0, 0.0], [-2.0, 0.0]])
    edges = [(i, j) for i in range(5) for j in range(i + 1, 5) if PAPER_OMEGA_PRINTED[i, j] != 0.0]
    return Framework(r, edges, leaders=[0, 1, 2], name="paper_example")


def paper_omega(exact: bool = True) -> NDArray[np.float64]:
    """The paper's stress matrix: as printed (``exact=False``) or projected onto the nearest exact stress."""
    if not exact:
        return PAPER_OMEGA_PRINTED.copy()
    from .stress import project_stress

    return project_stress(PAPER_OMEGA_PRINTED, paper_example())


# ------------------------------------------------------------------------------------------- classic shapes
def _edges_within(points: NDArray[np.float64], steps: NDArray[np.float64], tol: float = 1e-9) -> NDArray[np.int64]:
    """Pairs (i, j), i < j, with r_j - r_i equal to +- one of ``steps`` (k, d) up to ``tol``, shape (m, 2)."""
    pairs = cKDTree(points).query_pairs(float(np.linalg.norm(steps, axis=1).max()) + tol, output_type="ndarray")
    diff = points[pairs[:, 1]] - points[pairs[:, 0]]
    same = np.abs(diff[:, None, :] - steps[None, :, :]).max(axis=-1) < tol
    flip = np.abs(diff[:, None, :] + steps[None, :, :]).max(axis=-1) < tol
    return pairs[(same | flip).any(axis=1)]


def _check_count(value: int, minimum: int, what: str) -> None:
    try:
        check_int(value, what, low=minimum)
    except TypeError:
        raise
    except ValueError as exc:
        raise FrameworkError(f"{what} must be an integer >= {minimum}, got {value!r}") from exc


def _length(value: float, name: str) -> float:
    """A positive, finite length in metres (a zero or negative one collapses or mirrors the shape)."""
    return check_real_scalar(value, name, low=0.0, unit="m", what="a positive finite length in metres")


def hexagon(radius: float = 1.0) -> Framework:
    """A regular hexagon with its centre: 7 agents, 15 edges, in R^2.

    Edges: the rim, the six spokes to the centre (agent 6) and the three long
    diagonals. The bare wheel (rim and spokes) has no PSD stress of rank
    n - d - 1 = 4; the diagonals make it universally rigid. Leaders are the
    alternate vertices 0, 2, 4.

    Parameters
    ----------
    radius
        Distance of the vertices from the centre, in metres.
    """
    radius = _length(radius, "radius")
    ang = np.arange(6) * np.pi / 3
    r = radius * np.vstack([np.c_[np.cos(ang), np.sin(ang)], [0.0, 0.0]])
    rim = [(i, (i + 1) % 6) for i in range(6)]
    spokes = [(i, 6) for i in range(6)]
    diagonals = [(0, 3), (1, 4), (2, 5)]
    return Framework(r, rim + spokes + diagonals, leaders=[0, 2, 4], name="hexagon")


def square_grid(rows: int = 3, cols: int = 3, spacing: float = 1.0) -> Framework:
    """A rows x cols square lattice in R^2, n = rows * cols.

    Edges: the sides and both diagonals of every cell, and the second neighbours
    along each row and column (i.e. two cells apart). Without those the grid
    folds along a lattice line in R^3 and is not universally rigid. Agent
    ``i * cols + j`` sits at (j, i) * spacing; leaders are the corners (0, 0),
    (cols - 1, 0) and (0, rows - 1).

    Parameters
    ----------
    rows, cols
        Lattice size, each at least 2.
    spacing
        Side of a cell, in metres.
    """
    _check_count(rows, 2, "rows")
    _check_count(cols, 2, "cols")
    spacing = _length(spacing, "spacing")
    r = spacing * np.array([[j, i] for i in range(rows) for j in range(cols)], dtype=np.float64)
    steps = spacing * np.array([[1, 0], [0, 1], [1, 1], [1, -1], [2, 0], [0, 2]], dtype=np.float64)
    leaders = [0, cols - 1, (rows - 1) * cols]
    return Framework(r, _edges_within(r, steps), leaders, name=f"square_grid_{rows}x{cols}")


def triangle_formation(rows: int = 4, spacing: float = 1.0) -> Framework:
    """A triangular wedge of the triangular lattice in R^2, n = rows (rows + 1) / 2.

    Row i (from the base) holds rows - i agents. Edges: the lattice edges and the
    second neighbours along the three lattice directions (without them the wedge
    folds along a lattice line in R^3). Leaders are the three corners.

    Parameters
    ----------
    rows
        Agents on the base, at least 3.
    spacing
        Lattice spacing, in metres.
    """
    _check_count(rows, 3, "rows")
    spacing = _length(spacing, "spacing")
    ij = [(i, j) for i in range(rows) for j in range(rows - i)]
    r = spacing * np.array([[j + i / 2, i * np.sqrt(3) / 2] for i, j in ij])
    unit = spacing * np.array([[1.0, 0.0], [0.5, np.sqrt(3) / 2], [-0.5, np.sqrt(3) / 2]])
    leaders = [ij.index((0, 0)), ij.index((0, rows - 1)), ij.index((rows - 1, 0))]
    return Framework(r, _edges_within(r, np.vstack([unit, 2 * unit])), leaders, name=f"triangle_{rows}")


def bipyramid(k: int = 6, radius: float = 1.0, height: float = 1.0) -> Framework:
    """A k-gonal bipyramid in R^3: a ring of k agents at z = 0 and apexes at z = +-height, n = k + 2.

    Edges: the ring, the chords joining ring agents two apart, every apex-ring
    pair and the axis between the apexes. Leaders are ring agents 0 and 1 and
    both apexes (agents k and k + 1).

    Parameters
    ----------
    k
        Ring size, at least 4 (k = 4 is the braced octahedron, see :func:`octahedron`).
    radius, height
        Ring radius and apex height, in metres.
    """
    _check_count(k, 4, "k")
    radius, height = _length(radius, "radius"), _length(height, "height")
    ang = 2 * np.pi * np.arange(k) / k
    r = np.vstack([np.c_[radius * np.cos(ang), radius * np.sin(ang), np.zeros(k)], [[0, 0, height], [0, 0, -height]]])
    ring = {tuple(sorted((i, (i + s) % k))) for i in range(k) for s in (1, 2)}
    apexes = [(i, a) for a in (k, k + 1) for i in range(k)]
    return Framework(r, sorted(ring) + apexes + [(k, k + 1)], leaders=[0, 1, k, k + 1], name=f"bipyramid_{k}")


def octahedron(radius: float = 1.0) -> Framework:
    """The regular octahedron with its three long diagonals in R^3 (the complete graph on its 6 vertices).

    Vertices +-radius e_x, +-radius e_y, +-radius e_z are the square bipyramid
    (:func:`bipyramid` with k = 4). The bare octahedron has no nonzero
    equilibrium stress (it is isostatic), so the diagonals are needed.
    """
    fw = bipyramid(4, radius, radius)
    return Framework(fw.positions, fw.edges, fw.leaders, name="octahedron")


def cube_with_center(side: float = 2.0) -> Framework:
    """A cube with its centre in R^3: 9 agents, 32 edges.

    Edges: the 12 cube edges, both diagonals of each face and the 8 spokes to the
    centre (agent 8). Agent i is the corner whose coordinates are the bits of i
    (0 -> -side/2, 1 -> +side/2, x the high bit). Leaders are the alternate
    corners 0, 3, 5, 6 (a regular tetrahedron).
    """
    side = _length(side, "side")
    corners = np.array([[(i >> 2) & 1, (i >> 1) & 1, i & 1] for i in range(8)], dtype=np.float64)
    r = side * (np.vstack([corners, [0.5, 0.5, 0.5]]) - 0.5)
    hamming = np.abs(corners[:, None, :] - corners[None, :, :]).sum(-1)
    cube = [(i, j) for i in range(8) for j in range(i + 1, 8) if hamming[i, j] in (1, 2)]
    return Framework(r, cube + [(i, 8) for i in range(8)], leaders=[0, 3, 5, 6], name="cube_with_center")


def helix(n: int = 12, radius: float = 1.0, pitch: float = 1.0, per_turn: float = 2.7) -> Framework:
    """n agents on a circular helix in R^3, each joined to the next four.

    Agent i sits at angle 2 pi i / per_turn and height pitch * i / per_turn. The
    cliques {i, ..., i + 4} make it a trilateration framework in index order
    (usable with ``design_stress(fw, "constructive")``). Leaders are the four
    middle agents n // 2 - 2 .. n // 2 + 1, so that errors spread both ways along
    the chain: with leaders at one end cond(Omega_ff) of the SDP stress is about
    60 at n = 12 (about 23 from the middle), and it grows fast with n either way.

    Parameters
    ----------
    n
        Number of agents, at least 5.
    radius, pitch
        Helix radius and rise per turn, in metres (the stress does not depend on
        ``pitch``: a change of pitch is an affine map).
    per_turn
        Agents per turn. Values near 2.7 gave the best-conditioned stresses in our
        trials (per_turn = 5 gives cond(Omega_ff) of about 1,500 at n = 12).
    """
    _check_count(n, 5, "n")
    radius, pitch = _length(radius, "radius"), _length(pitch, "pitch")
    per_turn = check_real_scalar(per_turn, "per_turn", low=0.0, what="a positive finite number of agents per turn")
    t = np.arange(n) / per_turn
    r = np.c_[radius * np.cos(2 * np.pi * t), radius * np.sin(2 * np.pi * t), pitch * t]
    edges = [(i, j) for i in range(n) for j in range(i + 1, min(i + 5, n))]
    return Framework(r, edges, leaders=range(n // 2 - 2, n // 2 + 2), name=f"helix_{n}")


# ------------------------------------------------------------------------------------------- random generators
def spread_leaders(positions: NDArray[np.float64], count: int | None = None) -> list[int]:
    """Greedy well-spread leaders: ``count`` (default d + 1) agents spanning a large simplex.

    Starts from the agent farthest from the centroid, then repeatedly adds the
    agent farthest from the affine hull of those chosen.

    Parameters
    ----------
    positions
        Nominal positions, shape (n, d).
    count
        Number of leaders, at least d + 1 (default d + 1).
    """
    n, d = positions.shape
    count = d + 1 if count is None else count
    if not d + 1 <= count <= n:
        raise FrameworkError(f"count must lie in d + 1 = {d + 1} .. n = {n}, got {count}")
    chosen = [int(np.argmax(np.linalg.norm(positions - positions.mean(axis=0), axis=1)))]
    while len(chosen) < count:
        base = positions[chosen[0]]
        span = (positions[chosen[1:]] - base).T  # (d, len - 1)
        rel = positions - base
        if span.shape[1]:
            q, _ = np.linalg.qr(span)
            rel = rel - (rel @ q) @ q.T
        dist = np.linalg.norm(rel, axis=1)
        dist[chosen] = -1.0
        chosen.append(int(np.argmax(dist)))
    return chosen


def random_knn(n: int = 20, d: int = 2, k: int = 8, seed: int = 0) -> Framework:
    """n random points in R^d joined to their k nearest neighbours (graph made symmetric).

    Points are uniform in a cube of side n^(1/d) metres (about one agent per
    cubic metre); leaders are d + 1 well-spread agents (:func:`spread_leaders`).
    Generic with probability one, but not always universally rigid: small k or a
    sparse corner can leave an agent with too few neighbours, and
    ``design_stress`` then raises ``StressMatrixError``. k = 8 in 2D and k = 12
    in 3D gave a stress for every seed tried (25 seeds at each even n up to 20,
    8 seeds at n = 30 and 40).

    Parameters
    ----------
    n
        Number of agents, at least d + 2.
    d
        Dimension, at least 1.
    k
        Neighbours per agent, at least d + 1 (capped at n - 1).
    seed
        Seed of ``np.random.default_rng``.
    """
    _check_count(d, 1, "d")
    _check_count(n, d + 2, "n")
    _check_count(k, d + 1, "k")
    k = min(k, n - 1)
    rng = np.random.default_rng(check_seed(seed))
    r = rng.uniform(0.0, n ** (1.0 / d), size=(n, d))
    _, idx = cKDTree(r).query(r, k=k + 1)
    i = np.repeat(np.arange(n), k)
    j = idx[:, 1:].ravel()
    pairs = np.unique(np.sort(np.c_[i, j], axis=1), axis=0)
    return Framework(r, pairs, spread_leaders(r), name=f"random_knn_{d}d_{n}_k{k}_s{seed}")


def _regular_simplex(d: int) -> NDArray[np.float64]:
    """Vertices of a regular simplex in R^d with circumradius 1, centred at 0, shape (d + 1, d)."""
    e = np.eye(d + 1) - 1.0 / (d + 1)  # centred standard simplex in the hyperplane sum = 0 of R^(d+1)
    u, _, _ = np.linalg.svd(e)
    v = e @ u[:, :d]
    return v / np.linalg.norm(v[0])


def farthest_point_leaders(positions: ArrayLike, count: int, fixed: Sequence[int] = ()) -> list[int]:
    """Well-spread leaders by farthest-point sampling: ``count`` agents, starting with ``fixed``.

    Each new leader is the agent farthest (Euclidean) from those chosen; O(n count).
    Without ``fixed`` it starts from the agent farthest from the centroid.

    Args:
        positions: nominal positions, shape (n, d), m.
        count: number of leaders, len(fixed) .. n (at least 1).
        fixed: agents that must be leaders (e.g. the hull's vertices).
    Returns:
        ``count`` distinct agent indices, ``fixed`` first.
    """
    r = as_array(positions, "positions", ndim=2)
    n = r.shape[0]
    fixed_l = as_index_array(fixed, "fixed", n=n, distinct=True).tolist()
    count = check_int(count, "count", low=max(1, len(fixed_l)), high=n)
    chosen = list(fixed_l)
    if not chosen:
        chosen = [int(np.argmax(np.linalg.norm(r - r.mean(axis=0), axis=1)))]
    dist = np.min(np.linalg.norm(r[:, None, :] - r[chosen][None, :, :], axis=2), axis=1)
    while len(chosen) < count:
        i = int(np.argmax(dist))
        chosen.append(i)
        dist = np.minimum(dist, np.linalg.norm(r - r[i], axis=1))
    return chosen


def _hierarchical_cliques(
    simplex: NDArray[np.float64], points: NDArray[np.float64], n_leaders: int
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Positions in agent order and cliques of the hierarchical trilateration (see :func:`trilateration`)."""
    from scipy.spatial import Delaunay

    d = simplex.shape[1]
    extra = farthest_point_leaders(np.vstack([simplex, points]), n_leaders, fixed=range(d + 1))[d + 1 :]
    extra_pts = [i - d - 1 for i in extra]
    lead = np.vstack([simplex, points[extra_pts]])
    cliques: list[NDArray[np.int64]] = []

    def containing(tri_pts: NDArray[np.float64], new: NDArray[np.float64]) -> NDArray[np.int64]:
        if d == 1:
            order = np.argsort(tri_pts[:, 0])
            pos = np.clip(np.searchsorted(tri_pts[order, 0], new[:, 0]), 1, tri_pts.shape[0] - 1)
            return np.sort(np.c_[order[pos - 1], order[pos]], axis=1)
        tri = Delaunay(tri_pts)
        s = tri.find_simplex(new)
        if np.any(s < 0):  # on the hull up to rounding: the nearest simplex by centroid
            cent = tri_pts[tri.simplices].mean(axis=1)
            s[s < 0] = cKDTree(cent).query(new[s < 0])[1]
        return np.sort(tri.simplices[s], axis=1)

    for j in range(d + 1, n_leaders):  # leaders' own cliques (they only enter Omega_ll)
        cliques.append(np.r_[containing(lead[:j], lead[j : j + 1])[0], j])
    rest = np.setdiff1d(np.arange(points.shape[0]), extra_pts)
    placed = [lead]
    nxt = n_leaders
    target = n_leaders
    lo, span = points.min(axis=0), np.ptp(points, axis=0) + 1e-12
    while rest.size:
        target *= 2**d
        if target >= nxt + rest.size:
            new, rest = rest, rest[:0]
        else:  # one point per grid cell, nearest the cell's centre: a quasi-uniform level
            h = (float(np.prod(span)) / (target - nxt)) ** (1.0 / d)
            cell = np.floor((points[rest] - lo) / h).astype(np.int64)
            key = np.ravel_multi_index(cell.T, tuple(cell.max(axis=0) + 1))
            off = np.linalg.norm(points[rest] - ((cell + 0.5) * h + lo), axis=1)
            order = np.lexsort((off, key))
            first = np.r_[True, key[order][1:] != key[order][:-1]]
            pick = np.zeros(rest.size, dtype=bool)
            pick[order[first]] = True
            new, rest = rest[pick], rest[~pick]
        simplices = containing(np.vstack(placed), points[new])
        cliques.append(np.c_[simplices, nxt + np.arange(new.size)])
        placed.append(points[new])
        nxt += new.size
    return np.vstack(placed), np.vstack([np.atleast_2d(c) for c in cliques])


def trilateration(n: int = 100, d: int = 2, seed: int = 0, n_leaders: int | None = None) -> Framework:
    """A random trilateration framework in R^d: each agent j > d joins d + 1 earlier, pairwise-joined agents.

    Agents 0..d (the leaders) are the vertices of a regular simplex of volume n
    (about one agent per unit volume); the others are uniform inside it. They are
    inserted in random order, each into the simplex of the current triangulation
    that contains it, which it splits into d + 1 (a random stacked, or Apollonian,
    triangulation). Agent j is joined to the d + 1 vertices of the simplex it
    split, which are pairwise joined and numbered before j: {j} and these form a
    clique K_{d+2}, the edges are exactly the union of the cliques, and
    ``design_stress(fw, "constructive")`` builds a sparse PSD stress of rank
    n - d - 1 without a solver.

    Every agent lies inside the simplex of its d + 1 partners, so its target is a
    convex combination of theirs: errors are interpolated, never extrapolated,
    down the insertion tree (depth about 2 ln n). With the constructive stress,
    cond(Omega_ff) is about 2e2 at n = 100, 6e3 at n = 1,000 and 2e5 at n = 10,000
    in 2D. Growing the swarm outwards from a small seed simplex instead makes it
    grow exponentially (1e7 at n = 30). Each level of the tree is one vectorised
    step: n = 10,000 in 2D builds in about 0.4 s.

    With ``n_leaders=k`` the same points get a hierarchical, well-conditioned structure
    instead: the k leaders are the simplex vertices plus k - d - 1 agents chosen by
    farthest-point sampling (:func:`farthest_point_leaders`); the followers come in levels
    of about k 2^d, k 4^d, ... agents (one per cell of a grid that halves each level), and
    each follower joins the d + 1 vertices of the Delaunay simplex of the earlier levels
    that contains it (its clique; the simplex's vertices are joined pairwise). Agents are
    numbered leaders first (0..k-1), then level by level, and the cliques are stored on the
    framework (``fw.cliques``) for ``design_stress(fw, "constructive")``. Every follower is
    interpolated from a coarser level, the tree is only about log_(2^d)(n / k) deep, and
    cond(Omega_ff) of the constructive stress stays in the hundreds (about 550 at
    n = 10,000, k = 100 in 2D; ``benchmarks/conditioning.py`` makes the table in BENCHMARKS.md),
    against 2e5 for the default. Degrees stay below about 50.

    Parameters
    ----------
    n
        Number of agents, at least d + 2.
    d
        Dimension, at least 1.
    seed
        Seed of ``np.random.default_rng``, a non-negative integer.
    n_leaders
        None (the random insertion order above, leaders 0..d), or the number of leaders k,
        d + 1 <= k <= n - 1, for the hierarchical structure.
    """
    _check_count(d, 1, "d")
    _check_count(n, d + 2, "n")
    seed = check_seed(seed)
    if n_leaders is not None:
        n_leaders = check_int(n_leaders, "n_leaders", low=d + 1, high=n - 1)
    rng = np.random.default_rng(seed)
    simplex = _regular_simplex(d)
    volume = abs(np.linalg.det(simplex[1:] - simplex[0])) / math.factorial(d)
    simplex *= (n / volume) ** (1.0 / d)
    points = rng.dirichlet(np.ones(d + 1), size=n - d - 1) @ simplex  # uniform in the simplex, random order
    if n_leaders is not None:
        r_h, cl_h = _hierarchical_cliques(simplex, points, n_leaders)
        m = d + 2
        pairs_h = np.vstack([cl_h[:, [a, b]] for a, b in itertools.combinations(range(m), 2)])
        return Framework(
            r_h,
            np.unique(np.sort(pairs_h, axis=1), axis=0),
            leaders=range(n_leaders),
            name=f"trilateration_{d}d_{n}_k{n_leaders}_s{seed}",
            cliques=cl_h,
        )
    r = np.vstack([simplex, np.empty((n - d - 1, d))])
    cliques = []
    pid = np.arange(n - d - 1)  # points not yet inserted (rank = insertion priority) ...
    cell = np.tile(np.arange(d + 1), (n - d - 1, 1))  # ... and the cell (d + 1 sorted agents) holding each
    nxt = d + 1
    while pid.size:
        key = np.unique(cell, axis=0, return_inverse=True)[1].ravel()
        order = np.lexsort((pid, key))
        pid, cell, key = pid[order], cell[order], key[order]
        first = np.r_[True, key[1:] != key[:-1]]  # the earliest point of each cell splits it
        new = nxt + np.arange(np.count_nonzero(first))
        nxt += new.size
        r[new] = points[pid[first]]
        cliques.append(np.c_[cell[first], new])
        splitter = new[np.cumsum(first) - 1][~first]
        pid, cell = pid[~first], cell[~first]
        if not pid.size:
            break
        # The ray from the splitter s through p leaves the cell through the face opposite vertex
        # argmin_k beta_k(p) / beta_k(s) (barycentric coordinates): p lies in the child that drops it.
        h = np.concatenate([r[cell].transpose(0, 2, 1), np.ones((pid.size, 1, d + 1))], axis=1)
        beta_p = np.linalg.solve(h, np.c_[points[pid], np.ones(pid.size)][..., None])[..., 0]
        beta_s = np.linalg.solve(h, np.c_[r[splitter], np.ones(pid.size)][..., None])[..., 0]
        cell[np.arange(pid.size), np.argmin(beta_p / beta_s, axis=1)] = splitter
        cell.sort(axis=1)
    cl = np.vstack(cliques)
    pairs = np.vstack([cl[:, [a, b]] for a, b in itertools.combinations(range(d + 2), 2)])
    return Framework(r, np.unique(pairs, axis=0), leaders=range(d + 1), name=f"trilateration_{d}d_{n}_s{seed}")


def bipyramid_3d() -> Framework:
    """A 6-agent 3D framework: 4 leaders (triangle plus apex) and 2 followers (lower apex, tail), complete graph
    (its stress is :func:`gram_stress`)."""
    r = np.array(
        [[1.0, 0.0, 0.0], [-0.5, 0.9, 0.0], [-0.5, -0.9, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, -1.0], [-1.5, 0.0, 0.2]]
    )
    edges = [(i, j) for i in range(6) for j in range(i + 1, 6)]
    return Framework(r, edges, leaders=[0, 1, 2, 3], name="bipyramid_3d")


def gram_stress(fw: Framework) -> NDArray[np.float64]:
    """The complete-graph stress N N^T (n, n), N an orthonormal basis (n, n - d - 1) of the affine dependencies
    of r (the null space of [r, 1]^T).

    PSD with rank n - d - 1, zero row sums and Omega r = 0 by construction; it is
    supported on every pair of agents, so it is a valid stress only for a
    complete graph. Scaled so that the largest eigenvalue of Omega_ff is 1.
    """
    import scipy.linalg as sla

    h = np.hstack([fw.positions, np.ones((fw.n, 1))])
    nb = sla.null_space(h.T)
    om = nb @ nb.T
    om = (om + om.T) / 2
    f = list(fw.followers)
    return om / float(np.linalg.eigvalsh(om[np.ix_(f, f)])[-1])


def _paper() -> tuple[Framework, NDArray[np.float64]]:
    return paper_example(), paper_omega()


def _bipyramid() -> tuple[Framework, NDArray[np.float64]]:
    fw = bipyramid_3d()
    return fw, gram_stress(fw)


# ------------------------------------------------------------------------------------------- registry
#: Every named framework builder; each takes only keyword arguments with defaults.
REGISTRY: dict[str, Callable[..., Framework]] = {
    "paper_example": paper_example,
    "hexagon": hexagon,
    "square_grid": square_grid,
    "triangle_formation": triangle_formation,
    "octahedron": octahedron,
    "bipyramid": bipyramid,
    "bipyramid_3d": bipyramid_3d,
    "cube_with_center": cube_with_center,
    "helix": helix,
    "random_knn": random_knn,
    "trilateration": trilateration,
}


#: Frameworks that come with their own stress matrix, as the env names them: name -> () -> (Framework, omega (n, n)).
#: The env looks other names up among this module's builders and designs their stress (``design_stress``).
NAMED_FRAMEWORKS: dict[str, Callable[[], tuple[Framework, NDArray[np.float64]]]] = {
    "paper": _paper,
    "bipyramid_3d": _bipyramid,
}


def get_framework(name: str, **kwargs: Any) -> Framework:
    """Build the registered framework ``name`` with ``kwargs`` (see :data:`REGISTRY`).

    Raises
    ------
    UnknownNameError
        ``name`` is not registered (a ``FormationError`` and a ``KeyError``); the message lists the names.
    TypeError
        A keyword argument the builder does not take.
    """
    try:
        builder = REGISTRY[name]
    except KeyError:
        raise UnknownNameError(
            f"name must be a registered framework, got the unknown framework {name!r}; "
            f"registered: {', '.join(sorted(REGISTRY))}"
        ) from None
    return builder(**kwargs)
