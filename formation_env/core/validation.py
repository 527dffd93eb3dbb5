"""One place for input checks at the public boundary of the maths core.

Every public function of :mod:`formation_env.core` checks its arguments with
these helpers: type, shape, finiteness, range and meaning. Messages follow
python-control's ``_check_shape``: they name the argument and give the expected
against the actual value. Public input is checked with ``raise``, never ``assert``.

Errors:

* ``TypeError``: the argument has the wrong kind (None, a string for a number,
  a float for an index, a complex array, an object that is not a ``Framework``).
* :class:`ControlDimension`: the argument has the wrong shape.
* :class:`FormationError`: the argument has the right kind and shape but a bad
  value (NaN, out of range, an index outside 0..n-1, an asymmetric matrix).
"""

from __future__ import annotations

import numbers
from collections.abc import Iterable
from typing import Any

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray

from .errors import ControlDimension, FormationError

__all__ = [
    "as_array",
    "as_index_array",
    "check_bool",
    "check_dt",
    "check_finite",
    "check_int",
    "check_kwargs_consumed",
    "check_mapping",
    "check_real_scalar",
    "check_rtol",
    "check_seed",
    "check_shape",
    "check_square_matrix",
    "check_symmetric",
    "json_object",
]


def _describe(x: Any) -> str:
    """Short description of a value for messages: its repr, cut to 60 characters, and its type."""
    text = repr(x)
    if len(text) > 60:
        text = text[:57] + "..."
    return f"{text} ({type(x).__name__})"


def as_array(
    x: ArrayLike,
    name: str,
    ndim: int | None = None,
    shape: tuple[int | None, ...] | None = None,
    finite: bool = True,
) -> NDArray[np.float64]:
    """Convert ``x`` to a real float64 array, checking ``ndim``, ``shape`` (None = any) and finiteness
    (``finite=False`` leaves NaN and inf to the caller, e.g. to name the agent whose action holds them).

    Raises:
        TypeError: None, a string, a complex or a non-numeric (object, ragged) array.
        ControlDimension: wrong number of dimensions or shape.
        FormationError: NaN or infinite entries (the message counts them).
    """
    if x is None:
        raise TypeError(f"{name} must be a real numeric array, got None")
    if isinstance(x, str | bytes):
        raise TypeError(f"{name} must be a real numeric array, got the string {x!r}")
    if sp.issparse(x):
        raise TypeError(f"{name} must be a dense array here, got a scipy.sparse {type(x).__name__}")
    try:
        raw = np.asarray(x)
    except (TypeError, ValueError) as exc:  # ragged lists
        raise TypeError(f"{name} must be a real numeric array: {exc}") from exc
    if np.iscomplexobj(raw):
        raise TypeError(f"{name} must be real, got a complex array (dtype {raw.dtype})")
    if raw.dtype.kind not in "biuf":
        raise TypeError(f"{name} must be a real numeric array, got dtype {raw.dtype} from {_describe(x)}")
    arr = np.asarray(raw, dtype=np.float64)
    if ndim is not None and arr.ndim != ndim:
        raise ControlDimension(f"{name} must have {ndim} dimensions, got shape {arr.shape}")
    if shape is not None:
        check_shape(arr, shape, name)
    if finite:
        check_finite(arr, name)
    return arr


def as_index_array(
    x: Any, name: str, n: int | None = None, ndim: int = 1, min_size: int = 0, distinct: bool = False
) -> NDArray[np.int64]:
    """Integer indices (leaders, edges) as an int64 array, refusing floats instead of truncating them.

    Args:
        x: a sequence, range or array of integers; for ``ndim=2`` an (m, 2) array of edges.
        name: argument name for messages.
        n: indices must lie in 0..n-1 (None: only non-negative).
        ndim: 1 (index list) or 2 (edge list, shape (m, 2)).
        min_size: fewest entries (rows for ``ndim=2``).
        distinct: refuse repeated indices (``ndim=1``).

    Raises:
        TypeError: None, a string, or non-integer entries (e.g. 0.7).
        ControlDimension: wrong shape.
        FormationError: out of range, repeated, or too few.
    """
    if x is None:
        raise TypeError(f"{name} must be a sequence of integer agent indices, got None")
    if isinstance(x, str | bytes):
        raise TypeError(f"{name} must be a sequence of integer agent indices, got the string {x!r}")
    if isinstance(x, numbers.Number) or not isinstance(x, Iterable | np.ndarray):
        raise TypeError(f"{name} must be a sequence of integer agent indices, got {_describe(x)}")
    try:
        seq = list(x) if not isinstance(x, np.ndarray) else x
        raw = np.asarray(seq)
    except (TypeError, ValueError) as exc:  # ragged lists
        raise ControlDimension(f"{name} must be a regular array of integer agent indices (not ragged): {exc}") from exc
    if raw.size == 0:
        raw = raw.astype(np.int64).reshape((0,) if ndim == 1 else (0, 2))
    if raw.dtype == bool or raw.dtype.kind not in "iu":
        if raw.dtype.kind == "O":
            try:
                ok = all(isinstance(v, numbers.Integral) and not isinstance(v, bool) for v in raw.ravel())
            except TypeError:
                ok = False
            if ok:
                raw = raw.astype(np.int64)
        if raw.dtype.kind not in "iu" or raw.dtype == bool:
            cls = FormationError if raw.dtype.kind in "f" else TypeError
            raise cls(
                f"{name} must hold integer agent indices, got dtype {raw.dtype} "
                f"(e.g. {raw.ravel()[:3].tolist()}); float indices are refused, not truncated"
            )
    idx = raw.astype(np.int64)
    if ndim == 1 and idx.ndim != 1:
        raise ControlDimension(f"{name} must be a flat sequence of indices, got shape {idx.shape}")
    if ndim == 2:
        if idx.ndim == 1 and idx.size == 2:
            idx = idx.reshape(1, 2)
        if idx.ndim != 2 or idx.shape[1] != 2:
            raise ControlDimension(f"{name} must have shape (m, 2) (pairs of agents), got {idx.shape}")
    rows = idx.shape[0]
    if rows < min_size:
        raise FormationError(f"{name} must have at least {min_size} entries, got {rows}")
    if idx.size:
        lo, hi = int(idx.min()), int(idx.max())
        if lo < 0 or (n is not None and hi >= n):
            bad = lo if lo < 0 else hi
            rng = "0.." + (str(n - 1) if n is not None else "")
            raise FormationError(f"{name} must be agent indices in {rng}, got {bad} (outside {rng})")
    if distinct and np.unique(idx).size != idx.size:
        raise FormationError(f"{name} must be distinct indices, got repeated indices in {idx.tolist()[:20]}")
    return idx


def check_real_scalar(
    x: Any,
    name: str,
    *,
    low: float | None = None,
    high: float | None = None,
    low_open: bool = True,
    high_open: bool = True,
    allow_inf: bool = False,
    unit: str = "",
    what: str = "",
) -> float:
    """A real, finite (unless ``allow_inf``) number in the range (low, high) (ends open by default).

    Raises:
        TypeError: None, a string, a bool, a complex number or an array.
        FormationError: NaN, infinite, or out of range.
    """
    if isinstance(x, bool | np.bool_) or x is None or isinstance(x, str | bytes):
        raise TypeError(f"{name} must be a real number{unit and ' (' + unit + ')'}, got {_describe(x)}")
    if isinstance(x, np.ndarray) and x.ndim == 0:
        x = x.item()
    if isinstance(x, complex | np.complexfloating):
        raise TypeError(f"{name} must be a real number, got the complex {x!r}")
    if not isinstance(x, numbers.Real):
        raise TypeError(f"{name} must be a real number{unit and ' (' + unit + ')'}, got {_describe(x)}")
    v = float(x)
    bounds = []
    if low is not None:
        bounds.append(f"{'>' if low_open else '>='} {low:g}")
    if high is not None:
        bounds.append(f"{'<' if high_open else '<='} {high:g}")
    want = what or ("a finite number" + (" " + " and ".join(bounds) if bounds else ""))
    bad = (
        np.isnan(v)
        or (np.isinf(v) and not allow_inf)
        or (low is not None and (v < low or (low_open and v == low)))
        or (high is not None and (v > high or (high_open and v == high)))
    )
    if bad:
        raise FormationError(f"{name} must be {want}, got {v:g}")
    return v


def check_int(x: Any, name: str, *, low: int | None = None, high: int | None = None, what: str = "") -> int:
    """An integer (Python or numpy; floats, even integral ones such as 3.0, are refused) in [low, high].

    Raises:
        TypeError: not a number (None, str, bool, complex).
        FormationError: a float (1.5, NaN, inf, 3.0) or out of range.
    """
    rng = " and ".join(([f">= {low}"] if low is not None else []) + ([f"<= {high}"] if high is not None else []))
    want = what or ("an integer" + (" " + rng if rng else ""))
    if isinstance(x, np.ndarray) and x.ndim == 0:
        x = x.item()
    if isinstance(x, bool | np.bool_) or not isinstance(x, numbers.Real):
        raise TypeError(f"{name} must be {want}, got {_describe(x)}")
    if not isinstance(x, numbers.Integral):
        raise FormationError(f"{name} must be {want}, got the float {x!r} (not truncated)")
    v = int(x)
    if (low is not None and v < low) or (high is not None and v > high):
        raise FormationError(f"{name} must be {want}, got {v}")
    return v


def check_bool(x: Any, name: str) -> bool:
    """A bool (Python or numpy)."""
    if not isinstance(x, bool | np.bool_):
        raise TypeError(f"{name} must be True or False, got {_describe(x)}")
    return bool(x)


def check_dt(dt: Any, name: str = "dt") -> float:
    """A sampling period: a real, finite number > 0 (seconds)."""
    return check_real_scalar(
        dt, name, low=0.0, unit="a sampling period in seconds", what="a positive finite sampling period in seconds"
    )


def check_rtol(rtol: Any, name: str = "rtol") -> float:
    """A relative tolerance: a real number in [0, 1)."""
    return check_real_scalar(rtol, name, low=0.0, low_open=False, high=1.0)


def check_seed(seed: Any, name: str = "seed") -> int:
    """A seed for ``np.random.default_rng``: a non-negative integer."""
    return check_int(seed, name, low=0)


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


def check_square_matrix(x: Any, name: str, allow_sparse: bool = True) -> Any:
    """A real, finite, square matrix: a float64 array or (``allow_sparse``) a CSR matrix.

    Raises:
        TypeError: None, string, complex or non-numeric input.
        ControlDimension: not two-dimensional and square, or empty.
        FormationError: NaN or infinite entries.
    """
    if sp.issparse(x):
        if not allow_sparse:
            raise TypeError(f"{name} must be a dense array, got a scipy.sparse matrix")
        if np.iscomplexobj(x.data if hasattr(x, "data") else np.zeros(0)):
            raise TypeError(f"{name} must be real, got a complex sparse matrix")
        if x.dtype.kind not in "biuf":
            raise TypeError(f"{name} must be a real numeric matrix, got dtype {x.dtype}")
        mat = sp.csr_matrix(x, dtype=np.float64)
        check_finite(mat.data, name)
    else:
        mat = as_array(x, name, ndim=2)
    if mat.shape[0] != mat.shape[1] or mat.shape[0] == 0:
        raise ControlDimension(f"{name} must be a non-empty square matrix (n, n), got shape {mat.shape}")
    return mat


def check_symmetric(mat: Any, name: str, rtol: float) -> None:
    """Raise ``FormationError`` unless max |M - M^T| <= rtol * max |M_ij| (dense or sparse)."""
    if sp.issparse(mat):
        diff = abs(mat - mat.T)
        asym = float(diff.max()) if diff.nnz else 0.0
        scale = float(abs(mat).max()) if mat.nnz else 0.0
    else:
        asym = float(np.max(np.abs(mat - mat.T))) if mat.size else 0.0
        scale = float(np.max(np.abs(mat))) if mat.size else 0.0
    if asym > rtol * scale:
        raise FormationError(
            f"{name} must be symmetric: max |{name} - {name}^T| = {asym:.3g} > tolerance {rtol * scale:.3g} "
            f"(rtol {rtol:g} times max |entry| {scale:.3g})"
        )


def check_mapping(x: Any, name: str) -> dict[str, Any]:
    """A dict of keyword-style settings, or None (an empty dict); anything else is a TypeError naming ``name``."""
    if x is None:
        return {}
    if not isinstance(x, dict):
        raise TypeError(f"{name} must be a dict or None, got {_describe(x)}")
    return x


def json_object(flag: str, text: str) -> dict[str, Any]:
    """The JSON object given to the command-line ``flag`` ({} for ''); a ValueError naming the flag if ``text`` is
    not one."""
    import json

    if not text:
        return {}
    try:
        value = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ValueError(f"{flag} must be a JSON object such as '{{\"dt\": 0.05}}': {exc}") from None
    if not isinstance(value, dict):
        raise ValueError(f"{flag} must be a JSON object (a dict of arguments), got {text!r}")
    return value


def check_kwargs_consumed(kwargs: dict[str, Any], where: str) -> None:
    """Refuse unused keyword arguments (VMAS ``check_kwargs_consumed``)."""
    if kwargs:
        names = ", ".join(sorted(kwargs))
        raise TypeError(f"{where} got unexpected keyword argument(s): {names}")
