"""A library of named frameworks: the paper's 5-agent example and classic shapes in 2D and 3D.

Every function returns a :class:`Framework`; those with a known stress matrix
return it through :func:`paper_omega` or can be designed with
:func:`formation_env.core.design_stress`.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from .framework import Framework

__all__ = ["paper_example", "paper_omega", "PAPER_OMEGA_PRINTED"]

#: The stress matrix exactly as printed in the paper (Section 4.3), rounded to 3 decimals.
#: Agents 1-3 (indices 0-2) are leaders, 4-5 (indices 3-4) followers. Its rows sum to
#: about -0.001 and one eigenvalue is about -4.6e-4, so it passes :func:`check_stress`
#: only with ``rtol=1e-3``; :func:`paper_omega` with ``exact=True`` projects it.
PAPER_OMEGA_PRINTED: NDArray[np.float64] = np.array(
    [
        [0.292, -0.292, -0.292, 0.292, 0.0],
        [-0.292, 0.354, 0.354, -0.542, 0.125],
        [-0.292, 0.354, 0.354, -0.542, 0.125],
        [0.292, -0.542, -0.542, 1.292, -0.500],
        [0.0, 0.125, 0.125, -0.500, 0.250],
    ]
)
PAPER_OMEGA_PRINTED.setflags(write=False)


def paper_example() -> Framework:
    """The paper's 5-agent framework (Fig. 1): leaders (1,0), (0,1), (0,-1); followers (-1,0), (-2,0).

    The edges are the nonzero off-diagonal entries of the printed stress matrix
    (every pair but agents 1 and 5).
    """
    r = np.array([[1.0, 0.0], [0.0, 1.0], [0.0, -1.0], [-1.0, 0.0], [-2.0, 0.0]])
    edges = [(i, j) for i in range(5) for j in range(i + 1, 5) if PAPER_OMEGA_PRINTED[i, j] != 0.0]
    return Framework(r, edges, leaders=[0, 1, 2], name="paper_example")


def paper_omega(exact: bool = True) -> NDArray[np.float64]:
    """The paper's stress matrix: as printed (``exact=False``) or projected onto the nearest exact stress."""
    if not exact:
        return PAPER_OMEGA_PRINTED.copy()
    from .stress import project_stress

    return project_stress(PAPER_OMEGA_PRINTED, paper_example())
