"""The engine's state and one step's context: plain arrays, batched over B environments, no behaviour."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from .obstacles import Capsules

__all__ = ["EngineState", "StepContext", "StepInfo"]

Array = NDArray[np.float64]


class EngineState(NamedTuple):
    """Everything that changes during an episode, batched over B environments (immutable; steps make new ones).

    Attributes:
        x: agent states, shape (B, n, q).
        pos: positions C x, shape (B, n, d), m.
        vel: velocities, shape (B, n, d), m/s (C A x when C B = 0, e.g. double integrators; else the mean
            velocity over the last sample, e.g. the applied single-integrator command).
        memory: follower-law memory (``dynamic_distributed``: previous inputs), shape (B, n_f, p), or None.
        k: samples taken, shape (B,) int.
        goal: goal (reference) positions x_i* = Theta(t) r_i + b(t) of every agent, shape (B, n, d), m.
        goal_vel: their velocity (x*(t + T) - x*(t)) / T, shape (B, n, d), m/s (zero for static goals).
        goal_dist: each leader's distance to its goal position, shape (B, n_l), m.
        err: affine-image formation error (RMS residual of the affine fit), shape (B,), m.
        streak: consecutive successful samples, shape (B,) int.
        params: per-episode arrays (B, ...): the scenario's (goal pose, obstacles under their types' keys, its
            own parameters) and derived ones (keys starting with "_"), all read-only.
    """

    x: Array
    pos: Array
    vel: Array
    memory: Array | None
    k: NDArray[np.int64]
    goal: Array
    goal_vel: Array
    goal_dist: Array
    err: Array
    streak: NDArray[np.int64]
    params: dict[str, Array]

    @property
    def batch_size(self) -> int:
        """B."""
        return int(self.x.shape[0])


class StepContext(NamedTuple):
    """What observation blocks and reward terms read: one step's measurements, batched over B.

    ``state`` is the new state (for a reset, the first one) and ``prev`` the one before (None at reset);
    ``actions`` the clipped leader actions (B, n_l, p) in [-1, 1] (zeros at reset). ``theta`` (B, d, d) and
    ``b`` (B, d) are the least-squares affine fit of all agents (m); ``clearance`` (B,) the smallest gap
    between surfaces (m); ``collision``, ``out_of_bounds``, ``success`` (B,) bool; ``at_goal`` (B,) bool: the
    scenario's success test holds at this sample and nothing collided (``success`` needs ``hold_steps`` of
    them); ``capsules`` the obstacles at this time; ``rng`` the generator of observation noise (one, or one
    per environment; None: no noise).
    """

    engine: Any
    state: EngineState
    prev: EngineState | None
    actions: Array
    theta: Array
    b: Array
    clearance: Array
    collision: NDArray[np.bool_]
    out_of_bounds: NDArray[np.bool_]
    at_goal: NDArray[np.bool_]
    success: NDArray[np.bool_]
    capsules: Capsules
    rng: np.random.Generator | Sequence[np.random.Generator] | None


class StepInfo(dict[str, Any]):
    """The info dict of one env step, whose values are immutable Python scalars (bool, int, float).

    ``copy.deepcopy`` of it is a plain copy: SB3's ``DummyVecEnv`` deep-copies every info at every step,
    which for eight scalar entries costs more than the env step through ``deepcopy``'s per-object dispatch.
    """

    def __deepcopy__(self, memo: dict[int, Any]) -> StepInfo:
        return StepInfo(self)
