"""Affine targets x* = (I kron Theta) r + 1 kron b (eq. 7), Theta builders and manoeuvre schedules.

A :class:`Maneuver` is a function of time t (s) -> (Theta(t), b(t)). Primitives
(translate, rotate, scale, shear) change their parameter smoothly over a time
window [start, stop] and hold it afterwards; ``m2 @ m1`` composes them (apply
m1, then m2). :class:`AffineImage` fits the closest affine image of r to a
configuration (least squares over Theta, b), the formation error used by the env.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .errors import ControlDimension, FormationError
from .validation import as_array, check_bool, check_dt, check_int, check_real_scalar

__all__ = [
    "AffineImage",
    "Maneuver",
    "affine_targets",
    "hold",
    "rotate",
    "rotation",
    "scale",
    "scaling",
    "shear",
    "shear_matrix",
    "translate",
]

Array = NDArray[np.float64]

#: Largest n for which ``AffineImage.residual`` uses the dense (n, n) projector.
DENSE_RESIDUAL_UP_TO = 1000


def affine_targets(r: ArrayLike, theta: ArrayLike, b: ArrayLike) -> Array:
    """x_i* = Theta r_i + b for every agent (eq. 7).

    Args:
        r: nominal configuration, shape (n, d).
        theta: shape (d, d) or batched (..., d, d).
        b: shape (d,) or batched (..., d).
    Returns:
        Targets, shape (..., n, d).
    """
    rr = as_array(r, "r", ndim=2)
    th = as_array(theta, "theta")
    bb = as_array(b, "b")
    d = rr.shape[1]
    if th.shape[-2:] != (d, d) or bb.shape[-1:] != (d,):
        raise ControlDimension(f"theta must be (..., {d}, {d}) and b (..., {d}); got {th.shape} and {bb.shape}")
    return np.einsum("...ij,nj->...ni", th, rr) + bb[..., None, :]


def rotation(angle: float, axis: ArrayLike | None = None) -> Array:
    """Rotation matrix: 2D by ``angle`` (rad, counter-clockwise) or 3D about ``axis`` (Rodrigues)."""
    angle = check_real_scalar(angle, "angle", unit="rad")
    c, s = np.cos(angle), np.sin(angle)
    if axis is None:
        return np.array([[c, -s], [s, c]])
    k = as_array(axis, "axis", ndim=1)
    if k.shape != (3,) or np.linalg.norm(k) == 0:
        raise ControlDimension(f"axis must be a nonzero 3-vector, got {k}")
    k = k / np.linalg.norm(k)
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + s * kx + (1 - c) * kx @ kx


def scaling(*factors: float) -> Array:
    """diag(factors): scale axis i by factors[i] (d = len(factors))."""
    f = as_array(factors, "factors", ndim=1)
    if f.size == 0 or np.any(f == 0):
        raise FormationError(f"scaling factors must be nonzero (one per axis), got {factors}")
    return np.diag(f)


def shear_matrix(amount: float, d: int = 2, i: int = 0, j: int = 1) -> Array:
    """I + amount e_i e_j^T: coordinate i shifted by amount times coordinate j."""
    amount = check_real_scalar(amount, "amount")
    d, i, j = check_int(d, "d", low=2), check_int(i, "i"), check_int(j, "j")
    if i == j or not (0 <= i < d and 0 <= j < d):
        raise FormationError(f"shear axes must be distinct in 0..{d - 1}, got i={i}, j={j}")
    m = np.eye(d)
    m[i, j] = amount
    return m


def _window(start: float, stop: float, smooth: bool) -> tuple[float, float, bool]:
    """A manoeuvre's time window [start, stop] (s, finite reals) and its ``smooth`` flag, checked."""
    return (
        check_real_scalar(start, "start", unit="s"),
        check_real_scalar(stop, "stop", unit="s"),
        check_bool(smooth, "smooth"),
    )


def _ramp(t: float, start: float, stop: float, smooth: bool) -> float:
    """0 before start, 1 after stop; smoothstep (C1) or linear between."""
    if stop <= start:
        return 1.0 if t >= start else 0.0
    s = min(max((t - start) / (stop - start), 0.0), 1.0)
    return s * s * (3 - 2 * s) if smooth else s


@dataclass(frozen=True)
class Maneuver:
    """A time-varying affine transformation t -> (Theta(t), b(t)) in R^d.

    Compose with ``@``: ``(m2 @ m1)(t)`` applies m1 then m2, i.e.
    Theta = Theta2 Theta1, b = Theta2 b1 + b2.
    """

    d: int
    theta_fn: Callable[[float], Array]
    b_fn: Callable[[float], Array]
    label: str = "maneuver"

    def __call__(self, t: float) -> tuple[Array, Array]:
        return self.theta_fn(t), self.b_fn(t)

    def __matmul__(self, other: Maneuver) -> Maneuver:
        if other.d != self.d:
            raise ControlDimension(f"cannot compose a {self.d}D and a {other.d}D manoeuvre")
        first, second = other, self

        def th(t: float) -> Array:
            return second.theta_fn(t) @ first.theta_fn(t)

        def b(t: float) -> Array:
            return second.theta_fn(t) @ first.b_fn(t) + second.b_fn(t)

        return Maneuver(self.d, th, b, f"{second.label} o {first.label}")

    def targets(self, r: ArrayLike, t: float) -> Array:
        """Targets of every agent at time t (s), shape (n, d)."""
        th, b = self(t)
        return affine_targets(r, th, b)

    def leader_path(self, r_leaders: ArrayLike, dt: float) -> Callable[[int], Array]:
        """Sampled leader path k -> Theta(k dt) r_l + b(k dt), shape (n_l, d): for ``simulate``."""
        rl = as_array(r_leaders, "r_leaders", ndim=2, shape=(None, self.d))
        dt = check_dt(dt)
        return lambda k: self.targets(rl, k * dt)


def hold(d: int = 2, theta: ArrayLike | None = None, b: ArrayLike | None = None) -> Maneuver:
    """A constant pose (identity by default)."""
    d = check_int(d, "d", low=1)
    th = np.eye(d) if theta is None else as_array(theta, "theta", shape=(d, d))
    bb = np.zeros(d) if b is None else as_array(b, "b", shape=(d,))
    return Maneuver(d, lambda t: th, lambda t: bb, "hold")


def translate(offset: Sequence[float], start: float = 0.0, stop: float = 1.0, smooth: bool = True) -> Maneuver:
    """b moves from 0 to ``offset`` (m) over [start, stop] s."""
    off = as_array(offset, "offset", ndim=1)
    start, stop, smooth = _window(start, stop, smooth)
    d = off.size
    return Maneuver(d, lambda t: np.eye(d), lambda t: _ramp(t, start, stop, smooth) * off, "translate")


def rotate(
    angle: float, start: float = 0.0, stop: float = 1.0, axis: ArrayLike | None = None, smooth: bool = True
) -> Maneuver:
    """Theta rotates from I to rotation(angle) (rad) over [start, stop] s; 3D about ``axis``."""
    angle = check_real_scalar(angle, "angle", unit="rad")
    start, stop, smooth = _window(start, stop, smooth)
    rotation(angle, axis)  # validates the axis
    d = 2 if axis is None else 3
    return Maneuver(d, lambda t: rotation(_ramp(t, start, stop, smooth) * angle, axis), lambda t: np.zeros(d), "rotate")


def scale(
    factors: Sequence[float] | float, start: float = 0.0, stop: float = 1.0, d: int = 2, smooth: bool = True
) -> Maneuver:
    """Theta goes from I to diag(factors) over [start, stop] s (a scalar scales every axis)."""
    start, stop, smooth = _window(start, stop, smooth)
    if isinstance(factors, int | float):
        f = np.full(check_int(d, "d", low=1), check_real_scalar(factors, "factors"))
    else:
        f = as_array(factors, "factors", ndim=1)
    if f.size == 0 or np.any(f <= 0):
        raise FormationError(f"scale factors must be positive (a zero factor collapses the formation), got {f}")
    dd = f.size
    return Maneuver(dd, lambda t: np.diag(1 + _ramp(t, start, stop, smooth) * (f - 1)), lambda t: np.zeros(dd), "scale")


def shear(
    amount: float, start: float = 0.0, stop: float = 1.0, d: int = 2, i: int = 0, j: int = 1, smooth: bool = True
) -> Maneuver:
    """Theta goes from I to I + amount e_i e_j^T over [start, stop] s."""
    shear_matrix(amount, d, i, j)  # validates the amount and the axes
    start, stop, smooth = _window(start, stop, smooth)
    return Maneuver(
        d, lambda t: shear_matrix(_ramp(t, start, stop, smooth) * amount, d, i, j), lambda t: np.zeros(d), "shear"
    )


class AffineImage:
    """Least-squares fit of the affine image of r: min over (Theta, b) of ||x - (Theta r + b)||.

    ``error(x)`` is the formation's distance from its affine image, the
    quantity the env rewards; zero iff x is an affine transformation of r.
    Batched: x of shape (..., n, d).
    """

    def __init__(self, r: ArrayLike) -> None:
        rr = as_array(r, "r", ndim=2)
        n, d = rr.shape
        h = np.hstack([rr, np.ones((n, 1))])  # (n, d + 1)
        if np.linalg.matrix_rank(h) < d + 1:
            raise FormationError(
                f"r (the nominal configuration) must affinely span R^{d}, got an affine span of dimension "
                f"{np.linalg.matrix_rank(h) - 1}"
            )
        self.r = rr
        self._h = h
        self._pinv = np.linalg.pinv(h)  # (d + 1, n)

    @cached_property
    def _resid(self) -> Array:
        """I - H H^+, the projector onto the complement of the affine image, shape (n, n) (dense: only
        for small n; :meth:`residual` of large configurations uses the factored form)."""
        return np.eye(self.r.shape[0]) - self._h @ self._pinv

    def fit(self, x: Array) -> tuple[Array, Array]:
        """Best (Theta, b), shapes (..., d, d) and (..., d)."""
        coef = np.matmul(self._pinv, x)  # (..., d + 1, d): rows Theta^T and b
        return np.swapaxes(coef[..., :-1, :], -1, -2), coef[..., -1, :]

    def residual(self, x: Array) -> Array:
        """x minus its best affine image, shape (..., n, d) (above ``DENSE_RESIDUAL_UP_TO`` agents as
        x - H (H^+ x), never forming the n x n projector)."""
        if self.r.shape[0] > DENSE_RESIDUAL_UP_TO:
            return x - np.matmul(self._h, np.matmul(self._pinv, x))
        return np.matmul(self._resid, x)

    def error(self, x: Array) -> Array:
        """RMS distance per agent (m) of x from the affine image of r, shape (...)."""
        res = self.residual(x)
        return np.sqrt(np.mean(np.sum(res * res, axis=-1), axis=-1))
