"""Frameworks: a graph with a nominal configuration r and a set of leaders.

A framework (G, r) in R^d is the communication graph G = (V, E) together with
the nominal positions r_i in R^d of its n agents (paper, Section 2.1). The
leaders are a subset of V that must affinely span R^d (Assumption 3).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .errors import FrameworkError
from .validation import as_array

__all__ = ["Framework", "affine_rank", "check_leaders_span"]


def affine_rank(points: NDArray[np.float64], rtol: float = 1e-9) -> int:
    """Dimension of the affine span of ``points``, shape (m, d).

    Computed as rank([points, 1]) - 1 with a singular-value tolerance relative to
    the largest singular value of the centred points.
    """
    if points.shape[0] == 0:
        return -1
    centred = points - points.mean(axis=0)
    s = np.linalg.svd(centred, compute_uv=False)
    if s.size == 0 or s[0] == 0.0:
        return 0
    return int(np.sum(s > rtol * s[0] * max(points.shape)))


def check_leaders_span(positions: NDArray[np.float64], leaders: Sequence[int]) -> None:
    """Raise ``FrameworkError`` unless the leaders' positions affinely span R^d."""
    d = positions.shape[1]
    if len(leaders) < d + 1:
        raise FrameworkError(f"leaders must number at least d + 1 = {d + 1} to affinely span R^{d}, got {len(leaders)}")
    rank = affine_rank(positions[list(leaders)])
    if rank < d:
        raise FrameworkError(
            f"leaders {list(leaders)} do not affinely span R^{d}: their affine span has "
            f"dimension {rank} (collinear or coplanar leaders?), expected {d}"
        )


def _normalise_edges(edges: Iterable[Sequence[int]], n: int) -> tuple[tuple[int, int], ...]:
    out: list[tuple[int, int]] = []
    seen: set[tuple[int, int]] = set()
    for e in edges:
        if len(e) != 2:
            raise FrameworkError(f"edge {tuple(e)} must have two endpoints")
        i, j = int(e[0]), int(e[1])
        if not (0 <= i < n and 0 <= j < n):
            raise FrameworkError(f"edge ({i}, {j}) refers to an agent outside 0..{n - 1}")
        if i == j:
            raise FrameworkError(f"edge ({i}, {j}) is a self-loop")
        key = (min(i, j), max(i, j))
        if key in seen:
            raise FrameworkError(f"edge {key} is listed twice (the graph is undirected)")
        seen.add(key)
        out.append(key)
    return tuple(sorted(out))


@dataclass(frozen=True, eq=False)
class Framework:
    """A framework (G, r) with leaders.

    Attributes:
        positions: nominal configuration r, shape (n, d), in metres.
        edges: undirected edges (i, j), i < j, sorted.
        leaders: indices of the leader agents (at least d + 1, affinely spanning R^d).
        name: optional label used in reports.

    Raises:
        FrameworkError: fewer than d + 2 agents, bad edges, duplicate or
            out-of-range leaders, or leaders that do not affinely span R^d.
    """

    positions: NDArray[np.float64]
    edges: tuple[tuple[int, int], ...]
    leaders: tuple[int, ...]
    name: str = ""
    _followers: tuple[int, ...] = field(init=False, repr=False, compare=False)

    def __init__(
        self,
        positions: ArrayLike,
        edges: Iterable[Sequence[int]],
        leaders: Iterable[int],
        name: str = "",
    ) -> None:
        r = as_array(positions, "positions", ndim=2)
        n, d = r.shape
        if d < 1:
            raise FrameworkError("positions must have at least one coordinate (d >= 1)")
        if n < d + 2:
            raise FrameworkError(
                f"a framework in R^{d} needs at least d + 2 = {d + 2} agents (d + 1 leaders and a follower), got {n}"
            )
        lead = tuple(int(i) for i in leaders)
        if len(set(lead)) != len(lead):
            raise FrameworkError(f"leaders {list(lead)} contain duplicates")
        if any(not 0 <= i < n for i in lead):
            raise FrameworkError(f"leaders {list(lead)} refer to agents outside 0..{n - 1}")
        if len(lead) >= n:
            raise FrameworkError("every agent is a leader: a framework needs at least one follower")
        check_leaders_span(r, lead)
        r = r.copy()
        r.setflags(write=False)
        object.__setattr__(self, "positions", r)
        object.__setattr__(self, "edges", _normalise_edges(edges, n))
        object.__setattr__(self, "leaders", lead)
        object.__setattr__(self, "name", name)
        lset = set(lead)
        object.__setattr__(self, "_followers", tuple(i for i in range(n) if i not in lset))

    @property
    def n(self) -> int:
        """Number of agents."""
        return int(self.positions.shape[0])

    @property
    def d(self) -> int:
        """Dimension of the space the agents move in."""
        return int(self.positions.shape[1])

    @property
    def followers(self) -> tuple[int, ...]:
        """Indices of the follower agents, increasing."""
        return self._followers

    def neighbours(self, i: int) -> list[int]:
        """Neighbours of agent ``i`` in the (undirected) graph."""
        return [b if a == i else a for a, b in self.edges if i in (a, b)]

    def degree(self) -> NDArray[np.int64]:
        """Degree of each agent, shape (n,)."""
        deg = np.zeros(self.n, dtype=np.int64)
        for i, j in self.edges:
            deg[i] += 1
            deg[j] += 1
        return deg

    def edge_array(self) -> NDArray[np.int64]:
        """Edges as an integer array, shape (m, 2)."""
        return np.asarray(self.edges, dtype=np.int64).reshape(-1, 2)
