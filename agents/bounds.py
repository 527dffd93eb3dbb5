"""A lower bound on each episode's time to goal, from the leaders' travel under the input bound.

Every scenario's success test needs, at some sample k, every agent within ``goal_tol`` of its goal position
x_i*(kT) (and more: the formation error below ``formation_tol``, no contact, ``hold_steps`` samples in a
row). A leader's input is bounded per axis, |u_j| <= u_max, so from its reset state (p0, v0) it can be at
sample k only inside the box

* double integrators: p0 + v0 t + [-u_max t^2 / 2, u_max t^2 / 2]^d, t = kT (ZOH inputs reach its corners);
* single integrators: p0 + [-u_max t, u_max t]^d.

The success test at sample k therefore needs, for every leader, the box within ``goal_tol`` of x_i*(kT):
k_reach is the first such sample, and success cannot come before k_reach + hold_steps - 1 (the test must
hold for ``hold_steps`` samples). The bound is (k_reach + hold_steps - 1) T seconds. It ignores obstacles,
the followers, the formation error, the speed cap and the need to stop, so no policy reaches it on tasks
that need those; arrival at any speed is allowed where the test allows it (one-sample tests), and it is
still a bound where the test needs the agent to stay (``hold``). ``inf`` where no sample within the
horizon passes; ``nan`` for general linear agents (no bound is derived for them).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from formation_env.env.engine import Engine, EngineState
from formation_env.env.scenarios._base import affine_batch

__all__ = ["time_lower_bound", "time_lower_bound_seeds"]

Array = NDArray[np.float64]


def time_lower_bound(engine: Engine, state: EngineState) -> Array:
    """Lower bound (s) on the time to goal of each episode of a reset state (B,); see the module docstring."""
    B, K = state.batch_size, engine.max_cycles
    if engine.kind not in ("double_integrator", "single_integrator"):
        return np.full(B, np.nan)
    lead = engine.leaders
    t = engine.dt * np.arange(1, K + 1, dtype=np.float64)  # sample times 1..K
    p0, v0 = state.pos[:, lead], state.vel[:, lead]  # (B, n_l, d)
    if engine.kind == "double_integrator":
        centre = p0[:, None] + v0[:, None] * t[None, :, None, None]  # (B, K, n_l, d)
        half = 0.5 * engine.u_max * t**2
    else:
        centre = np.broadcast_to(p0[:, None], (B, K, *p0.shape[1:]))
        half = engine.u_max * t
    tb = np.repeat(t, B)  # sample-major: entry k B + b
    th, b = engine.scenario.reference(_tile(state.params, K), tb)
    goal = affine_batch(engine.fw.positions[lead], th, b).reshape(K, B, lead.size, engine.d).transpose(1, 0, 2, 3)
    gap = np.maximum(np.abs(goal - centre) - half[None, :, None, None], 0.0)  # per axis, outside the box
    far = np.sqrt(np.einsum("bkld,bkld->bkl", gap, gap)).max(axis=2)  # (B, K): worst leader
    ok = far < engine.scenario.goal_tol
    first = np.where(ok.any(axis=1), ok.argmax(axis=1) + 1, -1)  # first passing sample, or -1
    k = first + engine.scenario.hold_steps - 1
    return np.where((first > 0) & (k <= K), engine.dt * k, np.inf)


def time_lower_bound_seeds(engine: Engine, seeds: Sequence[int]) -> Array:
    """:func:`time_lower_bound` of the episodes of a seeded suite (episode i from ``default_rng(seeds[i])``)."""
    state = engine.reset_each([np.random.default_rng(int(s)) for s in seeds])
    return time_lower_bound(engine, state)


def _tile(params: dict[str, Array], K: int) -> dict[str, Array]:
    """Every per-episode array repeated K times along the batch axis (sample-major: entry k B + b)."""
    return {key: np.concatenate([v] * K, axis=0) for key, v in params.items()}
