"""Frameworks: a graph with a nominal configuration r and a set of leaders.

A framework (G, r) in R^d is the communication graph G = (V, E) together with
the nominal positions r_i in R^d of its n agents (paper, Section 2.1). The
leaders are a subset of V that must affinely span R^d (Assumption 3).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .errors import ControlDimension, FormationError, FrameworkError
from .validation import _describe, as_array, as_index_array

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
    if edges is not None and not isinstance(edges, np.ndarray | str | bytes):
        if not isinstance(edges, Iterable):
            raise TypeError(f"edges must be a sequence of (i, j) pairs of agent indices, got {_describe(edges)}")
        edges = list(edges)
        for e in edges:
            if np.ndim(e) != 1 or len(e) != 2:
                raise FrameworkError(f"edges must be (i, j) pairs of agent indices, got the entry {e!r}")
    try:
        arr = as_index_array(edges, "edges", n=n, ndim=2)
    except (ControlDimension, FormationError) as exc:
        raise FrameworkError(str(exc)) from exc
    out: list[tuple[int, int]] = []
    seen: set[tuple[int, int]] = set()
    for i, j in arr.tolist():
        if i == j:
            raise FrameworkError(f"edges must join two distinct agents, got the self-loop ({i}, {j})")
        key = (min(i, j), max(i, j))
        if key in seen:
            raise FrameworkError(f"edges must list each pair once (the graph is undirected), got {key} twice")
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
        cliques: optional trilateration cliques, shape (n - d - 1, d + 2), integer: row j - d - 1
            lists d + 1 pairwise-joined agents before j, then j (used by
            ``design_stress(fw, "constructive")``; None: found from the edges in index order).

    Raises:
        FrameworkError: fewer than d + 2 agents, bad edges, duplicate or
            out-of-range leaders, or leaders that do not affinely span R^d.
    """

    positions: NDArray[np.float64]
    edges: tuple[tuple[int, int], ...]
    leaders: tuple[int, ...]
    name: str = ""
    cliques: NDArray[np.int64] | None = None
    _followers: tuple[int, ...] = field(init=False, repr=False, compare=False)

    def __init__(
        self,
        positions: ArrayLike,
        edges: Iterable[Sequence[int]],
        leaders: Iterable[int],
        name: str = "",
        cliques: ArrayLike | None = None,
    ) -> None:
        r = as_array(positions, "positions", ndim=2)
        n, d = r.shape
        if d < 1:
            raise FrameworkError(f"positions must have at least one coordinate (d >= 1), got shape {r.shape}")
        if n < d + 2:
            raise FrameworkError(
                f"positions must have at least d + 2 = {d + 2} agents (rows): a framework in R^{d} needs d + 1 "
                f"leaders and a follower, got {n}"
            )
        if not isinstance(name, str):
            raise TypeError(f"name must be a string, got {type(name).__name__}")
        try:
            lead_arr = as_index_array(leaders, "leaders", n=n)
        except (ControlDimension, FormationError) as exc:
            raise FrameworkError(str(exc)) from exc
        lead = tuple(int(i) for i in lead_arr)
        if len(set(lead)) != len(lead):
            raise FrameworkError(f"leaders {list(lead)} contain duplicates")
        if len(lead) >= n:
            raise FrameworkError(f"leaders must leave at least one follower, got all {n} agents as leaders")
        check_leaders_span(r, lead)
        r = r.copy()
        r.setflags(write=False)
        object.__setattr__(self, "positions", r)
        object.__setattr__(self, "edges", _normalise_edges(edges, n))
        object.__setattr__(self, "leaders", lead)
        object.__setattr__(self, "name", name)
        if cliques is not None:
            cl = (
                as_index_array(np.asarray(cliques).ravel(), "cliques", n=n).reshape(-1, d + 2)
                if np.size(cliques) % (d + 2) == 0
                else None
            )
            if cl is None or np.ndim(cliques) != 2 or cl.shape[0] != n - d - 1:
                raise ControlDimension(
                    f"cliques must have shape (n - d - 1, d + 2) = ({n - d - 1}, {d + 2}), got {np.shape(cliques)}"
                )
            cl = cl.copy()
            cl.setflags(write=False)
            object.__setattr__(self, "cliques", cl)
        else:
            object.__setattr__(self, "cliques", None)
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


def check_framework(fw: Any, name: str = "fw") -> Any:
    """A :class:`~formation_env.core.framework.Framework`."""
    if not isinstance(fw, Framework):
        raise TypeError(f"{name} must be a Framework, got {_describe(fw)}")
    return fw
