"""Communication networks between the agents: delay, packet loss, sampling jitter and quantisation.

The distributed stress-feedback laws (``stationary``, ``linear``) have follower i apply

    u_i(k) = G c_i(k),   c_i(k) = sum_{j != i} w_ij (xhat_ij(k) - x_i(k)),   G = eps K  (stationary: -g I),

where xhat_ij(k) is what i holds of its neighbour j (leader or follower) at sample k. On a perfect
network xhat_ij(k) = x_j(k), w_ij = Omega_ij and c_i = (Omega x)_i. A :class:`Network` changes that:

* ``delay=d``, ``delayed="neighbours"``: xhat_ij(k) = s_j(k - d) (i's own x_i(k) is current);
  ``delayed="input"``: u_i(k) = G c_i(k - d), the whole correction computed d samples ago.
  Before k = 0 every agent is taken to have sat at x(0) (the history is x(0)).
* ``loss=p``: every directed link j -> i delivers each sample independently with probability 1 - p.
  ``loss_model="hold"``: xhat_ij keeps the last value received (initially the value at k = 0, as if
  everything had been received then); ``"drop"``: w_ij = theta_ij(k) Omega_ij, the lost term is left out.
* ``jitter=(T_min, T_max)``: sample k lasts T_k ~ U[T_min, T_max]; every agent's zero-order hold uses T_k
  (A_d(T_k), B_d(T_k)). The law's gain is the one designed for the nominal ``dt``.
* ``quantise=("uniform", delta)``: what is sent is s_j = delta round(x_j / delta) per component;
  ``("log", rho)``: the logarithmic quantiser with levels +-rho^i (Fu & Xie 2005), |s - x| <= delta_rho |x|,
  delta_rho = (1 - rho) / (1 + rho). Unquantised: s_j = x_j.

Random draws (:meth:`Network.draw`) at every sample k = 0, 1, ..., in this order: first the period
T_k = rng.uniform(T_min, T_max) (only with jitter), then ``rng.random(n_links)``, link e delivering iff its
draw is >= p (only with loss > 0), links in the order of :func:`network_links`. A compiled step that makes
the same calls on the same generator reproduces the same samples.

The analysis (:func:`network_analysis`, used by ``stability_report(..., network=)``) writes the loop in
error coordinates on an augmented state z = [e(k), sent history, correction history, held copies],
obtained column by column from the same :class:`NetworkLoop` step that ``simulate`` runs (the step is
linear in the state and affine in each link's delivery theta_e), so the analysed matrices are the
simulated loop's.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from .dynamics import LinearDynamics, c2d_zoh
from .errors import FormationError
from .stress import Partition
from .validation import _describe, as_array, check_int, check_mapping, check_real_scalar

__all__ = [
    "DELAYED",
    "LOSS_MODELS",
    "MAX_MS_STATES",
    "MAX_STATES",
    "NETWORK_LAWS",
    "QUANTISERS",
    "Network",
    "NetworkLoop",
    "levin_may_bound",
    "log_quantiser",
    "network_links",
    "uniform_quantiser",
]

Array = NDArray[np.float64]

DELAYED = ("neighbours", "input")
LOSS_MODELS = ("hold", "drop")
QUANTISERS = ("uniform", "log")
#: Laws a network model applies to: the distributed stress feedback u_f = eps K (Omega x)_f.
NETWORK_LAWS = ("stationary", "linear")
#: Largest augmented state (per analysed coordinate) for the mean-square analysis: E[A kron A] is its square.
MAX_MS_STATES = 40
#: Largest augmented state (per analysed coordinate) for the deterministic analysis (dense eigenvalues).
MAX_STATES = 2000

_WHY_NOT = {
    "dynamic": (
        "the dynamic law solves Omega_ff u_f = (Omega x)_f K' - Omega_fl u_l over the whole network at every "
        "sample (a centralised solve that needs every follower's next input at once), so a link-by-link "
        "delay, loss or quantisation model does not define it"
    ),
    "dynamic_distributed": (
        "dynamic_distributed exchanges inputs over m Jacobi rounds inside each sample; a per-sample link model "
        "(delays in samples, one loss draw per sample) does not say what happens between the rounds"
    ),
    "linear_paper": (
        "linear_paper is the paper's literal eq. 25, which does not hold the formation even on a perfect "
        "network (there is no formation error to keep); use law='linear'"
    ),
}


def check_network_law(law: str) -> None:
    """Raise ``FormationError`` saying why a network model does not apply to ``law``."""
    if law not in NETWORK_LAWS:
        why = _WHY_NOT.get(law, f"unknown law {law!r}")
        raise FormationError(
            f"network= is defined for the distributed stress-feedback laws {', '.join(NETWORK_LAWS)}; "
            f"not for law {law!r}: {why}"
        )


def levin_may_bound(delay: int) -> float:
    """Levin and May (1976): x(k+1) = x(k) - a x(k - d) is stable iff 0 < a < 2 sin(pi / (2 (2d + 1)))."""
    d = check_int(delay, "delay", low=0)
    return 2.0 * math.sin(math.pi / (2.0 * (2 * d + 1)))


def uniform_quantiser(x: Array, delta: float) -> Array:
    """Uniform (mid-tread) quantiser delta round(x / delta), componentwise; |q(x) - x| <= delta / 2."""
    return np.asarray(delta * np.round(x / delta), dtype=np.float64)


def log_quantiser(x: Array, rho: float) -> Array:
    """Logarithmic quantiser with levels +-rho^i (i integer) and 0 (Elia & Mitter 2001, Fu & Xie 2005).

    q(v) = rho^i for rho^i / (1 + delta) < v <= rho^i / (1 - delta), delta = (1 - rho) / (1 + rho);
    q(-v) = -q(v), q(0) = 0. So |q(v) - v| <= delta |v| (the sector bound).
    """
    x = np.asarray(x, dtype=np.float64)
    out = np.zeros_like(x)
    nz = x != 0
    w = 2.0 * np.abs(x[nz]) / (1.0 + rho)
    i = np.floor(np.log(w) / math.log(rho)) + 1.0
    out[nz] = np.sign(x[nz]) * rho**i
    return out


@dataclass(frozen=True)
class Network:
    """A communication network between the agents (see the module docstring for the models).

    Attributes:
        delay: d, samples (integer >= 0), uniform over the links.
        delayed: ``"neighbours"`` (the neighbours' values are d samples old) or ``"input"`` (the whole
            correction is d samples old: computation or actuation delay).
        loss: p in [0, 1), the probability that a directed link j -> i loses a sample.
        loss_model: ``"hold"`` (use the last value received) or ``"drop"`` (leave the term out).
        jitter: None or (T_min, T_max) (s), 0 < T_min <= T_max: each period drawn uniformly from it.
        quantise: None, ``("uniform", delta)`` (delta > 0, the state's unit) or ``("log", rho)`` (0 < rho < 1).
    """

    delay: int = 0
    delayed: str = "neighbours"
    loss: float = 0.0
    loss_model: str = "hold"
    jitter: tuple[float, float] | None = None
    quantise: tuple[str, float] | None = None

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        set_(self, "delay", check_int(self.delay, "delay", low=0, what="a non-negative integer number of samples"))
        for name, val, allowed in (
            ("delayed", self.delayed, DELAYED),
            ("loss_model", self.loss_model, LOSS_MODELS),
        ):
            if not isinstance(val, str) or val not in allowed:
                raise FormationError(f"{name} must be one of {', '.join(map(repr, allowed))}, got {_describe(val)}")
        set_(
            self,
            "loss",
            check_real_scalar(self.loss, "loss", low=0.0, low_open=False, high=1.0, what="a probability in [0, 1)"),
        )
        if self.jitter is not None:
            jit = self.jitter
            if isinstance(jit, str | bytes) or not hasattr(jit, "__len__") or len(jit) != 2:
                raise TypeError(f"jitter must be None or a pair (T_min, T_max) in seconds, got {_describe(jit)}")
            lo = check_real_scalar(jit[0], "jitter[0]", low=0.0, what="a positive period T_min in seconds")
            hi = check_real_scalar(jit[1], "jitter[1]", low=0.0, what="a positive period T_max in seconds")
            if hi < lo:
                raise FormationError(f"jitter must be (T_min, T_max) with T_min <= T_max, got ({lo:g}, {hi:g})")
            set_(self, "jitter", (lo, hi))
        if self.quantise is not None:
            qz = self.quantise
            if isinstance(qz, str | bytes) or not hasattr(qz, "__len__") or len(qz) != 2:
                raise TypeError(f"quantise must be None, ('uniform', delta) or ('log', rho), got {_describe(qz)}")
            kind = qz[0]
            if not isinstance(kind, str) or kind not in QUANTISERS:
                raise FormationError(f"quantise[0] must be 'uniform' or 'log', got {_describe(kind)}")
            if kind == "uniform":
                qval = check_real_scalar(qz[1], "quantise[1]", low=0.0, what="a positive quantisation step delta")
            else:
                qval = check_real_scalar(
                    qz[1], "quantise[1]", low=0.0, high=1.0, what="a logarithmic density rho in (0, 1)"
                )
            set_(self, "quantise", (kind, qval))

    # ------------------------------------------------------------------ forms
    def as_dict(self) -> dict[str, Any]:
        """JSON-ready dict; :meth:`from_dict` gives the same network back."""
        return {
            "delay": self.delay,
            "delayed": self.delayed,
            "loss": self.loss,
            "loss_model": self.loss_model,
            "jitter": None if self.jitter is None else list(self.jitter),
            "quantise": None if self.quantise is None else list(self.quantise),
        }

    @classmethod
    def from_dict(cls, data: Any) -> Network:
        """A network from a dict of its fields (missing ones take their defaults; unknown keys are refused)."""
        if data is None:
            raise TypeError("network dict must be a dict of Network fields, got None")
        d = dict(check_mapping(data, "network"))
        unknown = set(d) - set(cls.__dataclass_fields__)
        if unknown:
            raise TypeError(
                f"network got unknown key(s) {', '.join(sorted(unknown))}; known: {', '.join(cls.__dataclass_fields__)}"
            )
        for key in ("jitter", "quantise"):
            if isinstance(d.get(key), list):
                d[key] = tuple(d[key])
        return cls(**d)

    # ------------------------------------------------------------------ properties
    @property
    def random(self) -> bool:
        """True when samples draw random numbers (loss > 0 or jitter)."""
        return self.loss > 0 or self.jitter is not None

    @property
    def ideal(self) -> bool:
        """True for the perfect network (no delay, loss, jitter or quantisation)."""
        return self.delay == 0 and not self.random and self.quantise is None

    @property
    def sector(self) -> float | None:
        """delta = (1 - rho) / (1 + rho) of a logarithmic quantiser (None otherwise)."""
        if self.quantise is None or self.quantise[0] != "log":
            return None
        rho = self.quantise[1]
        return (1.0 - rho) / (1.0 + rho)

    def send(self, x: Array) -> Array:
        """What an agent transmits of its state x (quantised if ``quantise``), same shape."""
        if self.quantise is None:
            return x
        kind, val = self.quantise
        return uniform_quantiser(x, val) if kind == "uniform" else log_quantiser(x, val)

    def draw(self, rng: np.random.Generator, dt: float, n_links: int) -> tuple[float, NDArray[np.bool_]]:
        """One sample's random draws, in the documented order.

        Args:
            rng: the generator (``np.random.default_rng(seed)``).
            dt: the nominal period (s), returned when there is no jitter.
            n_links: number of directed links (:func:`network_links`).
        Returns:
            (T_k in s, delivered (n_links,) bool). First ``rng.uniform(T_min, T_max)`` if jitter, then
            ``rng.random(n_links) >= loss`` if loss > 0; nothing is drawn for a model that is off.
        """
        period = float(rng.uniform(self.jitter[0], self.jitter[1])) if self.jitter is not None else float(dt)
        if self.loss > 0:
            delivered = rng.random(n_links) >= self.loss
        else:
            delivered = np.ones(n_links, dtype=bool)
        return period, delivered


def check_network(network: Any) -> Network | None:
    """None, a :class:`Network`, or a dict of its fields (-> Network)."""
    if network is None or isinstance(network, Network):
        return network
    if isinstance(network, dict):
        return Network.from_dict(network)
    raise TypeError(f"network must be None, a Network or a dict of its fields, got {_describe(network)}")


def network_links(part: Partition) -> tuple[NDArray[np.int64], NDArray[np.int64], Array]:
    """The directed links j -> i into the followers: (receivers, senders, weights Omega_ij), each (m,).

    Receivers and senders are agent indices; the links are ordered by receiver (in ``part.followers``
    order), then by sender index. A link exists where Omega_ij != 0, j != i (leaders send too).
    """
    rows = sp.csr_matrix(part.omega)[part.followers] if part.sparse else sp.csr_matrix(part.omega[part.followers])
    rows.sort_indices()
    coo = rows.tocoo()
    recv = part.followers[coo.row]
    keep = (coo.col != recv) & (coo.data != 0)
    order = np.lexsort((coo.col[keep], coo.row[keep]))
    return (
        recv[keep][order].astype(np.int64),
        coo.col[keep][order].astype(np.int64),
        coo.data[keep][order].astype(np.float64),
    )


class NetState(NamedTuple):
    """The loop's state at sample k (before the step).

    x: agent states (n, q). sent: the values sent at k-1, ..., k-d, (d, n, q) (neighbours delay, else (0, n, q)).
    corr: the corrections c(k-1), ..., c(k-d), (d, n_f, q) (input delay, else (0, n_f, q)).
    held: the value each link holds, (m, q) (hold model, else (0, q)).
    """

    x: Array
    sent: Array
    corr: Array
    held: Array


class NetworkLoop:
    """The stress feedback u_i = G c_i over a :class:`Network`: one step, used by ``simulate`` and the analysis.

    Args:
        part: leader/follower partition of the stress.
        G: the feedback gain, shape (p, q): eps K (``stationary``: -g I).
        network: the network.
        sender: optional replacement of ``network.send`` (the analysis injects quantisation errors with it).
    """

    def __init__(
        self,
        part: Partition,
        G: Array,
        network: Network,
        sender: Callable[[Array], Array] | None = None,
    ) -> None:
        self.part = part
        self.G = np.asarray(G, dtype=np.float64)
        self.net = network
        self.recv, self.send_idx, self.w = network_links(part)
        self.m = int(self.recv.size)
        row_of = np.full(part.n, -1, dtype=np.int64)
        row_of[part.followers] = np.arange(part.n_f)
        self.recv_row = row_of[self.recv]
        # S (n_f, m): sums the link terms into their receiver's correction (dense while small).
        S = sp.csr_matrix((np.ones(self.m), (self.recv_row, np.arange(self.m))), shape=(part.n_f, self.m))
        self.S: Any = S.toarray() if part.n_f * self.m <= 250_000 else S
        self.sender = sender if sender is not None else network.send
        self.d_n = network.delay if network.delayed == "neighbours" else 0
        self.d_i = network.delay if network.delayed == "input" else 0
        self.hold = network.loss > 0 and network.loss_model == "hold"

    def initial_state(self, x0: Array) -> NetState:
        """The state at k = 0: history x(0), everything received at k = 0."""
        s0 = self.sender(x0)
        q = x0.shape[-1]
        sent = np.repeat(s0[None], self.d_n, axis=0)
        c0 = self._correction(x0, s0[self.send_idx], self.w)
        corr = np.repeat(c0[None], self.d_i, axis=0)
        held = s0[self.send_idx].copy() if self.hold else np.zeros((0, q))
        return NetState(x0.copy(), sent, corr, held)

    def _correction(self, x: Array, vals: Array, w: Array) -> Array:
        xi = x[self.recv]
        return np.asarray(self.S @ (w[:, None] * (vals - xi)))

    def control(self, st: NetState, delivered: NDArray[np.bool_]) -> tuple[Array, NetState]:
        """Follower inputs u_f (n_f, p) at this sample and the state with updated buffers (x unchanged)."""
        s = self.sender(st.x)
        if self.d_n:
            avail = st.sent[-1]
            sent = np.concatenate([s[None], st.sent[:-1]], axis=0)
        else:
            avail, sent = s, st.sent
        vals = avail[self.send_idx]
        w = self.w
        held = st.held
        if self.net.loss > 0:
            if self.hold:
                held = np.where(delivered[:, None], vals, st.held)
                vals = held
            else:
                w = w * delivered
        c = self._correction(st.x, vals, w)
        if self.d_i:
            c_used = st.corr[-1]
            corr = np.concatenate([c[None], st.corr[:-1]], axis=0)
        else:
            c_used, corr = c, st.corr
        return c_used @ self.G.T, NetState(st.x, sent, corr, held)

    def step(
        self, st: NetState, delivered: NDArray[np.bool_], A_d: Array, B_d: Array, u_leaders: Array
    ) -> tuple[NetState, Array]:
        """One sample: (state at k + 1, follower inputs u_f (n_f, p)). Leaders move by u_leaders (n_l, p)."""
        u_f, st = self.control(st, delivered)
        x = st.x @ A_d.T
        part = self.part
        x[part.followers] += u_f @ B_d.T
        x[part.leaders] += u_leaders @ B_d.T
        return NetState(x, st.sent, st.corr, st.held), u_f

    # ------------------------------------------------------------------ linear algebra of the loop
    def size(self, q: int) -> int:
        """Dimension of the augmented error state for per-agent state size q."""
        nf = self.part.n_f
        return q * (nf * (1 + self.d_n + self.d_i) + (self._held_follower_links().size if self.hold else 0))

    def _held_follower_links(self) -> NDArray[np.int64]:
        is_f = np.zeros(self.part.n, dtype=bool)
        is_f[self.part.followers] = True
        return np.flatnonzero(is_f[self.send_idx])

    def pack(self, st: NetState) -> Array:
        """Error-coordinate state as a vector (followers' parts only; leaders sit at 0)."""
        f = self.part.followers
        parts = [st.x[f].ravel(), st.sent[:, f].ravel(), st.corr.ravel()]
        if self.hold:
            parts.append(st.held[self._held_follower_links()].ravel())
        return np.concatenate(parts)

    def unpack(self, z: Array, q: int) -> NetState:
        part, nf = self.part, self.part.n_f
        x = np.zeros((part.n, q))
        i = nf * q
        x[part.followers] = z[:i].reshape(nf, q)
        sent = np.zeros((self.d_n, part.n, q))
        j = i + self.d_n * nf * q
        sent[:, part.followers] = z[i:j].reshape(self.d_n, nf, q)
        k = j + self.d_i * nf * q
        corr = z[j:k].reshape(self.d_i, nf, q)
        held = np.zeros((self.m if self.hold else 0, q))
        if self.hold:
            held[self._held_follower_links()] = z[k:].reshape(-1, q)
        return NetState(x, sent, corr, held)

    def matrix(self, delivered: NDArray[np.bool_], A_d: Array, B_d: Array) -> Array:
        """The one-step matrix of the augmented error state for one delivery pattern, (s, s)."""
        q = A_d.shape[0]
        s = self.size(q)
        out = np.empty((s, s))
        zero_u = np.zeros((self.part.n_l, B_d.shape[1]))
        for col in range(s):
            z = np.zeros(s)
            z[col] = 1.0
            nxt, _ = self.step(self.unpack(z, q), delivered, A_d, B_d, zero_u)
            out[:, col] = self.pack(nxt)
        return out

    def link_matrices(self, A_d: Array, B_d: Array) -> tuple[Array, list[Array]]:
        """A(theta) = A_0 + sum_e theta_e A_e: returns (A_0, [A_e for links whose A_e != 0])."""
        a0 = self.matrix(np.zeros(self.m, dtype=bool), A_d, B_d)
        if self.net.loss == 0:
            return self.matrix(np.ones(self.m, dtype=bool), A_d, B_d), []
        mats = []
        for e in range(self.m):
            one = np.zeros(self.m, dtype=bool)
            one[e] = True
            ae = self.matrix(one, A_d, B_d) - a0
            if np.any(ae):
                mats.append(ae)
        return a0, mats

    def link_forcing(self, x_abs: Array, A_d: Array, B_d: Array) -> list[Array]:
        """Drop model: b_e, the error-state forcing of link e alone delivering at the formation x_abs (n, q).

        The loop in error coordinates is z(k+1) = A(theta) z(k) + sum_e theta_e b_e; all links delivering
        gives sum_e b_e = 0 (the formation is an equilibrium).
        """
        st0 = self.initial_state(x_abs)
        ref = self.pack(st0)
        zero_u = np.zeros((self.part.n_l, B_d.shape[1]))
        out = []
        for e in range(self.m):
            one = np.zeros(self.m, dtype=bool)
            one[e] = True
            nxt, _ = self.step(st0, one, A_d, B_d, zero_u)
            out.append(self.pack(nxt) - ref)
        return out


def as_leader_positions(x_leaders: Any, n_l: int) -> Array:
    """Leader positions (n_l, d) as an array (checked)."""
    arr = as_array(x_leaders, "x_leaders", ndim=2)
    if arr.shape[0] != n_l:
        raise FormationError(f"x_leaders must have one row per leader ({n_l}), got shape {arr.shape}")
    return arr


def zoh_of(dyn: LinearDynamics) -> Callable[[float], tuple[Array, Array]]:
    """T -> (A_d(T), B_d(T)) (the given matrices for a discrete model)."""
    if dyn.discrete:
        return lambda t: (dyn.A, dyn.B)
    return lambda t: c2d_zoh(dyn.A, dyn.B, t)


# ---------------------------------------------------------------------------------------------- analysis
class LoopModel(NamedTuple):
    """What the analysis needs of a law on a network: the partition, analysed dynamics, gain and network.

    ``coords`` is the number of identical decoupled copies analysed once (d for single integrators with
    G a multiple of I, whose coordinates decouple; 1 otherwise, the full state analysed).
    """

    part: Partition
    dyn: LinearDynamics
    G: Array
    network: Network
    coords: int


def loop_model(part: Partition, dyn: LinearDynamics, G: Array, network: Network) -> LoopModel:
    """Reduce to one coordinate where the coordinates decouple (single integrators, G = c I)."""
    G = np.asarray(G, dtype=np.float64)
    if dyn.is_single_integrator and np.allclose(G, G[0, 0] * np.eye(G.shape[0]), rtol=0, atol=1e-14 * abs(G[0, 0])):
        return LoopModel(part, LinearDynamics.single_integrator(1), G[:1, :1].copy(), network, dyn.d)
    return LoopModel(part, dyn, G, network, 1)


def _gauss_nodes(network: Network, dt: float, single: bool) -> list[tuple[float, float]]:
    """(T, weight) pairs for E over the period: Gauss-Legendre on [T_min, T_max] (or just dt)."""
    if network.jitter is None:
        return [(dt, 1.0)]
    lo, hi = network.jitter
    if hi == lo:
        return [(lo, 1.0)]
    x, w = np.polynomial.legendre.leggauss(3 if single else 12)  # A(T) affine in T for single integrators
    return [(float(0.5 * (hi - lo) * xi + 0.5 * (hi + lo)), float(0.5 * wi)) for xi, wi in zip(x, w, strict=True)]


def _check_size(s: int, limit: int, what: str) -> None:
    if s > limit:
        raise FormationError(
            f"the {what} needs an augmented state of {s} per coordinate (followers x (1 + delay) + held link "
            f"copies), above the supported {limit}; analyse a smaller framework or a shorter delay"
        )


def deterministic_matrix(model: LoopModel, dt: float) -> Array:
    """The one-step matrix of the augmented error state (no loss, no jitter), (s, s)."""
    loop = NetworkLoop(model.part, model.G, model.network)
    s = loop.size(model.dyn.q)
    _check_size(s, MAX_STATES, "delay analysis")
    a_d, b_d = zoh_of(model.dyn)(dt)
    return loop.matrix(np.ones(loop.m, dtype=bool), a_d, b_d)


def second_moment_operator(model: LoopModel, dt: float) -> tuple[Array, list[tuple[float, Array, list[Array]]]]:
    """E[A kron A] over the losses (and periods), and per period node (weight, Abar, [A_e]), (s^2, s^2)."""
    net = model.network
    loop = NetworkLoop(model.part, model.G, net)
    s = loop.size(model.dyn.q)
    _check_size(s, MAX_MS_STATES, "mean-square analysis (E[A kron A] has the square of its size)")
    p = net.loss
    zoh = zoh_of(model.dyn)
    out = np.zeros((s * s, s * s))
    nodes = []
    for t, wt in _gauss_nodes(net, dt, model.dyn.is_single_integrator):
        a_d, b_d = zoh(t)
        a0, mats = loop.link_matrices(a_d, b_d)
        abar = a0 + (1 - p) * sum(mats, np.zeros_like(a0)) if p > 0 else a0
        out += wt * np.kron(abar, abar)
        for ae in mats:
            out += wt * p * (1 - p) * np.kron(ae, ae)
        nodes.append((wt, abar, mats))
    return out, nodes


def radius(mat: Array) -> float:
    """Spectral radius of a square matrix."""
    return float(np.max(np.abs(np.linalg.eigvals(mat)))) if mat.size else 0.0


def network_radius(model: LoopModel, dt: float) -> float:
    """Per-sample decay factor: rho(A) (deterministic loop) or sqrt(rho(E[A kron A])) (RMS, random loop)."""
    net = model.network
    if not net.random:
        return radius(deterministic_matrix(model, dt))
    commuting = net.loss == 0 and net.delay == 0 and model.dyn.is_single_integrator and model.dyn.q == 1
    if commuting:  # modes 1 + T G lambda_i: E[(1 + T G lambda)^2] from the moments of T
        lo, hi = net.jitter if net.jitter is not None else (dt, dt)
        m1, m2 = 0.5 * (lo + hi), (lo * lo + lo * hi + hi * hi) / 3.0
        lam = np.linalg.eigvalsh(model.part.omega_ff_dense)
        g = float(model.G[0, 0])
        return float(np.sqrt(np.max(1.0 + 2.0 * g * lam * m1 + (g * lam) ** 2 * m2)))
    eaa, _ = second_moment_operator(model, dt)
    return math.sqrt(radius(eaa))


def jitter_robust(model: LoopModel, dt: float) -> tuple[bool, bool, str]:
    """Stability for every sequence of periods in [T_min, T_max]: (stable, exact, how)."""
    net = model.network
    lo, hi = net.jitter if net.jitter is not None else (dt, dt)
    if net.delay == 0 and net.loss == 0 and model.dyn.is_single_integrator and model.dyn.q == 1:
        lam = np.linalg.eigvalsh(model.part.omega_ff_dense)
        g = float(model.G[0, 0])
        worst = max(float(np.max(np.abs(1.0 + t * g * lam))) for t in (lo, hi))
        return (
            worst < 1.0,
            True,
            "the one-step matrices I + T G Omega_ff commute: stable for every period sequence iff "
            f"max_i |1 + T G lambda_i| < 1 at T_min and T_max (= T_max g lambda_max < 2); worst {worst:.6g}",
        )
    loop = NetworkLoop(model.part, model.G, net)
    s = loop.size(model.dyn.q)
    _check_size(s, MAX_STATES, "jitter analysis")
    zoh = zoh_of(model.dyn)
    single = model.dyn.is_single_integrator
    grid = [lo, hi] if single else list(np.linspace(lo, hi, 21))
    mats = [loop.matrix(np.ones(loop.m, dtype=bool), *zoh(float(t))) for t in grid]
    if any(radius(m) >= 1.0 for m in mats):
        return False, True, "some fixed period in the interval is unstable (necessary condition fails)"
    where = (
        "at T_min and T_max (A(T) is affine in T, so the LMI there covers the interval)"
        if single
        else f"on {len(grid)} periods spanning the interval (a grid: between its points it is not proven)"
    )
    try:
        ok, how = _cqlf_lmi(mats)
    except ImportError:
        ok, how = _cqlf_lyapunov(mats, zoh, loop, 0.5 * (lo + hi))
    return ok, False, f"common quadratic Lyapunov function {how} {where}; sufficient, not necessary"


def _cqlf_lmi(mats: list[Array]) -> tuple[bool, str]:
    import cvxpy as cp  # the design extra

    s = mats[0].shape[0]
    P = cp.Variable((s, s), symmetric=True)
    cons = [P >> np.eye(s)]
    cons += [a.T @ P @ a - P << -1e-6 * np.eye(s) for a in mats]
    prob = cp.Problem(cp.Minimize(0), cons)
    try:
        prob.solve()
    except cp.error.SolverError:
        return False, "(LMI, cvxpy: solver failed)"
    if prob.status not in ("optimal", "optimal_inaccurate") or P.value is None:
        return False, f"(LMI, cvxpy: {prob.status})"
    pv = 0.5 * (P.value + P.value.T)
    ok = (
        all(float(np.max(np.linalg.eigvalsh(a.T @ pv @ a - pv))) < 0 for a in mats)
        and float(np.min(np.linalg.eigvalsh(pv))) > 0
    )
    return ok, "(LMI, cvxpy; solution re-checked)" if ok else "(LMI, cvxpy: solution failed the re-check)"


def _cqlf_lyapunov(mats: list[Array], zoh: Any, loop: NetworkLoop, t_mid: float) -> tuple[bool, str]:
    import scipy.linalg as sla

    a_mid = loop.matrix(np.ones(loop.m, dtype=bool), *zoh(t_mid))
    pv = sla.solve_discrete_lyapunov(a_mid.T, np.eye(a_mid.shape[0]))
    ok = all(float(np.max(np.linalg.eigvalsh(a.T @ pv @ a - pv))) < 0 for a in mats)
    return ok, "(the Lyapunov P of the mid period, checked; install the design extra for the LMI)"


def drop_steady_error(model: LoopModel, dt: float, x_abs: Array) -> float:
    """Drop model: the stationary RMS of the formation error sqrt(E ||x_f - x_f*||^2) (exact, 0-mean).

    z(k+1) = A(theta) z + sum_e theta_e b_e with sum_e b_e = 0, so E[z] -> 0 and the second moment
    S solves vec(S) = E[A kron A] vec(S) + p (1 - p) sum_e vec(b_e b_e').

    Args:
        x_abs: the formation, (n, q * coords) states (leaders and follower targets).
    """
    net = model.network
    loop = NetworkLoop(model.part, model.G, net)
    eaa, nodes = second_moment_operator(model, dt)
    s = loop.size(model.dyn.q)
    if radius(eaa) >= 1.0:
        return math.inf
    zoh = zoh_of(model.dyn)
    q = model.dyn.q
    n_e = model.part.n_f * q
    p = net.loss
    total = 0.0
    for c in range(model.coords):
        xc = x_abs[:, c * q : (c + 1) * q] if model.coords > 1 else x_abs
        rhs = np.zeros(s * s)
        for (t, _), (wt, _, _) in zip(_gauss_nodes(net, dt, model.dyn.is_single_integrator), nodes, strict=True):
            for b in loop.link_forcing(xc, *zoh(t)):
                rhs += wt * p * (1 - p) * np.kron(b, b)
        vs = np.linalg.solve(np.eye(s * s) - eaa, rhs).reshape(s, s)
        total += float(np.trace(vs[:n_e, :n_e]))
    return math.sqrt(max(total, 0.0))


def _adder(noise: Array) -> Callable[[Array], Array]:
    return lambda x: x + noise


def quantisation_gain(model: LoopModel, dt: float) -> float:
    """N = sum_k ||C A^k E||_inf: the l-inf gain from the quantisation errors of what is sent to the
    formation error (every component of every follower). limsup max |e| <= N max |q(x) - x|."""
    net = model.network
    a = deterministic_matrix(model, dt)
    if radius(a) >= 1.0:
        return math.inf
    q = model.dyn.q
    part = model.part
    a_d, b_d = zoh_of(model.dyn)(dt)
    # E: the augmented state's response to a unit error in what agent j sends (component c).
    cols = []
    for j in range(part.n):
        for c in range(q):
            noise = np.zeros((part.n, q))
            noise[j, c] = 1.0
            loop = NetworkLoop(part, model.G, Network(delay=net.delay, delayed=net.delayed), sender=_adder(noise))
            st = NetState(
                np.zeros((part.n, q)),
                np.zeros((loop.d_n, part.n, q)),
                np.zeros((loop.d_i, part.n_f, q)),
                np.zeros((0, q)),
            )
            nxt, _ = loop.step(st, np.ones(loop.m, dtype=bool), a_d, b_d, np.zeros((part.n_l, b_d.shape[1])))
            cols.append(loop.pack(nxt))
    e_mat = np.stack(cols, axis=1)
    n_e = part.n_f * q
    total, term = 0.0, e_mat
    for k in range(200000):
        row = float(np.max(np.sum(np.abs(term[:n_e]), axis=1)))
        total += row
        if k > 10 and row < 1e-12 * total:
            break
        term = a @ term
    return total
