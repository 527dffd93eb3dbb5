"""The communication network inside the compiled step: the ``network`` part (:data:`~formation_env.env.kernel.PARTS`).

With ``Engine(..., network=...)`` the followers' law is the distributed stress feedback u_i = G c_i of
:class:`~formation_env.core.network.NetworkLoop` (laws ``stationary`` and ``linear``), run per env copy in
:func:`network_row`: what each agent sends (quantised), the delay buffers, each directed link's delivery
(hold or drop), the input delay, and the zero-order hold of every agent over the sample's period (drawn under
jitter). It replaces the ``law`` part, whose one-step map M assumes the perfect network; without a network it is
not composed at all.

Randomness: copy b's draws come from its own PCG64 generator, ``np.random.default_rng(s_b)``, whose state (4
words: the 128-bit state and increment, high word first) is the state's ``net_rng`` (B, 4) uint64; the step
advances a copy of it (the step stays pure). :func:`pcg64_next` is numpy's PCG64 (the 128-bit LCG with the
XSL-RR output) and :func:`pcg64_double` numpy's ``random()``, so the step draws exactly what
:meth:`~formation_env.core.network.Network.draw` draws on ``np.random.default_rng(s_b)``: at each sample the
period first (``uniform(T_min, T_max)``, jitter only), then one number per link (loss only), a link
delivering iff its number is >= p. The seed s_b is drawn at the reset from the reset's generator, after the
scenario's draws (:func:`network_seeds`), and kept in ``params["_net_seed"]``.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from formation_env.core.dynamics import LinearDynamics
from formation_env.core.network import Network, NetworkLoop

from ._numba import jit

__all__ = [
    "NetworkSetup",
    "network_row",
    "network_seeds",
    "pcg64_double",
    "pcg64_next",
    "pcg64_state",
    "zoh_at",
]

Array = NDArray[np.float64]

#: ZOH of the sample: the nominal (A_d, B_d); integrators without drift (A = 0): (I, T B); general (A, B): the
#: matrix exponential of [[A, B], [0, 0]] T.
ZOH_FIXED, ZOH_NO_DRIFT, ZOH_EXPM = 0, 1, 2
#: Quantisers of what is sent: none, uniform (step delta), logarithmic (density rho).
QUANT_NONE, QUANT_UNIFORM, QUANT_LOG = 0, 1, 2

_M32 = np.uint64(0xFFFFFFFF)
_S32 = np.uint64(32)
_MULT_HI = np.uint64(0x2360ED051FC65DA4)  # PCG_DEFAULT_MULTIPLIER_128, high word
_MULT_LO = np.uint64(0x4385DF649FCCF645)
_ONE = np.uint64(1)
_ZERO = np.uint64(0)


# ---------------------------------------------------------------------------- numpy's PCG64
@jit
def _mul_64(a: np.uint64, b: np.uint64) -> tuple[np.uint64, np.uint64]:  # pragma: no cover
    """The 128-bit product of two 64-bit words: (high, low)."""
    a0, a1, b0, b1 = a & _M32, a >> _S32, b & _M32, b >> _S32
    p00, p01, p10, p11 = a0 * b0, a0 * b1, a1 * b0, a1 * b1
    mid = (p00 >> _S32) + (p01 & _M32) + (p10 & _M32)
    return p11 + (p01 >> _S32) + (p10 >> _S32) + (mid >> _S32), (p00 & _M32) | (mid << _S32)


@jit
def pcg64_next(st: NDArray[np.uint64]) -> np.uint64:  # pragma: no cover
    """numpy's PCG64 ``next_uint64``: state = state * M + inc (mod 2^128), then the XSL-RR output of the new state.
    ``st`` (4,) uint64: state high, state low, increment high, increment low (advanced in place)."""
    sh, sl, ih, il = st[0], st[1], st[2], st[3]
    ph, pl = _mul_64(sl, _MULT_LO)
    hi = ph + sh * _MULT_LO + sl * _MULT_HI
    lo = pl + il
    hi = hi + ih + (_ONE if lo < pl else _ZERO)
    st[0], st[1] = hi, lo
    x = hi ^ lo
    rot = hi >> np.uint64(58)
    return (x >> rot) | (x << ((np.uint64(64) - rot) & np.uint64(63)))


@jit
def pcg64_double(st: NDArray[np.uint64]) -> float:  # pragma: no cover
    """numpy's ``Generator.random()``: (next_uint64 >> 11) 2^-53, in [0, 1)."""
    return float(pcg64_next(st) >> np.uint64(11)) * (1.0 / 9007199254740992.0)


def pcg64_state(seed: int) -> NDArray[np.uint64]:
    """The state (4,) uint64 of ``np.random.default_rng(seed)``'s PCG64 (the words :func:`pcg64_next` reads)."""
    words = np.random.PCG64(seed).state["state"]
    mask = (1 << 64) - 1
    s, inc = int(words["state"]), int(words["inc"])
    return np.array([s >> 64, s & mask, inc >> 64, inc & mask], dtype=np.uint64)


def generator_of(words: NDArray[np.uint64]) -> np.random.Generator:
    """A numpy Generator in the state ``words`` (4,) uint64 (tests and the oracle read the step's draws so)."""
    bg = np.random.PCG64()
    w = [int(v) for v in words]
    bg.state = {
        "bit_generator": "PCG64",
        "state": {"state": (w[0] << 64) | w[1], "inc": (w[2] << 64) | w[3]},
        "has_uint32": 0,
        "uinteger": 0,
    }
    return np.random.Generator(bg)


def words_of(gen: np.random.Generator) -> NDArray[np.uint64]:
    """The state (4,) uint64 of a PCG64 Generator (inverse of :func:`generator_of`)."""
    words = gen.bit_generator.state["state"]
    mask = (1 << 64) - 1
    s, inc = int(words["state"]), int(words["inc"])
    return np.array([s >> 64, s & mask, inc >> 64, inc & mask], dtype=np.uint64)


def network_seeds(rngs: list[np.random.Generator] | np.random.Generator, B: int) -> NDArray[np.int64]:
    """Each copy's network seed s_b (B,): ``rng.integers(0, 2**63, size=B)`` of the reset's generator, or one
    ``integers(0, 2**63, size=1)`` per copy's generator (drawn after the scenario's draws)."""
    if isinstance(rngs, np.random.Generator):
        return rngs.integers(0, 2**63, size=B, dtype=np.int64)
    return np.array([g.integers(0, 2**63, size=1, dtype=np.int64)[0] for g in rngs], dtype=np.int64)


# ---------------------------------------------------------------------------- the sampled dynamics at T
@jit
def _expm(a: Array) -> Array:  # pragma: no cover
    """exp(a) of a small square matrix: scaling and squaring of the degree-16 Taylor polynomial (the scaled
    matrix has 1-norm <= 1/2, so the truncation is below 1e-20 relative)."""
    k = a.shape[0]
    norm = 0.0
    for j in range(k):
        col = 0.0
        for i in range(k):
            col += abs(a[i, j])
        norm = max(norm, col)
    s = 0
    while norm > 0.5:
        norm *= 0.5
        s += 1
    m = a / (2.0**s)
    out = np.eye(k)
    term = np.eye(k)
    for j in range(1, 17):
        term = term @ m / j
        out = out + term
    for _ in range(s):
        out = out @ out
    return out


@jit
def zoh_at(  # pragma: no cover
    T: float, kind: int, zoh_a: Array, zoh_b: Array, dyn_a: Array, dyn_b: Array
) -> tuple[Array, Array]:
    """(A_d(T), B_d(T)) of x' = A x + B u held over T s: ``ZOH_FIXED`` the nominal (zoh_a, zoh_b);
    ``ZOH_NO_DRIFT`` (A = 0) (I, T B); ``ZOH_EXPM`` exp([[A, B], [0, 0]] T) = [[A_d, B_d], [0, I]]."""
    if kind == ZOH_FIXED:
        return zoh_a, zoh_b
    q, p = dyn_b.shape
    if kind == ZOH_NO_DRIFT:
        return np.eye(q), T * dyn_b
    aug = np.zeros((q + p, q + p))
    aug[:q, :q] = dyn_a * T
    aug[:q, q:] = dyn_b * T
    e = _expm(aug)
    return np.ascontiguousarray(e[:q, :q]), np.ascontiguousarray(e[:q, q:])


# ---------------------------------------------------------------------------- the row
@jit
def _quantised(v: float, quant: int, step: float) -> float:  # pragma: no cover
    """What is sent of one state component: core.network's uniform_quantiser / log_quantiser."""
    if quant == QUANT_UNIFORM:
        return step * np.round(v / step)
    if quant == QUANT_LOG:
        if v == 0.0:
            return 0.0
        w = 2.0 * abs(v) / (1.0 + step)
        i = math.floor(np.log(w) / math.log(step)) + 1.0
        return math.copysign(step**i, v)
    return v


@jit
def _delay_line(b: int, line0: Array, line: Array, new: Array) -> Array:  # pragma: no cover
    """A delay line of env b (``line0`` (B, d, ...) before the step, ``line`` after it, newest first): pushes ``new``
    in and returns what leaves, d samples old (``new`` itself when d = 0)."""
    d = line0.shape[1]
    if d == 0:
        return new
    out = line0[b, d - 1].copy()
    for lag in range(d - 1, 0, -1):
        line[b, lag] = line0[b, lag - 1]
    line[b, 0] = new
    return out


@jit
def clip_actions(b: int, act: Array, effort: Array, u_max: float) -> None:  # pragma: no cover
    """Env b's actions clipped to [-1, 1] in place, and each leader's effort |u_max a|^2."""
    for i in range(act.shape[1]):
        e = 0.0
        for j in range(act.shape[2]):
            act[b, i, j] = min(max(act[b, i, j], -1.0), 1.0)
            e += (u_max * act[b, i, j]) ** 2
        effort[b, i] = e


@jit
def kinematics(  # pragma: no cover
    b: int, x: Array, c_t: Array, ca_t: Array, pos0: Array, pos: Array, vel: Array, T: float, k0: Any, k: Any
) -> None:  # fmt: skip
    """Env b's positions C x', velocities (C A x', or the change of position over the period T) and count."""
    n, q, d = x.shape[1], x.shape[2], pos.shape[2]
    for i in range(n):
        for c in range(d):
            acc = 0.0
            for j in range(q):
                acc += x[b, i, j] * c_t[j, c]
            pos[b, i, c] = acc
            if ca_t.shape[0]:
                acc = 0.0
                for j in range(q):
                    acc += x[b, i, j] * ca_t[j, c]
                vel[b, i, c] = acc
            else:
                vel[b, i, c] = (acc - pos0[b, i, c]) / T
    k[b] = k0[b] + 1


@jit
def network_row(  # pragma: no cover
    b: int, act: Array, effort: Array, u_max: float, x0: Array, x: Array, mem0: Array, mem: Array, pos0: Array,
    pos: Array, vel: Array, c_t: Array, ca_t: Array, dt: float, k0: Any, k: Any, leaders: Any, followers: Any,
    net_recv: Any, net_send: Any, net_w: Array, net_row: Any, net_gain: Array, zoh_a: Array, zoh_b: Array,
    dyn_a: Array, dyn_b: Array, zoh_kind: int, loss: float, hold: bool, quant: int, quant_step: float,
    jitter: Array, sent0: Array, sent: Array, corr0: Array, corr: Array, held0: Array, held: Array, rng0: Any,
    rng: Any, lost0: Any, lost: Any, period: Array, time0: Array, time: Array
) -> None:  # fmt: skip
    """Env b's sample over the network (:class:`~formation_env.core.network.NetworkLoop`'s ``step``):

    1. draws (generator ``rng0[b]`` -> ``rng[b]``): the period T = U[T_min, T_max] (jitter; else dt), then
       theta_e = (U[0, 1) >= p) per link (loss);
    2. s_j = q(x_j) sent by every agent; the neighbours' delay: what arrives is s(k - d) (``sent``);
    3. link e = j -> i: hold: xhat_e = s_j if theta_e else the held copy; drop: w_e = theta_e Omega_ij;
       c_i = sum_e w_e (xhat_e - x_i); input delay: c(k - d) is used (``corr``); u_i = G c_i (followers);
    4. every agent: x' = A_d(T) x + B_d(T) u (leaders u = u_max a), positions, velocities, the count; the lost
       link samples are added to ``lost``; under jitter the env time ``time`` advances by T.
    """
    clip_actions(b, act, effort, u_max)
    n, q = x0.shape[1], x0.shape[2]
    p = act.shape[2]
    n_f = followers.shape[0]
    st = rng[b]
    st[:] = rng0[b]
    T = dt
    if jitter.shape[0]:
        T = jitter[0] + (jitter[1] - jitter[0]) * pcg64_double(st)
    period[b] = T
    if time0.shape[0]:  # jitter: the env time advances by the drawn period
        time[b] = time0[b] + T
    s = np.empty((n, q))
    for i in range(n):
        for j in range(q):
            s[i, j] = _quantised(x0[b, i, j], quant, quant_step)
    avail = _delay_line(b, sent0, sent, s)
    c = np.zeros((n_f, q))
    n_lost = 0
    for e in range(net_recv.shape[0]):
        w = net_w[e]
        src = net_send[e]
        recv = net_recv[e]
        row = net_row[e]
        if loss > 0.0:
            ok = pcg64_double(st) >= loss
            if not ok:
                n_lost += 1
            if hold:
                for j in range(q):
                    held[b, e, j] = avail[src, j] if ok else held0[b, e, j]
                for j in range(q):
                    c[row, j] += w * (held[b, e, j] - x0[b, recv, j])
                continue
            if not ok:
                w = 0.0
        for j in range(q):
            c[row, j] += w * (avail[src, j] - x0[b, recv, j])
    lost[b] = lost0[b] + n_lost
    used = _delay_line(b, corr0, corr, c)
    a_d, b_d = zoh_at(T, zoh_kind, zoh_a, zoh_b, dyn_a, dyn_b)
    u = np.empty(p)
    for i in range(n):
        for r in range(q):
            acc = 0.0
            for j in range(q):
                acc += a_d[r, j] * x0[b, i, j]
            x[b, i, r] = acc
    for li in range(leaders.shape[0]):
        for j in range(p):
            u[j] = u_max * act[b, li, j]
        for r in range(q):
            acc = 0.0
            for j in range(p):
                acc += b_d[r, j] * u[j]
            x[b, leaders[li], r] += acc
    for f in range(n_f):
        for j in range(p):
            acc = 0.0
            for cc in range(q):
                acc += net_gain[j, cc] * used[f, cc]
            u[j] = acc
        for r in range(q):
            acc = 0.0
            for j in range(p):
                acc += b_d[r, j] * u[j]
            x[b, followers[f], r] += acc
    for i in range(mem.shape[1]):  # the network laws keep no memory: (B, 0, 0)
        mem[b, i] = mem0[b, i]
    kinematics(b, x, c_t, ca_t, pos0, pos, vel, T, k0, k)


# ---------------------------------------------------------------------------- the engine's side
class NetworkSetup(NamedTuple):
    """What the engine keeps of its network: the loop (links, gain), the constants of the step and the sizes.

    Attributes:
        network: the :class:`~formation_env.core.network.Network`.
        loop: the core's :class:`~formation_env.core.network.NetworkLoop` (its ``initial_state`` is the reset's).
        consts: the step's network constants (``kernel.NetConsts`` fields; :data:`~formation_env.env.kernel.ARRAYS`).
    """

    network: Network
    loop: NetworkLoop
    consts: dict[str, Any]

    @classmethod
    def build(cls, network: Network, law: Any, dyn: LinearDynamics, dt: float) -> NetworkSetup:
        """The setup of ``network`` for the follower ``law`` (``stationary`` or ``linear``: G = eps K)."""
        part = law.part
        G = np.asarray(law.eps * law.K, dtype=np.float64)
        loop = NetworkLoop(part, G, network)
        row_of = np.full(part.n, -1, dtype=np.int64)
        row_of[part.followers] = np.arange(part.n_f)
        a_d, b_d = dyn.zoh(dt)
        if network.jitter is None or dyn.discrete:
            kind = ZOH_FIXED
        elif not np.any(dyn.A):
            kind = ZOH_NO_DRIFT
        else:
            kind = ZOH_EXPM
        quant, step = QUANT_NONE, 0.0
        if network.quantise is not None:
            quant = QUANT_UNIFORM if network.quantise[0] == "uniform" else QUANT_LOG
            step = float(network.quantise[1])
        consts = {
            "followers": np.ascontiguousarray(part.followers, dtype=np.int64),
            "net_recv": np.ascontiguousarray(loop.recv, dtype=np.int64),
            "net_send": np.ascontiguousarray(loop.send_idx, dtype=np.int64),
            "net_w": np.ascontiguousarray(loop.w, dtype=np.float64),
            "net_row": np.ascontiguousarray(row_of[loop.recv]),
            "net_gain": np.ascontiguousarray(G),
            "zoh_a": np.ascontiguousarray(a_d, dtype=np.float64),
            "zoh_b": np.ascontiguousarray(b_d, dtype=np.float64),
            "dyn_a": np.ascontiguousarray(dyn.A, dtype=np.float64),
            "dyn_b": np.ascontiguousarray(dyn.B, dtype=np.float64),
            "zoh_kind": kind,
            "loss": float(network.loss),
            "hold": bool(loop.hold),
            "quant": quant,
            "quant_step": step,
            "jitter": np.array(network.jitter if network.jitter is not None else (), dtype=np.float64),
        }
        return cls(network, loop, consts)

    def initial(self, x: Array, seeds: NDArray[np.int64]) -> dict[str, Any]:
        """The network's state fields at the reset of states x (B, n, q) with seeds (B,): the loop's
        ``initial_state`` per copy (history x(0), everything received at k = 0), each copy's generator, no loss."""
        sts = [self.loop.initial_state(xb) for xb in x]
        return {
            "net_sent": np.ascontiguousarray(np.stack([st.sent for st in sts])),
            "net_corr": np.ascontiguousarray(np.stack([st.corr for st in sts])),
            "net_held": np.ascontiguousarray(np.stack([st.held for st in sts])),
            "net_rng": np.stack([pcg64_state(int(s)) for s in seeds]),
            "net_lost": np.zeros(x.shape[0], dtype=np.int64),
            "net_time": np.zeros(x.shape[0]) if self.network.jitter is not None else None,
        }
