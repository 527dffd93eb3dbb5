"""Scenarios, one small file each; ``REGISTRY`` maps a name to its class (the one registry).

========================  ====  ===============================================================
name                      d     task
========================  ====  ===============================================================
``hold``                  2, 3  reach and hold a random affine image (``start="paper"``: the
                                paper's Section 4.3 example)
``maneuver``              2, 3  track a time-varying Theta(t), b(t): translate, rotate, scale, shear
``maneuver_3d``           3     ``maneuver`` on the 3D ``bipyramid_3d`` framework
``narrow_passage``        2     shrink through a gap narrower than the formation, restore, reach goal
``obstacle_field``        2, 3  reach a goal through scattered circular (spherical) obstacles
``moving_obstacles``      2     cross lanes of discs moving at constant velocity, reach the goal
========================  ====  ===============================================================

A new scenario of the package is a file with a :class:`Scenario` subclass and a line here; one of your own is a
file with the subclass and :func:`register_scenario`. Tests take the list from ``REGISTRY``.
"""

from __future__ import annotations

from formation_env.core.frameworks import NAMED_FRAMEWORKS  # re-exported: the env's names of frameworks

from ._base import Scenario
from .hold import Hold
from .maneuver import Maneuver
from .maneuver_3d import Maneuver3D
from .moving_obstacles import MovingObstacles
from .narrow_passage import NarrowPassage
from .obstacle_field import ObstacleField

__all__ = ["NAMED_FRAMEWORKS", "REGISTRY", "Scenario", "register_scenario"]

#: Scenario classes by name.
REGISTRY: dict[str, type[Scenario]] = {
    cls.name: cls for cls in (Hold, Maneuver, Maneuver3D, NarrowPassage, ObstacleField, MovingObstacles)
}


def register_scenario(cls: type[Scenario], replace: bool = False) -> type[Scenario]:
    """Add the scenario class ``cls`` to :data:`REGISTRY` under its ``name`` (once, unless ``replace``); returns
    ``cls`` (so it also decorates the class)."""
    if not (isinstance(cls, type) and issubclass(cls, Scenario)) or not cls.name:
        raise TypeError(f"register_scenario needs a Scenario subclass with a name, got {cls!r}")
    if cls.name in REGISTRY and REGISTRY[cls.name] is not cls and not replace:
        raise ValueError(f"scenario {cls.name!r} is registered already (pass replace=True to replace it)")
    REGISTRY[cls.name] = cls
    return cls
