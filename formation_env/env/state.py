"""The engine's state and one step's context: plain arrays, batched over B environments, no behaviour."""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

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
        net_sent: with a network (else None, as the four below): what every agent sent at k - 1, ..., k - d,
            shape (B, d, n, q) (neighbours delay; d = 0 otherwise).
        net_corr: the corrections c(k - 1), ..., c(k - d), shape (B, d, n_f, q) (input delay; d = 0 otherwise).
        net_held: the value each directed link j -> i holds, shape (B, m, q) (hold model; m = 0 otherwise), links
            in ``core.network.network_links`` order.
        net_rng: each copy's PCG64 generator state, shape (B, 4) uint64 (``env.network``).
        net_lost: link samples lost since the reset, shape (B,) int.
        net_time: under jitter, the env time (s), the sum of the drawn periods, shape (B,) (else None: t = k T).
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
    net_sent: Array | None = None
    net_corr: Array | None = None
    net_held: Array | None = None
    net_rng: NDArray[np.uint64] | None = None
    net_lost: NDArray[np.int64] | None = None
    net_time: Array | None = None

    @property
    def batch_size(self) -> int:
        """B."""
        return int(self.x.shape[0])


class StepContext(NamedTuple):
    """What a step computed beside the new state: every leader's observation ``obs`` (B, n_l, obs_dim) float32
    (None when the step observed the global state's blocks instead), the least-squares affine fit ``theta``
    (B, d, d) of all agents, and the global state's blocks ``blocks`` (B, n_l, state block dim) float32 (None
    unless the step observed them); the global state reuses the last two."""

    obs: NDArray[np.float32] | None
    theta: Array
    blocks: NDArray[np.float32] | None = None


class StepInfo(dict[str, Any]):
    """The info dict of one env step, whose values are immutable Python scalars (bool, int, float).

    ``copy.deepcopy`` of it is a plain copy: SB3's ``DummyVecEnv`` deep-copies every info at every step,
    which for eight scalar entries costs more than the env step through ``deepcopy``'s per-object dispatch.
    """

    def __deepcopy__(self, memo: dict[int, Any]) -> StepInfo:
        return StepInfo(self)
