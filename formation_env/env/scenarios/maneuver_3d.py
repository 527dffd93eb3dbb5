"""``maneuver_3d``: the ``maneuver`` task in 3D on the 6-agent ``bipyramid_3d`` framework (4 leaders).

Same reference as :mod:`.maneuver` (translate, rotate about a random axis, scale per axis,
shear of x by y), world box [-10, 10]^3. Obstacle sensing in 3D is the nearest-obstacle
vector block (all zero here: no obstacles).
"""

from __future__ import annotations

from typing import ClassVar

from .maneuver import Maneuver

__all__ = ["Maneuver3D"]


class Maneuver3D(Maneuver):
    """The 3D manoeuvre-tracking task (see :mod:`.maneuver`)."""

    name: ClassVar[str] = "maneuver_3d"
    dims: ClassVar[tuple[int, ...]] = (3,)
    default_framework: ClassVar[str] = "bipyramid_3d"
