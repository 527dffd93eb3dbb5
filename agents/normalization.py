"""Observation statistics that training does not move, for a policy's ``VecNormalize``.

SB3's ``VecNormalize`` divides each observation entry by a running standard deviation over every sample seen. Under a
curriculum on episode draws (``train.leaders.RangeCurriculum``), those statistics are those of the curriculum's first
draws for a long time: an obstacle that starts at y in [3.5, 4] m has a running deviation of about 0.15 m, so when the
curriculum spreads it over [-4, 4] m the policy sees its y 50 deviations off and clipped. :class:`FixedMeanStd` scales
each entry by its declared bounds instead (the observation space's low and high, which every formation env declares
finite): the same input map from the first update to the last, whatever the curriculum draws.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from stable_baselines3.common.running_mean_std import RunningMeanStd

__all__ = ["FixedMeanStd"]


class FixedMeanStd(RunningMeanStd):
    """``RunningMeanStd`` whose ``update`` keeps it as set: mean = (low + high) / 2, var = ((high - low) / 2)^2,
    each (k,) in the observation's units, so that ``VecNormalize`` maps [low, high] onto [-1, 1]."""

    def __init__(self, low: NDArray[np.floating], high: NDArray[np.floating]) -> None:
        lo, hi = np.asarray(low, dtype=np.float64), np.asarray(high, dtype=np.float64)
        if lo.shape != hi.shape or not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))) or np.any(hi < lo):
            raise ValueError(f"bounds: low and high must be finite, of one shape, low <= high; got {lo}, {hi}")
        super().__init__(shape=lo.shape)
        self.mean = 0.5 * (lo + hi)
        self.var = np.square(0.5 * (hi - lo))

    def update(self, arr: NDArray[np.floating]) -> None:
        """Nothing: the statistics are the bounds'."""
