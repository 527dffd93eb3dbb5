"""One place for input checks: shapes, finiteness, symmetric matrices.

Messages follow python-control's ``_check_shape``: they name the object and give
the expected against the actual value. Public input is checked with ``raise``,
never ``assert``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .errors import ControlDimension, FormationError

__all__ = ["as_array", "check_finite", "check_kwargs_consumed", "check_shape"]


def as_array(x: ArrayLike, name: str, ndim: int | None = None) -> NDArray[np.float64]:
    """Convert ``x`` to a float64 array, checking it is finite and has ``ndim`` dimensions.

    Raises:
        ControlDimension: wrong number of dimensions.
        FormationError: NaN or infinite entries (the message counts them).
    """
    try:
        arr = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError) as exc:  # ragged lists, strings
        raise FormationError(f"{name} must be a numeric array: {exc}") from exc
    if ndim is not None and arr.ndim != ndim:
        raise ControlDimension(f"{name} must have {ndim} dimensions, got shape {arr.shape}")
    check_finite(arr, name)
    return arr


def check_finite(arr: NDArray[Any], name: str) -> None:
    """Raise ``FormationError`` if ``arr`` holds NaN or infinite values."""
    if not np.all(np.isfinite(arr)):
        bad = int(np.size(arr) - np.count_nonzero(np.isfinite(arr)))
        raise FormationError(f"{name} holds {bad} non-finite value(s) (NaN or inf)")


def check_shape(arr: NDArray[Any], expected: tuple[int | None, ...], name: str) -> None:
    """Raise ``ControlDimension`` unless ``arr.shape`` matches ``expected`` (None = any)."""
    ok = arr.ndim == len(expected) and all(e is None or e == s for e, s in zip(expected, arr.shape, strict=True))
    if not ok:
        want = "(" + ", ".join("*" if e is None else str(e) for e in expected) + ")"
        raise ControlDimension(f"{name} must have shape {want}, got {arr.shape}")


def check_kwargs_consumed(kwargs: dict[str, Any], where: str) -> None:
    """Refuse unused keyword arguments (VMAS ``check_kwargs_consumed``)."""
    if kwargs:
        names = ", ".join(sorted(kwargs))
        raise TypeError(f"{where} got unexpected keyword argument(s): {names}")
