"""Vectorised obstacle geometry: distances, swept contacts and range sensing, batched over a leading axis.

Shapes follow the engine: B environments, m query points per environment
(agents), S wall segments and C circles (spheres in 3D) per environment. No
Python loops over B; every function is a handful of numpy operations.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "circle_clearance",
    "fibonacci_directions",
    "nearest_obstacle_vectors",
    "ray_directions",
    "ray_ranges",
    "segment_clearance",
    "segment_crossings",
]

Array = NDArray[np.float64]


def ray_directions(n_rays: int) -> Array:
    """Unit 2D directions at angles 2 pi k / n_rays, k = 0..n_rays-1 (counter-clockwise from +x), shape (R, 2)."""
    ang = 2.0 * np.pi * np.arange(n_rays) / n_rays
    return np.stack([np.cos(ang), np.sin(ang)], axis=1)


def fibonacci_directions(n: int) -> Array:
    """n roughly evenly spread unit 3D directions (Fibonacci sphere), shape (n, 3)."""
    k = np.arange(n) + 0.5
    z = 1.0 - 2.0 * k / n
    rho = np.sqrt(1.0 - z * z)
    phi = np.pi * (3.0 - np.sqrt(5.0)) * k
    return np.stack([rho * np.cos(phi), rho * np.sin(phi), z], axis=1)


def segment_clearance(p: Array, a: Array, e: Array, e_inv2: Array) -> Array:
    """Distance (m) from points to wall segments.

    Args:
        p: points, shape (B, m, d).
        a: segment starts, shape (B, S, d).
        e: segment vectors (end - start), shape (B, S, d).
        e_inv2: 1 / |e|^2, shape (B, S).
    Returns:
        Distances, shape (B, m, S).
    """
    w = p[:, :, None, :] - a[:, None, :, :]  # (B, m, S, d)
    s = np.clip(np.einsum("bmsd,bsd->bms", w, e) * e_inv2[:, None, :], 0.0, 1.0)
    diff = w - s[..., None] * e[:, None, :, :]
    return np.sqrt(np.einsum("bmsd,bmsd->bms", diff, diff))


def _cross(ax: Array, ay: Array, bx: Array, by: Array) -> Array:
    return ax * by - ay * bx


def segment_crossings(p0: Array, p1: Array, a: Array, e: Array) -> Array:
    """Whether each 2D motion p0 -> p1 properly crosses any wall segment (tunnelling check).

    Args:
        p0, p1: positions before and after the step, shape (B, m, 2).
        a, e: segment starts and vectors, shape (B, S, 2).
    Returns:
        Boolean, shape (B, m): the motion intersects at least one segment.
    """
    ax, ay = a[:, None, :, 0], a[:, None, :, 1]
    ex, ey = e[:, None, :, 0], e[:, None, :, 1]
    x0, y0 = p0[..., 0, None], p0[..., 1, None]
    x1, y1 = p1[..., 0, None], p1[..., 1, None]
    side0 = _cross(ex, ey, x0 - ax, y0 - ay)
    side1 = _cross(ex, ey, x1 - ax, y1 - ay)
    mx, my = x1 - x0, y1 - y0
    end0 = _cross(mx, my, ax - x0, ay - y0)
    end1 = _cross(mx, my, ax + ex - x0, ay + ey - y0)
    return np.any((side0 * side1 < 0.0) & (end0 * end1 < 0.0), axis=-1)


def circle_clearance(p0: Array, p1: Array, circles: Array) -> Array:
    """Swept clearance (m) of motions p0 -> p1 from circles (spheres): min distance of the path minus radius.

    Args:
        p0, p1: positions before and after the step, shape (B, m, d).
        circles: centre and radius, shape (B, C, d + 1).
    Returns:
        Clearance, shape (B, m, C); negative means the path enters the obstacle.
    """
    c = circles[:, None, :, :-1]
    mv = (p1 - p0)[:, :, None, :]
    w = c - p0[:, :, None, :]
    mm = np.einsum("bmcd,bmcd->bmc", mv, mv)
    s = np.clip(np.einsum("bmcd,bmcd->bmc", w, mv) / np.maximum(mm, 1e-300), 0.0, 1.0)
    diff = w - s[..., None] * mv
    return np.sqrt(np.einsum("bmcd,bmcd->bmc", diff, diff)) - circles[:, None, :, -1]


def ray_ranges(
    p: Array,
    dirs: Array,
    a: Array,
    e: Array,
    circles: Array,
    max_range: float,
    seg_cross_inv: Array | None = None,
) -> Array:
    """Range (m) along each 2D ray to the first wall segment or circle, capped at ``max_range``.

    Args:
        p: ray origins (the sensing agents), shape (B, m, 2).
        dirs: unit ray directions, shape (R, 2).
        a, e: wall segment starts and vectors, shape (B, S, 2) (S may be 0).
        circles: shape (B, C, 3) (C may be 0). A ray starting inside a circle reads 0.
        max_range: sensor range (m).
        seg_cross_inv: optional precomputed 1 / cross(dir_r, e_s), shape (B, R, S), inf where parallel.
    Returns:
        Ranges in [0, max_range], shape (B, m, R).
    """
    bsz, m = p.shape[0], p.shape[1]
    best = np.full((bsz, m, dirs.shape[0]), max_range)
    if a.shape[1]:
        if seg_cross_inv is None:
            seg_cross_inv = segment_ray_inverse(dirs, e)
        wx = a[:, None, :, 0] - p[..., 0, None]  # (B, m, S)
        wy = a[:, None, :, 1] - p[..., 1, None]
        t = (wx * e[:, None, :, 1] - wy * e[:, None, :, 0])[:, :, None, :] * seg_cross_inv[:, None]  # (B, m, R, S)
        s = (wx[:, :, None, :] * dirs[None, None, :, 1, None] - wy[:, :, None, :] * dirs[None, None, :, 0, None]) * (
            seg_cross_inv[:, None]
        )
        hit = (t >= 0.0) & (s >= 0.0) & (s <= 1.0)
        np.minimum(best, np.where(hit, t, max_range).min(axis=-1), out=best)
    if circles.shape[1]:
        w = circles[:, None, :, :2] - p[:, :, None, :]  # (B, m, C, 2)
        proj = w @ dirs.T  # (B, m, C, R)
        r2 = circles[:, None, :, 2, None] ** 2
        perp2 = np.einsum("bmcd,bmcd->bmc", w, w)[..., None] - proj * proj
        disc = r2 - perp2
        t = proj - np.sqrt(np.maximum(disc, 0.0))
        inside = perp2 + proj * proj <= r2
        t = np.where(inside, 0.0, t)
        hit = (disc >= 0.0) & ((t >= 0.0) | inside)
        np.minimum(best, np.where(hit, t, max_range).min(axis=2), out=best)
    return best


def segment_ray_inverse(dirs: Array, e: Array) -> Array:
    """1 / cross(dir_r, e_s) for rays (R, 2) and segments (B, S, 2), shape (B, R, S); inf where parallel."""
    cr = dirs[None, :, None, 0] * e[:, None, :, 1] - dirs[None, :, None, 1] * e[:, None, :, 0]
    with np.errstate(divide="ignore"):
        return np.where(np.abs(cr) > 1e-12, 1.0 / np.where(cr == 0.0, 1.0, cr), np.inf)


def nearest_obstacle_vectors(p: Array, circles: Array, k: int, max_range: float) -> Array:
    """Proximity vectors to the k nearest circles (spheres): direction times (1 - distance / range)^+.

    The distance is to the obstacle surface; an obstacle beyond ``max_range`` (or a
    missing one, when C < k) gives the zero vector, one in contact a unit vector.

    Args:
        p: agent positions, shape (B, m, d).
        circles: shape (B, C, d + 1).
    Returns:
        shape (B, m, k, d), each vector of norm in [0, 1].
    """
    bsz, m, d = p.shape
    out = np.zeros((bsz, m, k, d))
    c = circles.shape[1]
    if c == 0 or k == 0:
        return out
    w = circles[:, None, :, :d] - p[:, :, None, :]  # (B, m, C, d)
    dist_c = np.sqrt(np.einsum("bmcd,bmcd->bmc", w, w))
    surf = dist_c - circles[:, None, :, d]
    kk = min(k, c)
    idx = np.argsort(surf, axis=-1)[..., :kk]
    ws = np.take_along_axis(w, idx[..., None], axis=2)
    dc = np.take_along_axis(dist_c, idx, axis=2)
    ss = np.take_along_axis(surf, idx, axis=2)
    mag = np.clip(1.0 - ss / max_range, 0.0, 1.0)
    out[:, :, :kk] = ws / np.maximum(dc, 1e-12)[..., None] * mag[..., None]
    return out
