"""Obstacles as components: one small protocol, three types, geometry written once for all of them.

Every obstacle type turns its per-episode parameters into *capsules* at time t: a segment from ``a`` along
``e`` thickened by a radius ``rad`` (a wall is a capsule of radius 0; a circle or sphere one of length 0). The
step asks only for capsules, so the clearance, the swept contact within a step, the ray and the nearest-
obstacle readings below serve every type, and a new type (a box, a rotating bar, a polygon) is one class that
says where its capsules are at time t. The step never switches on a scenario or on an obstacle type. A moving
type is its compiled ``row(p, t, bounds, a, e, rad)`` (its capsules at time t, for one env), from which the
numpy ``capsules`` of the reset, the renderer and the global state follow; a scenario may have any number of
moving types (their capsules follow the static ones, type after type, in ``obstacle_types`` order).

=================  ==========================  =============================================================
type               ``params[key]`` per episode  capsules at time t
=================  ==========================  =============================================================
:class:`Segment`   ``segments`` (B, S, 2, d)    start, end - start, radius 0 (zero-thickness walls, 2D)
:class:`Circle`    ``circles`` (B, C, d + 1)    centre, length 0, radius (discs in 2D, balls in 3D)
:class:`MovingCircle` ``moving_circles``        centre c(t), length 0, radius; constant velocity v, bouncing
                   (B, M, 2 d + 1): c0, v, r    elastically off the world box (rim against the box's faces)
=================  ==========================  =============================================================

A moving circle bounces rather than wraps, so its path stays continuous; its position is a closed form (a
triangle wave per axis, :func:`bounce_row`) of the episode's parameters and t.

Shapes: B environments, n query points (agents) per environment, m capsules, R rays, d = 2 or 3. Distances
in metres.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar, NamedTuple

import numpy as np
from numpy.typing import NDArray

from ._numba import jit

__all__ = [
    "OBSTACLE_TYPES",
    "Capsules",
    "Circle",
    "MovingCircle",
    "Obstacle",
    "Segment",
    "axis_param",
    "bounce_axis",
    "bounce_row",
    "path_clearance",
    "point_clearance",
    "ray_directions",
    "ray_range",
    "toward_axis",
    "toward_axis_at",
]

Array = NDArray[np.float64]


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
    #: A moving type's compiled ``row(p (M, w), t, bounds, a (M, d), e (M, d), rad (M,))``: its capsules at time
    #: t (s) for the step (:mod:`~formation_env.env.kernel`); None for static types.
    row: ClassVar[Any] = None

    def capsules(self, p: Array, t: Array, bounds: Array) -> Capsules:
        """The capsules at times t (B,) s of the obstacles ``p`` (B, m, width) in the world box ``bounds`` (2, d).

        A moving type gets it from its compiled ``row``, env by env (the same code as the step's); a static type
        says it in numpy (it runs once per episode, at the reset)."""
        if self.row is None:
            raise NotImplementedError(f"{type(self).__name__}: a static obstacle type defines capsules()")
        p = np.ascontiguousarray(p, dtype=np.float64)
        B, m, d = p.shape[0], p.shape[1], bounds.shape[1]
        times = np.broadcast_to(np.asarray(t, dtype=np.float64), (B,))
        out = Capsules(np.empty((B, m, d)), np.empty((B, m, d)), np.empty((B, m)))
        for b in range(B):
            self.row(p[b], float(times[b]), bounds, out.a[b], out.e[b], out.rad[b])
        return out

    def moves(self) -> bool:
        """Whether the capsules depend on t (else the engine computes them once per episode): a type with a
        compiled ``row`` moves."""
        return self.row is not None

    def state_vector(self, p: Array, t: Array, bounds: Array) -> Array:
        """What the global state carries of these obstacles at times t (B,), (B, k): a moving type's capsules
        (start, axis, radius of each); none for static ones (the scenario's ``episode_params`` have them)."""
        if self.row is None:
            return np.zeros((p.shape[0], 0))
        c = self.capsules(p, t, bounds)
        return np.concatenate([c.a, c.e, c.rad[..., None]], axis=-1).reshape(p.shape[0], -1)

    def state_bounds(self, m: int, d: int, bounds: Array) -> tuple[Array, Array]:
        """(low, high) of :meth:`state_vector` for m obstacles, each (k,)."""
        if self.row is None:
            return np.zeros(0), np.zeros(0)
        ext = bounds[1] - bounds[0]
        lo = np.concatenate([bounds[0], -ext, [0.0]])
        hi = np.concatenate([bounds[1], ext, [float(np.min(ext)) / 2]])
        return np.tile(lo, m), np.tile(hi, m)

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


@jit
def bounce_axis(
    c0: float, v: float, r: float, lo: float, hi: float, t: float
) -> tuple[float, float]:  # pragma: no cover
    """Centre (m) and velocity (m/s) at time t (s), along one axis, of a disc of radius r that starts at c0 with
    velocity v and bounces elastically between the faces lo and hi: its centre moves in [lo + r, hi - r]. With
    span L = hi - lo - 2 r and s = (c0 - lo - r + v t) mod 2 L, it is lo + r + s, moving at v, for s <= L, and
    lo + r + 2 L - s, moving at -v, after (a triangle wave)."""
    lo_c = lo + r
    span = max(hi - r - lo_c, 1e-12)
    s = (c0 - lo_c + v * t) % (2.0 * span)
    return (lo_c + s, v) if s <= span else (lo_c + 2.0 * span - s, -v)


@jit
def bounce_row(p: Array, t: float, bounds: Array, a: Array, e: Array, rad: Array) -> None:  # pragma: no cover
    """Capsules at time t (s) of discs ``p`` (M, 2 d + 1) = start centre c0, velocity v, radius that bounce
    elastically off the box ``bounds`` (2, d) (per axis :func:`bounce_axis`): into a, e (M, d) and rad (M,)."""
    d = a.shape[1]
    for j in range(p.shape[0]):
        r = p[j, 2 * d]
        for k in range(d):
            a[j, k] = bounce_axis(p[j, k], p[j, d + k], r, bounds[0, k], bounds[1, k], t)[0]
            e[j, k] = 0.0
        rad[j] = r


@jit
def _bounce_rows(p: Array, t: Array, bounds: Array, a: Array, e: Array, rad: Array) -> None:  # pragma: no cover
    for b in range(p.shape[0]):
        bounce_row(p[b], t[b], bounds, a[b], e[b], rad[b])


class MovingCircle(Obstacle):
    """Discs (balls) at constant velocity that bounce off the world box: ``moving_circles`` (B, M, 2 d + 1) =
    start centre c0 (m), velocity v (m/s), radius (m); centre at t by :func:`bounce_row`."""

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

    row: ClassVar[Any] = staticmethod(bounce_row)

    def capsules(self, p: Array, t: Array, bounds: Array) -> Capsules:
        # the row's batched loop compiled (the global state reads it every step, at B in the thousands)
        B, M, w = p.shape
        d = (w - 1) // 2
        out = Capsules(np.empty((B, M, d)), np.empty((B, M, d)), np.empty((B, M)))
        _bounce_rows(np.ascontiguousarray(p), np.asarray(t, dtype=np.float64), bounds, *out)
        return out


#: Obstacle types by their ``params`` key.
OBSTACLE_TYPES: dict[str, type[Obstacle]] = {cls.key: cls for cls in (Segment, Circle, MovingCircle)}


# ---------------------------------------------------------------------------- geometry on capsules (one env)
def ray_directions(n_rays: int) -> Array:
    """Unit 2D directions at angles 2 pi k / n_rays, k = 0..n_rays-1 (counter-clockwise from +x), shape (R, 2)."""
    ang = 2.0 * np.pi * np.arange(n_rays) / n_rays
    return np.stack([np.cos(ang), np.sin(ang)], axis=1)


@jit
def axis_param(p: Array, a: Array, e: Array, j: int) -> float:  # pragma: no cover
    """The t in [0, 1] of the nearest point a_j + t e_j of capsule j's axis (a, e (m, d)) to the point p (d,)
    (0 for a disc, whose axis is a point)."""
    ee = 0.0
    t = 0.0
    for k in range(p.shape[0]):
        ee += e[j, k] * e[j, k]
    if ee > 0.0:
        for k in range(p.shape[0]):
            t += (p[k] - a[j, k]) * e[j, k]
        t = min(max(t / ee, 0.0), 1.0)
    return t


@jit
def toward_axis_at(p: Array, a: Array, e: Array, j: int, t: float, out: Array) -> float:  # pragma: no cover
    """The vector from the point p (d,) to the point a_j + t e_j of capsule j's axis (a, e (m, d)), written into
    out (d,); returns its length (m)."""
    dd = 0.0
    for k in range(p.shape[0]):
        out[k] = a[j, k] + t * e[j, k] - p[k]
        dd += out[k] ** 2
    return math.sqrt(dd)


@jit
def toward_axis(p: Array, a: Array, e: Array, j: int, out: Array) -> float:  # pragma: no cover
    """The vector from the point p (d,) to the nearest point of capsule j's axis (a, e (m, d); its parameter
    :func:`axis_param`), written into out (d,); returns its length (m)."""
    return toward_axis_at(p, a, e, j, axis_param(p, a, e, j), out)


@jit
def point_clearance(p: Array, a: Array, e: Array, rad: Array) -> float:  # pragma: no cover
    """Smallest distance (m) from the points p (n, d) to the capsules' surfaces (a, e (m, d), rad (m,))."""
    best = np.inf
    n, d = p.shape
    for j in range(rad.shape[0]):
        ee = 0.0
        for c in range(d):
            ee += e[j, c] * e[j, c]
        for i in range(n):
            t = 0.0
            if ee > 0.0:
                for c in range(d):
                    t += (p[i, c] - a[j, c]) * e[j, c]
                t = min(max(t / ee, 0.0), 1.0)
            dd = 0.0
            for c in range(d):
                w = p[i, c] - a[j, c] - t * e[j, c]
                dd += w * w
            best = min(best, math.sqrt(dd) - rad[j])
    return best


@jit
def path_clearance(p0: Array, p1: Array, a0: Array, a1: Array, e: Array, rad: Array) -> float:  # pragma: no cover
    """Smallest distance (m) between each agent's straight motion p0 -> p1 (n, d) and each capsule's surface
    over one step, in the capsule's frame (it translates from a0 to a1): segment-segment closest points
    (Ericson, Real-Time Collision Detection, 5.1.9)."""
    n, d = p0.shape
    tiny = 1e-300
    best = np.inf
    for j in range(rad.shape[0]):
        for i in range(n):
            aa = ee = bb = cc = ff = 0.0
            for c in range(d):
                d1 = p1[i, c] - (a1[j, c] - a0[j, c]) - p0[i, c]
                d2 = e[j, c]
                w = p0[i, c] - a0[j, c]
                aa += d1 * d1
                ee += d2 * d2
                bb += d1 * d2
                cc += d1 * w
                ff += d2 * w
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
                d1 = p1[i, c] - (a1[j, c] - a0[j, c]) - p0[i, c]
                w = p0[i, c] + s * d1 - a0[j, c] - t * e[j, c]
                dd += w * w
            best = min(best, math.sqrt(dd) - rad[j])
    return best


@jit
def ray_segment(ox: float, oy: float, ux: float, uy: float, ax: float, ay: float, ex: float, ey: float) -> float:
    """Distance along the unit ray (ux, uy) from (ox, oy) to the segment a + s e, s in [0, 1]; inf on a miss."""
    cr = ux * ey - uy * ex
    if abs(cr) <= 1e-12:
        return np.inf
    wx, wy = ax - ox, ay - oy
    t = (wx * ey - wy * ex) / cr
    u = (wx * uy - wy * ux) / cr
    return t if (t >= 0.0 and 0.0 <= u <= 1.0) else np.inf


@jit
def ray_circle(ox: float, oy: float, ux: float, uy: float, cx: float, cy: float, r: float) -> float:
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


@jit
def ray_range(ox: float, oy: float, ux: float, uy: float, a: Array, e: Array, rad: Array,
              max_range: float) -> float:  # pragma: no cover  # fmt: skip
    """Range (m) along the unit 2D ray (ux, uy) from (ox, oy) to the first capsule surface (a, e (m, 2), rad (m,)),
    at most ``max_range``; a ray starting inside a capsule reads 0."""
    best = max_range
    for j in range(rad.shape[0]):
        ax, ay, ex, ey, r = a[j, 0], a[j, 1], e[j, 0], e[j, 1], rad[j]
        if r <= 0.0:
            t = ray_segment(ox, oy, ux, uy, ax, ay, ex, ey)
        else:
            t = min(ray_circle(ox, oy, ux, uy, ax, ay, r), ray_circle(ox, oy, ux, uy, ax + ex, ay + ey, r))
            le = math.sqrt(ex * ex + ey * ey)
            if le > 0.0 and t > 0.0:
                nx, ny = -ey / le * r, ex / le * r
                t = min(t, ray_segment(ox, oy, ux, uy, ax + nx, ay + ny, ex, ey))
                t = min(t, ray_segment(ox, oy, ux, uy, ax - nx, ay - ny, ex, ey))
                u = min(max(((ox - ax) * ex + (oy - ay) * ey) / (le * le), 0.0), 1.0)
                wx, wy = ox - ax - u * ex, oy - ay - u * ey
                if wx * wx + wy * wy <= r * r:
                    t = 0.0
        best = min(best, t)
    return best
