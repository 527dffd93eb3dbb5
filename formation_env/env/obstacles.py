"""Obstacles as components: one small protocol, three types, geometry written once for all of them.

Every obstacle type turns its per-episode parameters into *capsules* at time t: a segment from ``a`` along
``e`` thickened by a radius ``rad`` (a wall is a capsule of radius 0; a circle or sphere one of length 0). The
step asks only for capsules, so the clearance, the swept contact within a step, the ray and the nearest-
obstacle readings below serve every type, and a new type (a box, a rotating bar, a polygon) is one class that
says where its capsules are at time t. The step never switches on a scenario or on an obstacle type.

=================  ==========================  =============================================================
type               ``params[key]`` per episode  capsules at time t
=================  ==========================  =============================================================
:class:`Segment`   ``segments`` (B, S, 2, d)    start, end - start, radius 0 (zero-thickness walls, 2D)
:class:`Circle`    ``circles`` (B, C, d + 1)    centre, length 0, radius (discs in 2D, balls in 3D)
:class:`MovingCircle` ``moving_circles``        centre c(t), length 0, radius; constant velocity v, bouncing
                   (B, M, 2 d + 1): c0, v, r    elastically off the world box (rim against the box's faces)
=================  ==========================  =============================================================

A moving circle bounces rather than wraps, so its path stays continuous; its position is a closed form (a
triangle wave per axis, :func:`bounce`) of the episode's parameters and t.

Shapes: B environments, n query points (agents) per environment, m capsules, R rays, d = 2 or 3. Distances
in metres.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Callable
from typing import Any, ClassVar, NamedTuple

import numba
import numpy as np
from numpy.typing import NDArray

__all__ = [
    "OBSTACLE_TYPES",
    "Capsules",
    "Circle",
    "MovingCircle",
    "Obstacle",
    "Segment",
    "bounce",
    "capsule_distance",
    "clearance",
    "nearest_vectors",
    "pair_clearance",
    "path_clearance",
    "ray_directions",
    "ray_ranges",
]

Array = NDArray[np.float64]


def _jit(fn: Callable[..., Any]) -> Any:
    """``fn`` compiled by numba (cached on disk). The kernels run on one thread: on threads they contended with
    numpy's BLAS threads for the same cores and made the batched step slower, not faster."""
    return numba.njit(cache=True)(fn)


class _CompileNotice(numba.core.event.Listener):
    """One line on stderr when numba starts compiling one of this module's kernels, once per process.

    numba fires ``"numba:compile"`` only when a kernel is not in its disk cache yet (the first run after an
    install or a change of this file); a kernel loaded from the cache fires nothing, so later runs stay silent.
    """

    shown = False

    def on_start(self, event: Any) -> None:
        disp = event.data.get("dispatcher") if isinstance(event.data, dict) else None
        if self.shown or getattr(getattr(disp, "py_func", None), "__module__", None) != __name__:
            return
        type(self).shown = True
        print(
            "formation-env: compiling the env's step kernels with numba (first run only, cached on disk) ...",
            file=sys.stderr,
            flush=True,
        )

    def on_end(self, event: Any) -> None:
        return None


numba.core.event.register("numba:compile", _CompileNotice())


class Capsules(NamedTuple):
    """Capsules of B environments: axis from ``a`` (B, m, d) along ``e`` (B, m, d), radius ``rad`` (B, m), m."""

    a: Array
    e: Array
    rad: Array

    @staticmethod
    def join(parts: list[Capsules], B: int, d: int) -> Capsules:
        """All capsules of several obstacle types side by side (B, sum m_i, ...); none: B empty sets in R^d."""
        if not parts:
            return Capsules(np.zeros((B, 0, d)), np.zeros((B, 0, d)), np.zeros((B, 0)))
        if len(parts) == 1:
            return parts[0]
        return Capsules(*(np.concatenate([getattr(p, f) for p in parts], axis=1) for f in Capsules._fields))


class Obstacle:
    """An obstacle type: where its capsules are at time t (the protocol of the module docstring).

    Class attributes: ``key`` (its entry of the episode's ``params``), ``dims`` (spatial dims it supports).
    The geometry (clearance, swept contact, rays, nearest readings) is this module's, on the capsules.
    """

    key: ClassVar[str] = ""
    dims: ClassVar[tuple[int, ...]] = (2, 3)

    def capsules(self, p: Array, t: Array, bounds: Array) -> Capsules:
        """The capsules at times t (B,) s of the obstacles ``p`` (B, m, width) in the world box ``bounds`` (2, d)."""
        raise NotImplementedError

    def moves(self) -> bool:
        """Whether the capsules depend on t (else the engine computes them once per episode)."""
        return False

    def state_vector(self, p: Array, t: Array, bounds: Array) -> Array:
        """What the global state carries of these obstacles at times t (B,), (B, k); none for static ones
        (the scenario's ``param_vector`` has them)."""
        return np.zeros((p.shape[0], 0))

    def state_bounds(self, m: int, d: int, bounds: Array) -> tuple[Array, Array]:
        """(low, high) of :meth:`state_vector` for m obstacles, each (k,)."""
        return np.zeros(0), np.zeros(0)

    def decode(self, vec: Array, t: Array, d: int) -> Array | None:
        """Parameters (B, m, width) equivalent at times t (B,) to a :meth:`state_vector` (B, k) read back, or None
        (static obstacles: the scenario decodes them)."""
        return None

    def shapes(self, p: Array, t: float, bounds: Array) -> dict[str, Array]:
        """Drawable shapes of one episode's obstacles ``p`` (m, width) at time t: ``segments`` (k, 2, d) and/or
        ``circles`` (k, d + 1) (the renderer's frame entries)."""
        c = self.capsules(p[None], np.array([t]), bounds)
        if not np.any(c.e):
            return {"circles": np.concatenate([c.a[0], c.rad[0, :, None]], axis=1)}
        return {"segments": np.stack([c.a[0], c.a[0] + c.e[0]], axis=1)}


class Segment(Obstacle):
    """Zero-thickness wall segments (2D): ``segments`` (B, S, 2, d), start and end (m)."""

    key = "segments"
    dims = (2,)

    def capsules(self, p: Array, t: Array, bounds: Array) -> Capsules:
        return Capsules(p[:, :, 0], p[:, :, 1] - p[:, :, 0], np.zeros(p.shape[:2]))


class Circle(Obstacle):
    """Static discs (2D) or balls (3D): ``circles`` (B, C, d + 1), centre and radius (m)."""

    key = "circles"

    def capsules(self, p: Array, t: Array, bounds: Array) -> Capsules:
        c = p[..., :-1]
        return Capsules(c, np.zeros_like(c), p[..., -1])


def bounce(c0: Array, v: Array, rad: Array, t: Array, bounds: Array) -> Array:
    """Centres at times t of discs starting at ``c0`` with velocity ``v`` that bounce elastically off the box.

    Per axis the centre moves in [lo + r, hi - r] of the box ``bounds`` (2, d): with span L = hi - lo - 2 r and
    s = (c0 - lo - r + v t) mod 2 L, it is lo + r + s for s <= L and lo + r + 2 L - s after (a triangle wave).
    c0, v (B, M, d) (m, m/s), rad (B, M) m, t (B,) s -> (B, M, d).
    """
    lo = bounds[0] + rad[..., None]
    span = np.maximum(bounds[1] - rad[..., None] - lo, 1e-12)
    s = np.mod(c0 - lo + v * t[:, None, None], 2.0 * span)
    return lo + np.where(s <= span, s, 2.0 * span - s)


class MovingCircle(Obstacle):
    """Discs (balls) at constant velocity that bounce off the world box: ``moving_circles`` (B, M, 2 d + 1) =
    start centre c0 (m), velocity v (m/s), radius (m); centre at t by :func:`bounce`."""

    key = "moving_circles"
    #: Speed bound (m/s) of the global state's velocity entries.
    max_speed: ClassVar[float] = 5.0

    def velocity(self, p: Array, t: Array, bounds: Array) -> Array:
        """Velocities at times t (B,), (B, M, d) m/s: v with the sign of the current leg of each axis' bounce."""
        d = (p.shape[-1] - 1) // 2
        c0, v, rad = p[..., :d], p[..., d : 2 * d], p[..., -1]
        lo = bounds[0] + rad[..., None]
        span = np.maximum(bounds[1] - rad[..., None] - lo, 1e-12)
        s = np.mod(c0 - lo + v * t[:, None, None], 2.0 * span)
        return np.where(s <= span, v, -v)

    def state_vector(self, p: Array, t: Array, bounds: Array) -> Array:
        c = self.capsules(p, t, bounds)
        parts = [c.a, self.velocity(p, t, bounds), c.rad[..., None]]
        return np.concatenate(parts, axis=-1).reshape(p.shape[0], -1)

    def decode(self, vec: Array, t: Array, d: int) -> Array | None:
        # the current centre c and leg velocity v determine the triangle wave: c0 = c - v t is equivalent
        per = vec.reshape(vec.shape[0], -1, 2 * d + 1).copy()
        per[..., :d] -= per[..., d : 2 * d] * t[:, None, None]
        return per

    def state_bounds(self, m: int, d: int, bounds: Array) -> tuple[Array, Array]:
        v = np.full(d, self.max_speed)
        lo = np.concatenate([bounds[0], -v, [0.0]])
        hi = np.concatenate([bounds[1], v, [float(np.min(bounds[1] - bounds[0])) / 2]])
        return np.tile(lo, m), np.tile(hi, m)

    def moves(self) -> bool:
        return True

    def capsules(self, p: Array, t: Array, bounds: Array) -> Capsules:
        d = (p.shape[-1] - 1) // 2
        c = bounce(p[..., :d], p[..., d : 2 * d], p[..., -1], t, bounds)
        return Capsules(c, np.zeros_like(c), p[..., -1])


#: Obstacle types by their ``params`` key.
OBSTACLE_TYPES: dict[str, type[Obstacle]] = {cls.key: cls for cls in (Segment, Circle, MovingCircle)}


# ---------------------------------------------------------------------------- geometry on capsules
def ray_directions(n_rays: int) -> Array:
    """Unit 2D directions at angles 2 pi k / n_rays, k = 0..n_rays-1 (counter-clockwise from +x), shape (R, 2)."""
    ang = 2.0 * np.pi * np.arange(n_rays) / n_rays
    return np.stack([np.cos(ang), np.sin(ang)], axis=1)


def capsule_distance(p: Array, caps: Capsules) -> tuple[Array, Array]:
    """Distance (m) from points p (B, n, d) to each capsule's surface (B, n, m), and the vector from the
    nearest axis point to p (B, n, m, d) (its norm is the distance to the axis). (For the 3D nearest-obstacle
    block; the step's clearance is :func:`clearance`.)"""
    w = p[:, :, None, :] - caps.a[:, None]
    ee = np.einsum("bmd,bmd->bm", caps.e, caps.e)
    s = np.einsum("bnmd,bmd->bnm", w, caps.e) / np.maximum(ee, 1e-300)[:, None]
    np.clip(s, 0.0, 1.0, out=s)
    diff = w - s[..., None] * caps.e[:, None]
    return np.sqrt(np.einsum("bnmd,bnmd->bnm", diff, diff)) - caps.rad[:, None], diff


# The kernels below loop over environments (row b), then over agents and capsules. tests/oracle.py holds the
# plain numpy versions they are tested against.
@_jit
def _clearance_rows(p: Array, a: Array, e: Array, rad: Array, out: Array) -> None:  # pragma: no cover
    B, n, d = p.shape
    m = a.shape[1]
    for b in range(B):
        best = np.inf
        for j in range(m):
            ee = 0.0
            for c in range(d):
                ee += e[b, j, c] * e[b, j, c]
            for i in range(n):
                s = 0.0
                if ee > 0.0:
                    for c in range(d):
                        s += (p[b, i, c] - a[b, j, c]) * e[b, j, c]
                    s = min(max(s / ee, 0.0), 1.0)
                dd = 0.0
                for c in range(d):
                    w = p[b, i, c] - a[b, j, c] - s * e[b, j, c]
                    dd += w * w
                best = min(best, math.sqrt(dd) - rad[b, j])
        out[b] = best


@_jit
def _path_rows(
    p0: Array, p1: Array, a0: Array, a1: Array, e: Array, rad: Array, out: Array
) -> None:  # pragma: no cover
    B, n, d = p0.shape
    m = a0.shape[1]
    tiny = 1e-300
    for b in range(B):
        best = np.inf
        for j in range(m):
            for i in range(n):
                # agent path q0 -> q1 relative to the capsule; capsule axis a0 -> a0 + e (Ericson 5.1.9)
                aa = 0.0
                ee = 0.0
                bb = 0.0
                cc = 0.0
                ff = 0.0
                for c in range(d):
                    d1 = p1[b, i, c] - (a1[b, j, c] - a0[b, j, c]) - p0[b, i, c]
                    d2 = e[b, j, c]
                    r = p0[b, i, c] - a0[b, j, c]
                    aa += d1 * d1
                    ee += d2 * d2
                    bb += d1 * d2
                    cc += d1 * r
                    ff += d2 * r
                denom = aa * ee - bb * bb
                s = 0.0
                if ee <= tiny:  # the capsule's axis is a point: the nearest point of the path to it
                    s = min(max(-cc / aa, 0.0), 1.0) if aa > tiny else 0.0
                elif aa > tiny and denom > 1e-12 * aa * ee:
                    s = min(max((bb * ff - cc * ee) / denom, 0.0), 1.0)
                t = (bb * s + ff) / ee if ee > tiny else 0.0
                if t < 0.0:
                    t = 0.0
                    s = min(max(-cc / aa, 0.0), 1.0) if aa > tiny else 0.0
                elif t > 1.0:
                    t = 1.0
                    s = min(max((bb - cc) / aa, 0.0), 1.0) if aa > tiny else 0.0
                dd = 0.0
                for c in range(d):
                    d1 = p1[b, i, c] - (a1[b, j, c] - a0[b, j, c]) - p0[b, i, c]
                    w = p0[b, i, c] + s * d1 - a0[b, j, c] - t * e[b, j, c]
                    dd += w * w
                best = min(best, math.sqrt(dd) - rad[b, j])
        out[b] = best


@_jit
def _ray_segment(ox: float, oy: float, ux: float, uy: float, ax: float, ay: float, ex: float, ey: float) -> float:
    """Distance along the unit ray (ux, uy) from (ox, oy) to the segment a + s e, s in [0, 1]; inf on a miss."""
    cr = ux * ey - uy * ex
    if abs(cr) <= 1e-12:
        return np.inf
    wx, wy = ax - ox, ay - oy
    t = (wx * ey - wy * ex) / cr
    s = (wx * uy - wy * ux) / cr
    return t if (t >= 0.0 and 0.0 <= s <= 1.0) else np.inf


@_jit
def _ray_circle(ox: float, oy: float, ux: float, uy: float, cx: float, cy: float, r: float) -> float:
    """Distance along the unit ray from (ox, oy) to the circle (c, r) (0 inside); inf on a miss."""
    wx, wy = cx - ox, cy - oy
    ww = wx * wx + wy * wy
    if ww <= r * r:
        return 0.0
    proj = wx * ux + wy * uy
    disc = r * r - (ww - proj * proj)
    if disc < 0.0:
        return np.inf
    t = proj - math.sqrt(disc)
    return t if t >= 0.0 else np.inf


@_jit
def _ray_rows(
    o: Array, u: Array, a: Array, e: Array, rad: Array, max_range: float, out: Array
) -> None:  # pragma: no cover
    B, l, _ = o.shape
    R = u.shape[0]
    m = a.shape[1]
    for b in range(B):
        for i in range(l):
            ox, oy = o[b, i, 0], o[b, i, 1]
            for k in range(R):
                ux, uy = u[k, 0], u[k, 1]
                best = max_range
                for j in range(m):
                    ax, ay, ex, ey, r = a[b, j, 0], a[b, j, 1], e[b, j, 0], e[b, j, 1], rad[b, j]
                    if r <= 0.0:
                        t = _ray_segment(ox, oy, ux, uy, ax, ay, ex, ey)
                    else:
                        t = min(
                            _ray_circle(ox, oy, ux, uy, ax, ay, r), _ray_circle(ox, oy, ux, uy, ax + ex, ay + ey, r)
                        )
                        le = math.sqrt(ex * ex + ey * ey)
                        if le > 0.0 and t > 0.0:
                            nx, ny = -ey / le * r, ex / le * r
                            t = min(t, _ray_segment(ox, oy, ux, uy, ax + nx, ay + ny, ex, ey))
                            t = min(t, _ray_segment(ox, oy, ux, uy, ax - nx, ay - ny, ex, ey))
                            # inside the straight part of the capsule
                            s = min(max(((ox - ax) * ex + (oy - ay) * ey) / (le * le), 0.0), 1.0)
                            wx, wy = ox - ax - s * ex, oy - ay - s * ey
                            if wx * wx + wy * wy <= r * r:
                                t = 0.0
                    best = min(best, t)
                out[b, i, k] = best


@_jit
def _pair_rows(p: Array, pi: NDArray[np.int64], pj: NDArray[np.int64], out: Array) -> None:  # pragma: no cover
    B, _, d = p.shape
    for b in range(B):
        best = np.inf
        for k in range(pi.shape[0]):
            dd = 0.0
            for c in range(d):
                w = p[b, pi[k], c] - p[b, pj[k], c]
                dd += w * w
            best = min(best, dd)
        out[b] = math.sqrt(best)


def pair_clearance(p: Array, pi: NDArray[np.int64], pj: NDArray[np.int64]) -> Array:
    """Smallest centre distance (m) of the agent pairs (pi[k], pj[k]) in each environment, p (B, n, d) -> (B,)."""
    out = np.empty(p.shape[0])
    _pair_rows(p, pi, pj, out)
    return out


def clearance(p: Array, caps: Capsules) -> Array:
    """Smallest distance (m) from any point p (B, n, d) to any capsule's surface, (B,) (inf without capsules)."""
    out = np.empty(p.shape[0])
    _clearance_rows(p, caps.a, caps.e, caps.rad, out)
    return out


def path_clearance(p0: Array, p1: Array, caps0: Capsules, caps1: Capsules) -> Array:
    """Smallest distance (m) between any agent's straight motion p0 -> p1 (B, n, d) and any capsule's surface
    over one step, (B,), in the capsule's frame: the capsule translates from ``caps0`` to ``caps1``, so the
    agent's path relative to it runs from p0 to p1 - (a1 - a0) (segment-segment closest points, Ericson,
    Real-Time Collision Detection, 5.1.9)."""
    out = np.empty(p0.shape[0])
    _path_rows(p0, p1, caps0.a, caps1.a, caps0.e, caps0.rad, out)
    return out


def ray_ranges(o: Array, u: Array, caps: Capsules, max_range: float) -> Array:
    """Range (m) along each 2D ray u (R, 2) from each origin o (B, l, 2) to the first capsule surface, at most
    ``max_range``; a ray starting inside a capsule reads 0. Shape (B, l, R)."""
    out = np.empty((o.shape[0], o.shape[1], u.shape[0]))
    _ray_rows(np.ascontiguousarray(o), u, caps.a, caps.e, caps.rad, float(max_range), out)
    return out


def nearest_vectors(p: Array, caps: Capsules, k: int, max_range: float) -> Array:
    """Proximity vectors to the k nearest capsules: unit direction from p toward the capsule's nearest point,
    times (1 - surface distance / max_range)^+; a capsule beyond range (or missing, m < k) gives 0, one in
    contact a unit vector. p (B, l, d) -> (B, l, k, d)."""
    B, l, d = p.shape
    out = np.zeros((B, l, k, d))
    m = caps.a.shape[1]
    if m == 0 or k == 0:
        return out
    surf, diff = capsule_distance(p, caps)
    kk = min(k, m)
    idx = np.argsort(surf, axis=-1, kind="stable")[..., :kk]
    toward = -np.take_along_axis(diff, idx[..., None], axis=2)
    norm = np.sqrt(np.einsum("blkd,blkd->blk", toward, toward))
    mag = np.clip(1.0 - np.take_along_axis(surf, idx, axis=2) / max_range, 0.0, 1.0)
    out[:, :, :kk] = toward / np.maximum(norm, 1e-12)[..., None] * mag[..., None]
    return out
