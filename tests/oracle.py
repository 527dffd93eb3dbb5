"""A plain numpy step: the oracle the engine's step is tested against (as gymnax checks its envs).

Written for clarity, not speed, and apart from the engine: the follower law is the core's ``FollowerLaw.step``
(not the engine's precomputed map), the geometry is broadcast numpy (not the compiled kernels), and the
default observation and rewards follow ``formation_v0``'s docstring formula by formula.
"""

from __future__ import annotations

import numpy as np

from formation_env.core.dynamics import c2d_zoh
from formation_env.core.network import NetState
from formation_env.env.engine import Engine, EngineState
from formation_env.env.network import generator_of, words_of
from formation_env.env.obstacles import Capsules


# ---------------------------------------------------------------------------- geometry
def capsule_distance(p, caps: Capsules):
    """Surface distance from points p (B, n, d) to every capsule, (B, n, m)."""
    w = p[:, :, None, :] - caps.a[:, None]
    ee = np.sum(caps.e * caps.e, axis=-1)[:, None]
    s = np.clip(np.sum(w * caps.e[:, None], axis=-1) / np.where(ee > 0, ee, 1.0), 0.0, 1.0)
    diff = w - s[..., None] * caps.e[:, None]
    return np.linalg.norm(diff, axis=-1) - caps.rad[:, None]


def nearest_vectors(p, caps: Capsules, k: int, max_range: float):
    """Proximity vectors to the k nearest capsules (B, l, k, d): unit direction from p (B, l, d) toward the
    capsule's nearest point, times (1 - surface distance / max_range)^+; missing capsules give 0."""
    B, l, d = p.shape
    out = np.zeros((B, l, k, d))
    m = caps.a.shape[1]
    if m == 0 or k == 0:
        return out
    w = p[:, :, None, :] - caps.a[:, None]
    ee = np.sum(caps.e * caps.e, axis=-1)[:, None]
    s = np.clip(np.sum(w * caps.e[:, None], axis=-1) / np.where(ee > 0, ee, 1.0), 0.0, 1.0)
    diff = w - s[..., None] * caps.e[:, None]
    surf = np.linalg.norm(diff, axis=-1) - caps.rad[:, None]
    kk = min(k, m)
    idx = np.argsort(surf, axis=-1, kind="stable")[..., :kk]
    toward = -np.take_along_axis(diff, idx[..., None], axis=2)
    norm = np.linalg.norm(toward, axis=-1)
    mag = np.clip(1.0 - np.take_along_axis(surf, idx, axis=2) / max_range, 0.0, 1.0)
    out[:, :, :kk] = toward / np.maximum(norm, 1e-12)[..., None] * mag[..., None]
    return out


def route_lengths(route_row, pvec, radius, pos, goal):
    """A scenario's compiled route row over a batch: pvec (B, k), pos, goal (B, n, d) -> (B, n) m."""
    out = np.empty(pos.shape[:2])
    for b in range(pos.shape[0]):
        route_row(np.ascontiguousarray(pvec[b], dtype=float), float(radius), np.ascontiguousarray(pos[b], dtype=float),
                  np.ascontiguousarray(goal[b], dtype=float), out[b])  # fmt: skip
    return out


def phase_distance(eng: Engine, state: EngineState):
    """Every agent's distance to its goal state in phase space, sqrt(g^2 + |v - v*|^2 (1 s)^2), (B, n), m; g the
    scenario's route length (the ``approach`` potential)."""
    g = route_lengths(eng.scenario.route_row, state.params["_pvec"], eng.agent_radius, state.pos, state.goal)
    ev = state.vel - state.goal_vel
    return np.sqrt(g * g + np.sum(ev * ev, axis=-1))


def path_distance(p0, p1, caps0: Capsules, caps1: Capsules, samples: int = 1001):
    """Smallest distance between each agent's motion and each capsule over a step, by dense sampling of the
    relative motion (B, n, m): an independent check of the closed-form segment-segment distance. The capsule
    translates from its start at the step's beginning to its start at the end; a capsule that turned or changed
    radius is measured with both its axes and radii (the engine's convention), the smaller distance counts."""
    best = np.full((p0.shape[0], p0.shape[1], caps0.a.shape[1]), np.inf)
    frames = [(caps0.e, caps0.rad)]
    if not (np.array_equal(caps0.e, caps1.e) and np.array_equal(caps0.rad, caps1.rad)):
        frames.append((caps1.e, caps1.rad))
    for s in np.linspace(0.0, 1.0, samples):
        q = p0 + s * (p1 - p0)
        for e, rad in frames:
            c = Capsules(caps0.a + s * (caps1.a - caps0.a), e, rad)
            best = np.minimum(best, capsule_distance(q, c))
    return best


def ray_ranges(o, u, caps: Capsules, max_range: float, samples: int = 3001):
    """Range along each ray (B, l, R) by marching the ray in small steps until it is inside a capsule, or within half
    a step of a zero-thickness one (so a wall between two samples is found); the reading errs by about a step."""
    ts = np.linspace(0.0, max_range, samples)
    out = np.full((o.shape[0], o.shape[1], u.shape[0]), max_range)
    slack = np.where(caps.rad > 0, 0.0, 0.5 * (ts[1] - ts[0]))[:, None, None, :]  # thin walls: half a step
    for k, uk in enumerate(u):
        pts = o[:, :, None, :] + ts[None, None, :, None] * uk  # (B, l, S, d)
        B, l, S, d = pts.shape
        dist = capsule_distance(pts.reshape(B, l * S, d), caps).reshape(B, l, S, -1)
        inside = (dist <= slack).any(axis=-1)
        first = np.where(inside.any(axis=-1), ts[np.argmax(inside, axis=-1)], max_range)
        out[:, :, k] = first
    return out


# ---------------------------------------------------------------------------- the step
def network_law(eng: Engine, state: EngineState, u):
    """The followers' law over the engine's network, copy by copy: the core's ``NetworkLoop.step`` with the draws
    of ``Network.draw`` on each copy's generator (read from ``state.net_rng``); (x', periods (B,), the network's
    state fields after the step)."""
    net, loop, dyn = eng.network, eng._net.loop, eng.dynamics
    B = state.batch_size
    x1, periods = np.empty_like(state.x), np.empty(B)
    fields = {f: np.empty_like(getattr(state, f)) for f in ("net_sent", "net_corr", "net_held", "net_rng")}
    lost = state.net_lost.copy()
    for b in range(B):
        gen = generator_of(state.net_rng[b])
        t_k, delivered = net.draw(gen, eng.dt, loop.m)
        if net.jitter is None or dyn.discrete:
            a_d, b_d = dyn.zoh(t_k)
        elif not np.any(dyn.A):
            a_d, b_d = np.eye(dyn.q), t_k * dyn.B
        else:
            a_d, b_d = c2d_zoh(dyn.A, dyn.B, t_k)
        st = NetState(state.x[b], state.net_sent[b], state.net_corr[b], state.net_held[b])
        nxt, _ = loop.step(st, delivered, a_d, b_d, u[b])
        x1[b], periods[b] = nxt.x, t_k
        fields["net_sent"][b], fields["net_corr"][b], fields["net_held"][b] = nxt.sent, nxt.corr, nxt.held
        fields["net_rng"][b] = words_of(gen)
        lost[b] += int(np.sum(~delivered))
    return x1, periods, {**fields, "net_lost": lost}


def oracle_step(eng: Engine, state: EngineState, actions):
    """(state', obs, rewards, terminated, truncated, info) of the default observation and rewards."""
    a = np.clip(np.asarray(actions, dtype=np.float64), -1.0, 1.0)
    u = eng.u_max * a
    net: dict = {}
    if eng.network is None:
        x1, mem1 = eng.law.step(state.x, u, state.memory)
        period = np.full(state.batch_size, eng.dt)
    else:
        x1, period, net = network_law(eng, state, u)
        mem1 = None
    pos = np.einsum("dq,bnq->bnd", eng.dynamics.C, x1)
    if not eng.dynamics.discrete and not np.any(eng.dynamics.C @ eng.dynamics.B):
        vel = np.einsum("dq,bnq->bnd", eng.dynamics.C @ eng.dynamics.A, x1)
    else:
        vel = (pos - state.pos) / period[:, None, None]
    k = state.k + 1
    t0 = eng.time(state)
    t = t0 + period if state.net_time is not None else k * eng.dt
    if state.net_time is not None:
        net["net_time"] = t
    B, n, d = pos.shape
    sc = eng.scenario
    # goals
    if sc.moving_goal:
        th, b = sc.reference(state.params, t)
        th1, b1 = sc.reference(state.params, t + eng.dt)
        goal = np.einsum("bij,nj->bni", th, sc.r) + b[:, None]
        goal_vel = (np.einsum("bij,nj->bni", th1, sc.r) + b1[:, None] - goal) / eng.dt
    else:
        goal = np.einsum("bij,nj->bni", state.params["goal_theta"], sc.r) + state.params["goal_b"][:, None]
        goal_vel = np.zeros_like(goal)
    # contacts
    clear = np.full(B, np.inf)
    pairs = [(i, j) for i in range(n) for j in range(i + 1, n)] if n <= 64 else [tuple(e) for e in eng.fw.edges]
    for i, j in pairs:
        clear = np.minimum(clear, np.linalg.norm(pos[:, i] - pos[:, j], axis=-1) - 2 * eng.agent_radius)
    caps = eng.capsules(state.params, k, t)
    if caps.a.shape[1]:
        clear = np.minimum(clear, capsule_distance(pos, caps).min(axis=(1, 2)) - eng.agent_radius)
        caps0 = eng.capsules(state.params, state.k, t0)
        shift = np.abs(caps.a - caps0.a).max(axis=(1, 2), initial=0.0)
        turned = np.any(caps.e != caps0.e, axis=(1, 2)) | np.any(caps.rad != caps0.rad, axis=1)
        ends = np.abs(caps.a + caps.e - caps0.a - caps0.e).max(axis=(1, 2), initial=0.0)
        moved = np.abs(pos - state.pos).max(axis=(1, 2)) + np.where(turned, np.maximum(shift, ends), shift)
        for bb in np.flatnonzero(moved > 2 * eng.agent_radius / np.sqrt(d)):
            c0, c1 = (Capsules(*(f[bb : bb + 1] for f in c)) for c in (caps0, caps))
            sw = path_distance(state.pos[bb : bb + 1], pos[bb : bb + 1], c0, c1).min()
            clear[bb] = min(clear[bb], sw - eng.agent_radius)
    lo, hi = eng.bounds
    oob = np.any((pos < lo) | (pos > hi), axis=(1, 2))
    collision = (clear < 0) | oob
    # affine fit
    H = np.hstack([sc.r, np.ones((n, 1))])
    coef = np.stack([np.linalg.lstsq(H, pos[bb], rcond=None)[0] for bb in range(B)])  # (B, d + 1, d)
    theta = np.swapaxes(coef[:, :d], 1, 2)
    err = np.sqrt(np.mean(np.sum((pos - H @ coef) ** 2, axis=-1), axis=1))
    gd = np.linalg.norm(goal - pos, axis=-1)
    ok = (gd.max(axis=1) < sc.goal_tol) & (err < sc.formation_tol) & ~collision
    streak = np.where(ok, state.streak + 1, 0)
    success = streak >= sc.hold_steps
    terminated = collision | success if sc.terminate_on_success else collision
    truncated = (k >= eng.max_cycles) & ~terminated
    # the default observation, per leader
    L = eng.leaders
    ext = hi - lo
    obs = []
    for i in L:
        others = [pos[:, j] - pos[:, i] for j in L if j != i]
        if d == 2:
            sense = ray_ranges(pos[:, [i]], eng.ray_dirs, caps, eng.obstacle_range)[:, 0] / eng.obstacle_range
        else:
            sense = nearest_vectors(pos[:, [i]], caps, eng.n_nearest, eng.obstacle_range).reshape(B, -1)
        parts = [
            np.clip(pos[:, i], lo, hi),
            np.clip(vel[:, i], -eng.v_bound, eng.v_bound),
            *[np.clip(o, -ext, ext) for o in others],
            np.clip(goal[:, i] - pos[:, i], -ext, ext),
            np.clip(goal_vel[:, i], -eng.v_bound, eng.v_bound),
            np.clip(theta.reshape(B, -1), -3, 3),
            (k / eng.max_cycles)[:, None],
            np.minimum(err, np.linalg.norm(ext))[:, None],
            np.clip(sense, -1, 1),
        ]
        obs.append(np.concatenate(parts, axis=1))
    obs = np.stack(obs, axis=1).astype(np.float32)
    # rewards
    w = eng.reward_weights
    gl0, gl1 = state.goal_dist, gd[:, L]
    rew = (
        w["progress"] * (gl0 - gl1)
        - w["distance"] * eng.dt * gl1
        - w["formation"] * eng.dt * err[:, None]
        - w["effort"] * eng.dt * np.sum(a * a, axis=-1) / eng.p
        - w["collision"] * collision[:, None]
        + w["success"] * success[:, None]
    )
    new = EngineState(x1, pos, vel, mem1, k, goal, goal_vel, gl1, err, streak, state.params, **net)
    lost = net["net_lost"] / (k * eng._net.loop.m) if net else np.zeros(B)
    info = {"success": success, "collision": collision, "out_of_bounds": oob, "formation_error": err,
            "min_clearance": clear, "goal_distance": gd.max(axis=1), "time": t,
            "control_effort": np.sum(u * u, axis=-1), "lost_fraction": lost}  # fmt: skip
    return new, obs, rew, terminated, truncated, info
