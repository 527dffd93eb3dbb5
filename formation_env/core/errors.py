"""Domain errors and warnings of the maths core.

Every error subclasses a built-in (``ValueError``) so callers that catch the
built-in keep working, and every message names the object, the property that
failed, and the expected against the actual value.
"""

from __future__ import annotations

__all__ = [
    "ControlDimension",
    "FormationError",
    "FrameworkError",
    "LawAssumptionWarning",
    "ReachabilityWarning",
    "StabilityWarning",
    "StressMatrixError",
    "UnknownNameError",
    "UnstableParameterError",
]


class FormationError(ValueError):
    """Base class of all formation-env input errors."""


class UnknownNameError(FormationError, KeyError):
    """A name not in a registry (a ``KeyError`` too, for callers that look names up); the message lists the names."""

    __str__ = BaseException.__str__  # the message as written, not KeyError's repr of it


class StressMatrixError(FormationError):
    """A stress matrix fails one of its defining properties (the message says which)."""


class FrameworkError(FormationError):
    """A framework (positions, edges, leaders) is invalid, e.g. leaders do not span R^d."""


class ControlDimension(FormationError):
    """Arrays have incompatible shapes (python-control's name for the same error)."""


class UnstableParameterError(FormationError):
    """A sampling period or gain lies outside the range in which the chosen law is stable."""


class StabilityWarning(UserWarning):
    """A legal but doubtful setting, e.g. a sampling period beyond the stability bound."""


class ReachabilityWarning(StabilityWarning):
    """A leader path that no input of the dynamics can follow exactly (the message gives the residual)."""


class LawAssumptionWarning(StabilityWarning):
    """A law used outside the assumption its tracking guarantee needs (e.g. ``linear`` with steered leaders)."""
