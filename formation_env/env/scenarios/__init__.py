"""Scenarios, one small file each; ``REGISTRY`` maps a name to its ``make``.

========================  ====  ===============================================================
name                      d     task
========================  ====  ===============================================================
``hold``                  2, 3  reach and hold a random affine image (``start="paper"``: the
                                paper's Section 4.3 example)
``maneuver``              2, 3  track a time-varying Theta(t), b(t): translate, rotate, scale, shear
``maneuver_3d``           3     ``maneuver`` on the 3D ``bipyramid_3d`` framework
``narrow_passage``        2     shrink through a gap narrower than the formation, restore, reach goal
``obstacle_field``        2, 3  reach a goal through scattered circular (spherical) obstacles
========================  ====  ===============================================================
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from . import hold, maneuver, maneuver_3d, narrow_passage, obstacle_field
from ._base import NAMED_FRAMEWORKS, Scenario

__all__ = ["NAMED_FRAMEWORKS", "REGISTRY", "Scenario"]

REGISTRY: dict[str, Callable[..., Any]] = {
    "hold": hold.make,
    "maneuver": maneuver.make,
    "maneuver_3d": maneuver_3d.make,
    "narrow_passage": narrow_passage.make,
    "obstacle_field": obstacle_field.make,
}

#: Scenario classes by name (for their class attributes, e.g. ``default_framework``).
CLASSES: dict[str, type[Scenario]] = {
    "hold": hold.Hold,
    "maneuver": maneuver.Maneuver,
    "maneuver_3d": maneuver_3d.Maneuver3D,
    "narrow_passage": narrow_passage.NarrowPassage,
    "obstacle_field": obstacle_field.ObstacleField,
}
