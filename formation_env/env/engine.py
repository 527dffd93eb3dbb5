"""The batched formation engine: a pure ``step(state, actions)`` over a leading batch dim B.

Every array in :class:`EngineState` starts with the batch dim B (VMAS style), so the
PettingZoo env (B = 1) and a vectorised env (B = 1024) share one step function. The
engine holds only constants; the state is passed in and a new state is returned
(gymnax style). Randomness comes only from the ``np.random.Generator`` given to
:meth:`Engine.reset`.

Speed: the followers' analytic law, the leaders' sampled dynamics, positions,
velocities, the affine-image residual and every observation entry that is linear in
the state are folded at construction into one matrix, so a step is one matmul plus
the nonlinear parts (norms, obstacle geometry, clipping). The matrix is read off the
core law by probing ``FollowerLaw.step`` with unit vectors (every law is linear in
x, u_l and its memory) and is cached per configuration.

Large swarms: the folded matrix grows as n^2, so frameworks of more than ``MAX_AGENTS``
agents take the sparse path of :mod:`formation_env.env.swarm` instead (a sparse stress
end to end, the core law stepped directly, O(n + edges) per step), with the same
observations, rewards and state.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray

from formation_env.core.affine import AffineImage
from formation_env.core.dynamics import LinearDynamics
from formation_env.core.errors import ControlDimension, FormationError, StabilityWarning
from formation_env.core.framework import Framework
from formation_env.core.laws import FollowerLaw, make_law
from formation_env.core.stress import Partition, check_stress

from . import _kernel, geometry
from .scenarios import CLASSES, NAMED_FRAMEWORKS, REGISTRY
from .scenarios._base import Scenario, affine_batch, gram_stress

__all__ = [
    "DYNAMICS",
    "FOLLOWER_LAWS",
    "Engine",
    "EngineState",
    "StepInfo",
    "check_combination",
    "offered_combinations",
    "resolve_dynamics",
    "resolve_framework",
]

Array = NDArray[np.float64]

#: Follower laws the env offers (``linear_paper`` is left out: its followers do not track, see core.laws).
FOLLOWER_LAWS: tuple[str, ...] = ("stationary", "dynamic", "dynamic_distributed", "linear")
#: Named dynamics (a ``LinearDynamics`` is accepted too).
DYNAMICS: tuple[str, ...] = ("single_integrator", "double_integrator")
#: Reward term names (see ``FormationEnv``'s Rewards section).
REWARD_TERMS: tuple[str, ...] = ("progress", "distance", "formation", "collision", "effort", "success")
#: Largest framework of the folded (dense) step, whose matrices grow as n^2; larger ones take the
#: sparse path of :mod:`formation_env.env.swarm` (read at construction, so tests may lower it).
MAX_AGENTS = 256
#: Above this many agents, agent-agent contacts are checked along the graph's edges only.
ALL_PAIRS_UP_TO = 64


# ---------------------------------------------------------------------------- configuration
def resolve_dynamics(dynamics: str | LinearDynamics, d: int) -> LinearDynamics:
    """``"single_integrator"`` | ``"double_integrator"`` in R^d, or a ``LinearDynamics`` with position dim d."""
    if isinstance(dynamics, LinearDynamics):
        if dynamics.d != d:
            raise ControlDimension(f"dynamics has position dimension {dynamics.d}, the framework is in R^{d}")
        return dynamics
    if dynamics == "single_integrator":
        return LinearDynamics.single_integrator(d)
    if dynamics == "double_integrator":
        return LinearDynamics.double_integrator(d)
    raise FormationError(f"unknown dynamics {dynamics!r}; choose one of {list(DYNAMICS)} or pass a LinearDynamics")


def check_combination(follower_law: str, dynamics: LinearDynamics) -> None:
    """Refuse law/dynamics pairs the env does not offer, with the reason.

    ``stationary`` (eq. 17) is for single integrators only; ``linear_paper`` is not offered.
    """
    if follower_law not in FOLLOWER_LAWS:
        extra = " (linear_paper is the paper's literal eq. 25, whose followers do not track)" * (
            follower_law == "linear_paper"
        )
        raise FormationError(f"unknown follower_law {follower_law!r}{extra}; choose one of {list(FOLLOWER_LAWS)}")
    if follower_law == "stationary" and not dynamics.is_single_integrator:
        raise FormationError(
            f"follower_law='stationary' (eq. 17) needs single_integrator dynamics, got {dynamics.name}; "
            "use 'dynamic', 'dynamic_distributed' or 'linear'"
        )


def offered_combinations() -> list[tuple[str, str, str]]:
    """Every (scenario, dynamics, follower_law) the env offers, for parametrised tests."""
    return [
        (s, dyn, law)
        for s in REGISTRY
        for dyn in DYNAMICS
        for law in FOLLOWER_LAWS
        if not (law == "stationary" and dyn != "single_integrator")
    ]


def _designed_stress(fw: Framework) -> Any:
    """A stress for ``fw``: sparse (CSR) above ``MAX_AGENTS`` agents when the design is sparse, else dense."""
    complete = len(fw.edges) == fw.n * (fw.n - 1) // 2
    try:
        from formation_env.core.design import design_stress  # lazily: the design module may be absent
    except ImportError:
        if complete:
            return gram_stress(fw)
        raise FormationError(
            f"framework {fw.name or '(custom)'} has no stress matrix: pass omega=..., or install "
            "formation_env.core.design (design_stress); a complete graph gets the Gram stress"
        ) from None
    from formation_env.core.design import trilateration_cliques

    try:  # a trilateration ordering gets the fast sparse construction instead of an SDP
        trilateration_cliques(fw)
        method = "constructive"
    except FormationError:
        method = "sdp"
    res: Any = design_stress(fw, method)
    if sp.issparse(res):
        return sp.csr_matrix(res, dtype=np.float64) if fw.n > MAX_AGENTS else res.toarray()
    return np.asarray(res, dtype=np.float64)


def resolve_framework(
    framework: str | Framework | None, omega: ArrayLike | None, default: str
) -> tuple[Framework, Any]:
    """The framework and its checked stress matrix: dense (n, n), or scipy.sparse CSR above ``MAX_AGENTS``.

    Args:
        framework: a name (``NAMED_FRAMEWORKS`` or a function of ``formation_env.core.frameworks``),
            a ``Framework``, or None for ``default``.
        omega: stress matrix (n, n), dense or scipy.sparse; None takes the named one, or designs one.
    Raises:
        FormationError: unknown name; StressMatrixError: omega fails ``check_stress``.
    """
    name = default if framework is None else framework
    om: Any = None
    if isinstance(name, str):
        if name in NAMED_FRAMEWORKS:
            fw, om = NAMED_FRAMEWORKS[name]()
        else:
            from formation_env.core import frameworks as lib

            fn = getattr(lib, name, None)
            if name.startswith("_") or not callable(fn):
                raise FormationError(
                    f"unknown framework {name!r}; named ones are {sorted(NAMED_FRAMEWORKS)} and the functions of "
                    "formation_env.core.frameworks, or pass a Framework"
                )
            fw = fn()
            if not isinstance(fw, Framework):
                raise FormationError(f"formation_env.core.frameworks.{name}() did not return a Framework")
    elif isinstance(name, Framework):
        fw = name
    else:
        raise TypeError(f"framework must be a name or a Framework, got {type(name).__name__}")
    if omega is not None:
        om = omega
    if om is None:
        om = _designed_stress(fw)
    if fw.n > MAX_AGENTS:  # the sparse path: never densify
        om = sp.csr_matrix(om, dtype=np.float64)
    elif sp.issparse(om):
        om = om.toarray()
    else:
        om = np.asarray(om, dtype=np.float64)
    check_stress(om, fw)
    return fw, om


# ---------------------------------------------------------------------------- the folded step map
_MAP_CACHE: dict[tuple[Any, ...], tuple[FollowerLaw, Array, float]] = {}


def _key(x: Any) -> Any:
    if isinstance(x, np.ndarray):
        return (x.shape, x.tobytes())
    if isinstance(x, dict):
        return tuple(sorted((k, _key(v)) for k, v in x.items()))
    return x


def _law_and_map(
    omega: Array, leaders: tuple[int, ...], dyn: LinearDynamics, law_name: str, dt: float, params: dict[str, Any]
) -> tuple[FollowerLaw, Array, float]:
    """The law, its one-step linear map M with [x', mem'] = [x, u_l, mem] @ M, and its spectral radius."""
    key = (_key(omega), leaders, _key(dyn.A), _key(dyn.B), _key(dyn.C), dyn.discrete, law_name, dt, _key(params))
    hit = _MAP_CACHE.get(key)
    if hit is not None:
        return hit
    part = Partition(omega, leaders)
    law = make_law(law_name, part, dyn, dt, **params)
    n, q, p = part.n, dyn.q, dyn.p
    mem0 = law.initial_memory((1,))
    m = 0 if mem0 is None else int(mem0[0].size)
    z = n * q + part.n_l * p + m
    eye = np.eye(z)
    xs = eye[:, : n * q].reshape(z, n, q)
    us = eye[:, n * q : n * q + part.n_l * p].reshape(z, part.n_l, p)
    ms = None if m == 0 else eye[:, n * q + part.n_l * p :].reshape(z, part.n_f, p)
    x1, mem1 = law.step(xs, us, ms)
    cols = [x1.reshape(z, -1)] + ([] if mem1 is None else [np.asarray(mem1).reshape(z, -1)])
    mat = np.concatenate(cols, axis=1)
    try:
        rho = float(law.spectral_radius())
    except FormationError:
        rho = float("nan")
    if len(_MAP_CACHE) > 64:
        _MAP_CACHE.clear()
    _MAP_CACHE[key] = (law, mat, rho)
    return law, mat, rho


def _fewest_stable_rounds(
    omega: Array, leaders: tuple[int, ...], dyn: LinearDynamics, dt: float, params: dict[str, Any], most: int = 30
) -> int:
    """The fewest Jacobi rounds m <= ``most`` whose ``dynamic_distributed`` closed loop is stable (else 1).

    Odd m can be unstable where even m is not (a negative Jacobi eigenvalue nu gives c = nu^m < 0):
    on the paper's framework with double integrators at T = 0.1, m = 1 diverges and m = 2 converges.
    """
    for m in range(1, most + 1):
        if _law_and_map(omega, leaders, dyn, "dynamic_distributed", dt, {**params, "rounds": m})[2] < 1.0:
            return m
    return 1


# ---------------------------------------------------------------------------- state
class StepInfo(dict[str, Any]):
    """The info dict of one env step, whose values are immutable Python scalars (bool, int, float).

    ``copy.deepcopy`` of it is a plain copy: SB3's ``DummyVecEnv`` deep-copies every info at every step,
    which for eight scalar entries cost more than the whole env step (about 80 us through ``deepcopy``'s
    per-object dispatch, against 1 us here).
    """

    def __deepcopy__(self, memo: dict[int, Any]) -> StepInfo:
        return StepInfo(self)


class EngineState(NamedTuple):
    """Everything that changes during an episode, batched over B environments (immutable; steps make new ones).

    Attributes:
        x: agent states, shape (B, n, q).
        pos: positions C x, shape (B, n, d), m.
        vel: velocities, shape (B, n, d), m/s (C A x when C B = 0, e.g. double integrators;
            else the mean velocity over the last sample, e.g. the applied single-integrator command).
        memory: follower-law memory (``dynamic_distributed``: previous inputs), shape (B, n_f, p), or None.
        k: samples taken, shape (B,) int.
        ref: the step's exogenous inputs [goal (n d), goal velocity (n d), 1, k], shape (B, 2 n d + 2):
            goal (reference) positions x_i* (m) and their velocity (m/s, zero for static goals).
        goal_dist: each leader's distance to its goal position, shape (B, n_l), m.
        err: affine-image formation error, shape (B,), m.
        streak: consecutive successful samples, shape (B,) int.
        params: per-episode arrays (B, ...): the scenario's (goal pose, ``segments``, ``circles``, its own
            parameters) and derived ones (keys starting with "_"), all read-only.
    """

    x: Array
    pos: Array
    vel: Array
    memory: Array | None
    k: NDArray[np.int64]
    ref: Array
    goal_dist: Array
    err: Array
    streak: NDArray[np.int64]
    params: dict[str, Array]

    @property
    def batch_size(self) -> int:
        """B."""
        return int(self.x.shape[0])

    @property
    def goal(self) -> Array:
        """Goal (reference) positions of every agent, shape (B, n, d), m."""
        b, n, d = self.pos.shape
        return self.ref[:, : n * d].reshape(b, n, d)

    @property
    def goal_vel(self) -> Array:
        """Velocity of the goal positions, shape (B, n, d), m/s."""
        b, n, d = self.pos.shape
        return self.ref[:, n * d : 2 * n * d].reshape(b, n, d)


# ---------------------------------------------------------------------------- engine
class Engine:
    """Scenario + framework + dynamics + follower law, stepped in batches (see the module docstring).

    Args:
        scenario: a ``scenarios.REGISTRY`` name.
        dynamics: ``"single_integrator"`` | ``"double_integrator"`` | a ``LinearDynamics`` (every agent).
        follower_law: one of ``FOLLOWER_LAWS``; the followers run it inside the engine.
        dt: sampling period T (s).
        max_cycles: samples per episode before truncation.
        framework: a framework name, a ``Framework`` (2D or 3D; above ``MAX_AGENTS`` agents the sparse
            path of :mod:`formation_env.env.swarm`), or None for the scenario's default.
        omega: stress matrix (n, n), dense or scipy.sparse, for ``framework`` (None: the named one, or designed).
        law_params: parameters of the law (``make_law``: gain, K, Q, eps, rounds). Defaults differ from
            the core's where the core's are slow or unstable: ``stationary`` without ``gain`` takes
            g = 2 / (T (lambda_min + lambda_max)) of Omega_ff, minimising the spectral radius (Theorem 1);
            ``dynamic_distributed`` without ``rounds`` the fewest rounds (<= 30) with a stable closed loop.
        u_max: leader input limit per axis: action 1 means u_max (m/s single, m/s^2 double integrator).
        agent_radius: agent disc (ball) radius (m).
        n_rays: 2D range-sensor rays per leader. n_nearest: 3D nearest obstacles sensed per leader.
        sensor_range: obstacle sensing range (m).
        max_speed: velocity bound (m/s) of observations and state (values beyond are clipped).
        reward_weights: overrides of the scenario's reward weights (keys ``REWARD_TERMS``).
        num_threads: threads of a large batched step (at least ``_kernel.MIN_ROWS_PER_THREAD`` envs each;
            None: the CPUs this process may use, at most 8; 1: none). Results do not depend on it.
        **scenario_kwargs: the scenario's own arguments (unknown ones raise TypeError).

    Contacts (collisions): two agents closer than 2 radii (all pairs up to ``ALL_PAIRS_UP_TO`` agents,
    graph edges beyond), an agent within one radius of a wall segment or of a circle's rim, an agent
    centre outside the world box. They are judged at the samples, and along the whole step (swept:
    wall crossings, path-to-circle distance) whenever some agent moved more than 2 radii / sqrt(d)
    along an axis in that step, so that a fast agent cannot tunnel through a wall.
    """

    theta_clip: float = 3.0

    def __init__(
        self,
        scenario: str = "narrow_passage",
        dynamics: str | LinearDynamics = "double_integrator",
        follower_law: str = "dynamic",
        dt: float = 0.1,
        max_cycles: int = 400,
        *,
        framework: str | Framework | None = None,
        omega: ArrayLike | None = None,
        law_params: dict[str, Any] | None = None,
        u_max: float = 1.0,
        agent_radius: float = 0.1,
        n_rays: int = 16,
        n_nearest: int = 2,
        sensor_range: float = 3.0,
        max_speed: float = 3.0,
        reward_weights: dict[str, float] | None = None,
        num_threads: int | None = None,
        **scenario_kwargs: Any,
    ) -> None:
        if scenario not in REGISTRY:
            raise FormationError(f"unknown scenario {scenario!r}; choose one of {sorted(REGISTRY)}")
        if not (np.isfinite(dt) and dt > 0):
            raise FormationError(f"dt must be a positive finite sampling period in seconds, got {dt}")
        if int(max_cycles) != max_cycles or max_cycles < 1:
            raise FormationError(f"max_cycles must be a positive integer, got {max_cycles}")
        for nm, val in (("u_max", u_max), ("sensor_range", sensor_range), ("max_speed", max_speed)):
            if not (np.isfinite(val) and val > 0):
                raise FormationError(f"{nm} must be positive and finite, got {val}")
        if not (np.isfinite(agent_radius) and agent_radius >= 0):
            raise FormationError(f"agent_radius must be finite and >= 0, got {agent_radius}")
        if int(n_rays) != n_rays or n_rays < 1 or int(n_nearest) != n_nearest or n_nearest < 1:
            raise FormationError(f"n_rays and n_nearest must be positive integers, got {n_rays}, {n_nearest}")
        if num_threads is not None and (int(num_threads) != num_threads or num_threads < 1):
            raise FormationError(f"num_threads must be a positive integer or None, got {num_threads}")
        self.num_threads = _kernel.default_threads() if num_threads is None else int(num_threads)
        self.scenario_name = scenario
        fw, om = resolve_framework(framework, omega, CLASSES[scenario].default_framework)
        self.fw, self.omega = fw, om
        self.sparse = fw.n > MAX_AGENTS  # the swarm path (module docstring)
        self._swarm: Any = None
        self.dynamics = dyn = resolve_dynamics(dynamics, fw.d)
        check_combination(follower_law, dyn)
        self.follower_law = follower_law
        self.dt = float(dt)
        self._max_cycles = int(max_cycles)
        self.u_max = float(u_max)
        self.sensor_range = float(sensor_range)
        self.agent_radius = float(agent_radius)
        self.scenario: Scenario = REGISTRY[scenario](
            fw, agent_radius=self.agent_radius, horizon=self.dt * self._max_cycles, **scenario_kwargs
        )
        from . import swarm

        swarm.fit_world(self.scenario)  # a framework too large for the world: grow it, or refuse the framework
        weights = dict(self.scenario.reward_weights)
        for kk, vv in (reward_weights or {}).items():
            if kk not in REWARD_TERMS:
                raise TypeError(f"reward_weights got unknown term {kk!r}; terms are {list(REWARD_TERMS)}")
            weights[kk] = float(vv)
        self.reward_weights = weights

        n, d, q, p = fw.n, fw.d, dyn.q, dyn.p
        self.n, self.d, self.q, self.p = n, d, q, p
        self.leaders = np.asarray(fw.leaders, dtype=np.int64)
        self.followers = np.asarray(fw.followers, dtype=np.int64)
        self.n_l, self.n_f = self.leaders.size, self.followers.size
        self.kind = (
            "single_integrator"
            if dyn.is_single_integrator
            else "double_integrator"
            if dyn.name == "double_integrator"
            else "general"
        )
        lp = dict(law_params or {})
        if self.sparse:
            self.law, rho = swarm.make_swarm_law(om, fw.leaders, dyn, follower_law, self.dt, lp)
        elif follower_law == "stationary" and "gain" not in lp:  # the gain minimising max |1 - T g lambda_i|
            lam = np.linalg.eigvalsh(Partition(om, fw.leaders).omega_ff_dense)
            lp["gain"] = 2.0 / (self.dt * (lam[0] + lam[-1]))
        if not self.sparse and follower_law == "dynamic_distributed" and "rounds" not in lp:
            lp["rounds"] = _fewest_stable_rounds(om, fw.leaders, dyn, self.dt, lp)
        self.law_params = lp
        step_map: Any = None
        if not self.sparse:
            self.law, step_map, rho = _law_and_map(om, fw.leaders, dyn, follower_law, self.dt, lp)
        self.spectral_radius = rho
        if rho >= 1.0:
            warnings.warn(
                f"follower_law={follower_law!r} at dt={dt} is unstable on this framework: spectral radius "
                f"{rho:.4g} >= 1 (see formation_env.core.analysis.stability_report)",
                StabilityWarning,
                stacklevel=2,
            )
        mem0 = self.law.initial_memory((1,))
        self.mem_dim = 0 if mem0 is None else int(mem0[0].size)
        self.affine = AffineImage(fw.positions)
        self.v_bound = max(float(max_speed), self.u_max if self.kind == "single_integrator" else 0.0)
        self.bounds = self.scenario.bounds
        self.n_rays, self.n_nearest = int(n_rays), int(n_nearest)
        self._dirs = geometry.ray_directions(self.n_rays) if d == 2 else np.zeros((0, d))
        probe = self.scenario.reset(np.random.default_rng(0), 1)
        self.n_seg, self.n_circ = int(probe["segments"].shape[1]), int(probe["circles"].shape[1])
        if self.n_seg and d != 2:
            raise FormationError(f"scenario {scenario!r}: wall segments are 2D only, the framework is {d}D")
        if n <= ALL_PAIRS_UP_TO:
            self._pairs = np.stack(np.triu_indices(n, 1), axis=1)
        else:
            self._pairs = fw.edge_array()
        self._perm = np.concatenate([self.leaders, self.followers])  # leaders first
        self._fast = 2.0 * self.agent_radius / math.sqrt(d)
        self._fused_success = type(self.scenario).is_success is Scenario.is_success
        self._step_map = step_map
        self._build_obs_layout()
        if not self.sparse:
            self._build_static()
            self._build_geometry_template()
        self._build_bounds()
        if self.sparse:
            self._swarm = swarm.SwarmStep(self)
            self._fast1 = self._kbatch = False  # the compiled paths use the folded (dense) matrices
        else:
            self._build_kernel_batch()
            self._build_fast1()

    # ------------------------------------------------------------------ construction
    @property
    def max_cycles(self) -> int:
        """Samples per episode before truncation (setting it rebuilds the folded step)."""
        return self._max_cycles

    @max_cycles.setter
    def max_cycles(self, value: int) -> None:
        if int(value) != value or value < 1:
            raise FormationError(f"max_cycles must be a positive integer, got {value}")
        self._max_cycles = int(value)
        self._build_obs_layout()
        if not self.sparse:
            self._build_static()
            self._build_fast1()  # its packed constants hold M and 1 / max_cycles

    def _build_obs_layout(self) -> None:
        """Observation blocks of one leader, and W mapping [pos, vel, ref] (B, 4 n d + 2) to its linear entries."""
        n, d, nl = self.n, self.d, self.n_l
        nd = n * d
        self.obs_blocks: dict[str, slice] = {}
        off = 0
        ks = self.n_rays if d == 2 else self.n_nearest * d
        sizes = {
            "position": d,
            "velocity": d,
            "other_leaders": (nl - 1) * d,
            "goal": d,
            "goal_velocity": d,
            "theta": d * d,
            "time": 1,
            "formation_error": 1,
            "obstacles": ks,
        }
        for name, size in sizes.items():
            self.obs_blocks[name] = slice(off, off + size)
            off += size
        self.obs_dim = off
        L1 = self.L1 = self.obs_blocks["time"].stop  # entries linear in [pos, vel, ref]
        if self.sparse:  # the swarm path computes these entries directly
            return
        pinv = self.affine._pinv  # (d + 1, n): rows of Theta^T, then b
        sl = self.obs_blocks
        w = np.zeros((4 * nd + 2, nl * L1))  # rows: pos, vel, goal, goal_vel, 1, k
        for li, a in enumerate(self.leaders):
            o = li * L1
            others = [b for b in self.leaders if b != a]
            for c in range(d):
                w[a * d + c, o + sl["position"].start + c] = 1.0
                w[nd + a * d + c, o + sl["velocity"].start + c] = 1.0
                for jj, b in enumerate(others):
                    col = o + sl["other_leaders"].start + jj * d + c
                    w[b * d + c, col] += 1.0
                    w[a * d + c, col] -= 1.0
                w[a * d + c, o + sl["goal"].start + c] = -1.0
                w[2 * nd + a * d + c, o + sl["goal"].start + c] = 1.0
                w[3 * nd + a * d + c, o + sl["goal_velocity"].start + c] = 1.0
            for i_ in range(d):  # Theta[i_, j_] = sum_m pinv[j_, m] pos[m, i_]
                for j_ in range(d):
                    w[np.arange(n) * d + i_, o + sl["theta"].start + i_ * d + j_] = pinv[j_]
            w[4 * nd + 1, o + sl["time"].start] = 1.0 / self._max_cycles
        self._w_obs = w

    def _build_static(self) -> None:
        """The folded step: z = [x, a, mem, ref] (B, Z) @ M -> [x', mem', pos', 1, vel', guard, ref', obs_lin]."""
        n, d, q, p, nl = self.n, self.d, self.q, self.p, self.n_l
        nq, nd = n * q, n * d
        nr = 2 * nd + 2
        dyn = self.dynamics
        core = self._step_map.copy()  # rows x, u, mem; columns x', mem'
        core[nq : nq + nl * p] *= self.u_max  # the actions a in [-1, 1] enter as u = u_max a
        zc = core.shape[0]
        z = zc + nr
        core = np.concatenate([core, np.zeros((nr, core.shape[1]))], axis=0)
        mx = core[:, :nq]
        ck = np.kron(np.eye(n), dyn.C)  # (nd, nq)
        mpos = mx @ ck.T
        p0 = np.zeros((z, nd))
        p0[:nq] = ck.T
        self._vel_from_state = not dyn.discrete and not np.any(dyn.C @ dyn.B)
        mvel = mx @ np.kron(np.eye(n), dyn.C @ dyn.A).T if self._vel_from_state else (mpos - p0) / self.dt
        mref = np.zeros((z, nr))
        mref[zc:] = np.eye(nr)
        mref[zc + 2 * nd, 2 * nd + 1] = 1.0  # k' = k + 1 (the "1" entry of ref feeds the k column)
        one = np.zeros((z, 1))
        one[zc + 2 * nd] = 1.0
        mobs = np.concatenate([mpos, mvel, mref], axis=1) @ self._w_obs
        blocks: list[tuple[str, Array]] = [("x", core[:, :nq]), ("mem", core[:, nq:]), ("pos", mpos), ("one", one)]
        # guard: world-box margins and the fast-step margins f -+ displacement; all >= 0 in a quiet step
        lo, hi = self.bounds
        disp = mpos - p0
        guard = np.concatenate([mpos, -mpos, -disp, disp], axis=1)
        guard[zc + 2 * nd] += np.concatenate([-np.tile(lo, n), np.tile(hi, n), np.full(2 * nd, self._fast)])
        # every agent's and every leader's [p_i, 1], for the per-episode wall and ray maps
        aug = np.concatenate([mpos.reshape(z, n, d), np.repeat(one[:, None, :], n, axis=1)], axis=2)
        blocks += [("vel", mvel), ("guard", guard), ("ref", mref), ("obs", mobs)]
        blocks += [("paug", aug.reshape(z, -1)), ("laug", aug[:, self.leaders].reshape(z, -1))]
        cols: dict[str, slice] = {}
        c = 0
        for name, blk in blocks:
            cols[name] = slice(c, c + blk.shape[1])
            c += blk.shape[1]
        cols["pos1"] = slice(cols["pos"].start, cols["one"].stop)
        g0 = cols["guard"].start
        cols["box"], cols["speed"] = slice(g0, g0 + 2 * nd), slice(g0 + 2 * nd, g0 + 4 * nd)
        self._falses: dict[int, NDArray[np.bool_]] = {}
        self._cols = cols
        self._M = np.ascontiguousarray(np.concatenate([blk for _, blk in blocks], axis=1))

    def _build_geometry_template(self) -> None:
        """The geometric features: Q = [pos, 1] (B, n d + 1) @ G (shared) + per-episode offsets.

        Rows of Q (each a d-vector whose norm matters): agent pairs p_i - p_j; agent-circle p_i - c_j;
        agent-wall (excess along the wall, distance across it) (2D, filled in by ``_features``);
        goal deltas x_i* - p_i (leaders first); affine residual rows / sqrt(n). ``_norms`` sums the
        squares per row (all residual rows into one): [contact distances, goal distances, formation error].
        Walls and rays have per-episode coefficients, applied per agent to [p_i, 1] (see ``_episode_geometry``).
        """
        n, d = self.n, self.d
        nd = n * d
        P, C, S = len(self._pairs), self.n_circ, self.n_seg
        rows = {"pairs": P, "circles": n * C, "walls": n * S, "delta": n, "res": n}
        r0: dict[str, int] = {}
        acc = 0
        for name, size in rows.items():
            r0[name] = acc
            acc += size
        self._rows = r0
        kc, kd = r0["delta"], r0["res"]
        self._kc, self._kd = kc, kd
        nrow = acc
        self._g = {
            "walls": slice(r0["walls"] * d, r0["delta"] * d),
            "delta": slice(r0["delta"] * d, r0["res"] * d),
            "circles": slice(r0["circles"] * d, r0["walls"] * d),
        }
        G0 = np.zeros((nd + 1, nrow * d))
        comp = np.arange(d)
        for k, (i, j) in enumerate(self._pairs):
            G0[i * d + comp, k * d + comp] = 1.0
            G0[j * d + comp, k * d + comp] = -1.0
        for i in range(n):
            for jj in range(C):
                G0[i * d + comp, (r0["circles"] + i * C + jj) * d + comp] = 1.0
        for k, a in enumerate(self._perm):
            G0[a * d + comp, (r0["delta"] + k) * d + comp] = -1.0
        pres = self.affine._resid / math.sqrt(n)
        for i in range(n):
            for j in range(n):
                G0[j * d + comp, (r0["res"] + i) * d + comp] = pres[i, j]
        self._G0 = G0
        sc = self.scenario
        self._thr0 = np.concatenate(
            [
                np.full(P, 2 * self.agent_radius),
                np.full(n * (C + S), self.agent_radius),
                np.full(n, sc.goal_tol),
                [sc.formation_tol],
            ]
        )
        self._thr_row = self._thr0[None].copy()
        self._thr_row.setflags(write=False)  # like the params arrays: one array type for the kernels

    def _episode_geometry(self, params: dict[str, Array]) -> None:
        """Per-episode geometry into ``params``: with circles, ``_thr`` (B, Kc + n + 1) thresholds (m); for walls
        ``_a``, ``_e`` (B, S, d) their starts and vectors (m) and the maps of :meth:`_wall_maps`: ``_W``
        (B, d + 1, 3 S), ``_R`` (B, 2, S R). (The constant parts of Q, circle centres and static goals,
        are added where Q is made: :meth:`_add_offsets`.)"""
        n = self.n
        seg, circ = params["segments"], params["circles"]
        B, S, C = seg.shape[0], self.n_seg, self.n_circ
        if seg.shape[1] != S or circ.shape[1] != C:
            raise FormationError(
                f"scenario {self.scenario_name!r} must give {S} segments and {C} circles per episode, "
                f"got {seg.shape[1]} and {circ.shape[1]}"
            )
        if C:  # per-episode thresholds only where circles' radii enter them (else :meth:`_thresholds` shares one)
            thr = np.repeat(self._thr0[None], B, axis=0)
            r0 = self._rows
            thr[:, r0["circles"] : r0["walls"]] += np.repeat(circ[:, None, :, self.d], n, axis=1).reshape(B, n * C)
            params["_thr"] = thr
        if S:
            params["_W"], params["_R"] = self._wall_maps(seg)
            params["_a"], params["_e"] = np.ascontiguousarray(seg[:, :, 0]), seg[:, :, 1] - seg[:, :, 0]

    def _thresholds(self, params: dict[str, Array]) -> Array:
        """The contact and success thresholds (m) of the episodes ``params``: their own ``_thr`` (B, Kc + n + 1)
        where circles make them differ, else the engine's, shared, as a read-only (1, Kc + n + 1) row."""
        return params.get("_thr", self._thr_row)

    def _wall_maps(self, seg: Array) -> tuple[Array, Array]:
        """The walls' coefficient maps, from their segments (start, end) (B, S, 2, d) (2D), m:

        * ``W`` (B, d + 1, 3 S): an agent's [p, 1] -> [across, along - length, -along] per wall;
        * ``R`` (B, 2, S R): G and U per wall and ray (``_kernel.wall_maps``): a leader whose across of wall s
          is a meets its line along ray r at T = -a G (sensor ranges) and at along + (-a) U along it: a hit iff
          G != 0 (not parallel), T >= 0 and 0 <= along + (-a) U <= length.

        Compiled per episode (``_kernel.wall_maps``, the same operations) when numba is there, else numpy."""
        if _kernel.AVAILABLE:
            return _kernel.wall_maps(np.ascontiguousarray(seg), self._dirs, self.sensor_range)
        B, S, d = seg.shape[0], seg.shape[1], self.d
        a = seg[:, :, 0]
        e = seg[:, :, 1] - seg[:, :, 0]
        length = np.linalg.norm(e, axis=-1)  # (B, S)
        t = e / np.maximum(length, 1e-300)[..., None]
        nr = np.stack([-t[..., 1], t[..., 0]], axis=-1)
        a_t, a_n = np.sum(a * t, -1), np.sum(a * nr, -1)
        W = np.zeros((B, d + 1, 3 * S))
        W[:, :d, :S], W[:, d, :S] = nr.transpose(0, 2, 1), -a_n
        W[:, :d, S : 2 * S], W[:, d, S : 2 * S] = t.transpose(0, 2, 1), -a_t - length
        W[:, :d, 2 * S :], W[:, d, 2 * S :] = -t.transpose(0, 2, 1), a_t
        un = np.einsum("rc,bsc->bsr", self._dirs, nr)  # (B, S, R)
        ut = np.einsum("rc,bsc->bsr", self._dirs, t)
        ok = np.abs(un) > 1e-9
        inv = np.where(ok, 1.0 / np.where(ok, un, 1.0), 0.0)
        Rm = np.stack([inv / self.sensor_range, ut * inv], axis=1)  # (B, 2, S, R)
        return W, Rm.reshape(B, 2, S * self.n_rays)

    def _build_bounds(self) -> None:
        d, nl, n = self.d, self.n_l, self.n
        lo_w, hi_w = self.bounds
        ext = hi_w - lo_w
        v = self.v_bound
        emax = float(np.linalg.norm(ext))
        ks = self.n_rays if d == 2 else self.n_nearest * d
        lo = [lo_w, np.full(d, -v), np.tile(-ext, nl - 1), -ext, np.full(d, -v), np.full(d * d, -self.theta_clip)]
        hi = [hi_w, np.full(d, v), np.tile(ext, nl - 1), ext, np.full(d, v), np.full(d * d, self.theta_clip)]
        lo += [[0.0], [0.0], np.zeros(ks) if d == 2 else -np.ones(ks)]
        hi += [[1.0], [emax], np.ones(ks)]
        self.obs_low = np.concatenate(lo).astype(np.float32)
        self.obs_high = np.concatenate(hi).astype(np.float32)
        self._lin_lo = self.obs_low[: self.L1].astype(np.float64)
        self._lin_hi = self.obs_high[: self.L1].astype(np.float64)
        self._lin_lo2 = np.tile(self._lin_lo, (nl, 1))  # per leader (n_l, L1), for the compiled steps
        self._lin_hi2 = np.tile(self._lin_hi, (nl, 1))
        self._err_hi = float(self.obs_high[self.L1])
        sc = self.scenario
        s_lo: list[ArrayLike] = [np.tile(lo_w, n), np.full(n * d, -v), np.tile(lo_w, n), np.full(n * d, -v), [0.0]]
        s_hi: list[ArrayLike] = [np.tile(hi_w, n), np.full(n * d, v), np.tile(hi_w, n), np.full(n * d, v), [emax]]
        s_lo += [np.full(d * d, -self.theta_clip), sc.param_low, [0.0]]
        s_hi += [np.full(d * d, self.theta_clip), sc.param_high, [1.0]]
        self.state_low = np.concatenate(s_lo).astype(np.float32)
        self.state_high = np.concatenate(s_hi).astype(np.float32)
        self._state_lo64 = self.state_low.astype(np.float64)
        self._state_hi64 = self.state_high.astype(np.float64)
        self.state_dim = int(self.state_low.size)
        pinv = self.affine._pinv  # Theta[i, j] = sum_m pinv[j, m] p_m[i], row-major in the state vector
        tm = np.zeros((n, d, d, d))
        for i_ in range(d):
            tm[:, i_, i_, :] = pinv[:d].T
        self._theta_map = tm.reshape(n * d, d * d)
        no_obstacles = (self.n_seg + self.n_circ) == 0
        self._const_sense = (np.ones(ks) if d == 2 else np.zeros(ks)) if no_obstacles else None
        # reward and effort from [success, collision, err, a^2 (n_l p), goal_dist (n_l), goal_dist' (n_l)]
        w, nlp = self.reward_weights, nl * self.p
        wr = np.zeros((3 + nlp + 2 * nl, 2 * nl))
        wr[0, :nl] = w["success"]
        wr[1, :nl] = -w["collision"]
        wr[2, :nl] = -w["formation"] * self.dt
        lead = np.repeat(np.arange(nl), self.p)
        wr[3 + np.arange(nlp), lead] = -w["effort"] * self.dt / self.p
        wr[3 + np.arange(nlp), nl + lead] = self.u_max**2
        wr[3 + nlp + np.arange(nl), np.arange(nl)] = w["progress"]
        wr[3 + nlp + nl + np.arange(nl), np.arange(nl)] = -w["progress"] - w["distance"] * self.dt
        self._w_rew = wr
        self._w_tail = np.ascontiguousarray(wr[3:])  # the compiled steps: rows of [a^2, goal distances before, after]
        self._w_head = [float(w) for w in wr[:3, 0]]  # and the success, collision, formation weights (all leaders)

    # ------------------------------------------------------------------ reset
    def reset(self, rng: np.random.Generator, B: int = 1) -> EngineState:
        """Draw B new episodes from ``rng``: agents at rest on the scenario's start, law memory empty."""
        if int(B) != B or B < 1:
            raise FormationError(f"batch size B must be a positive integer, got {B}")
        if B == 1 and self.scenario.compiled_draws:  # the same episode (tests), in fewer calls
            return self._reset_each([rng])[0]
        return self._reset_from(dict(self.scenario.reset(rng, int(B))))[0]

    def reset_each(self, rngs: list[np.random.Generator]) -> EngineState:
        """One new episode per generator, batched: entry b equals ``reset(rngs[b], 1)`` up to rounding (for
        vectorised envs whose copies are seeded one by one). Only the scenario's draws run per generator
        (``Scenario.reset_each``), the rest batched."""
        return self._reset_each(rngs)[0]

    def reset_each_observed(
        self, rngs: Sequence[np.random.Generator], bits: tuple[NDArray[np.int64], NDArray[np.int64]] | None = None
    ) -> tuple[EngineState, NDArray[np.float32]]:
        """``reset_each`` and the new episodes' observations, ``observe(state)`` (B, n_l, obs_dim) float32, taken
        from the measurement that the reset makes anyway (the compiled path) instead of a second one. ``bits``: the
        generators' ``_kernel.bit_generators``, where the caller keeps them (``Scenario.reset_each``)."""
        state, obs = self._reset_each(rngs, bits)
        return state, (self.observe(state) if obs is None else obs)

    def _reset_each(
        self, rngs: Sequence[np.random.Generator], bits: tuple[NDArray[np.int64], NDArray[np.int64]] | None = None
    ) -> tuple[EngineState, NDArray[np.float32] | None]:
        if not rngs:
            raise FormationError("reset_each needs at least one generator")
        return self._reset_from(dict(self.scenario.reset_each(rngs, bits)))

    def _reset_from(self, params: dict[str, Array]) -> tuple[EngineState, NDArray[np.float32] | None]:
        """The episodes of the scenario's draws ``params``, and their observations where the compiled measurement
        gave them (else None)."""
        if self._swarm is not None:
            return self._swarm.reset_from(params), None
        B = int(params["segments"].shape[0])
        start = np.array(params.pop("start"), dtype=np.float64)
        k = np.zeros(B, dtype=np.int64)
        ref = self._ref(params, k)
        self._episode_geometry(params)
        params["_pvec"] = np.ascontiguousarray(self.scenario.param_vector(params), dtype=np.float64)  # global_state
        if B == 1 and self._fast1:
            self._pack_episode(params)
        for arr in params.values():
            arr.setflags(write=False)
        obs = None
        if B == 1 and self._fast1:  # the goal distances and formation error in one compiled call
            nv = _kernel.measure1(start, ref, self._c1, params["_ep1"], self._layout1)
            goal_dist, err = nv[None, self._kc : self._kc + self.n_l], nv[-1:]
        elif self._kbatch:
            obs, dist = self._measure_compiled(start, np.zeros_like(start), ref, params)[:2]
            goal_dist, err = dist[:, : self.n_l], dist[:, self.n_l]
        else:
            nv = self._norms(self._features(*self._aug(start), params, ref))
            goal_dist, err = nv[:, self._kc : self._kc + self.n_l], nv[:, -1]
        at_rest = self.__dict__.get("_at_rest")  # x at rest from positions: dynamics.state_from_position, cached
        if at_rest is None:
            at_rest = self.__dict__["_at_rest"] = np.linalg.pinv(self.dynamics.C).T
        state = EngineState(
            x=start @ at_rest,
            pos=start,
            vel=np.zeros_like(start),
            memory=self.law.initial_memory((B,)),
            k=k,
            ref=ref,
            goal_dist=goal_dist,
            err=err,
            streak=np.zeros(B, dtype=np.int64),
            params=params,
        )
        return state, obs

    def _ref(self, params: dict[str, Array], k: NDArray[np.int64]) -> Array:
        """ref = [goal x*(k T), its velocity (x*((k+1) T) - x*(k T)) / T, 1, k], shape (B, 2 n d + 2)."""
        sc = self.scenario
        B, nd = k.shape[0], self.n * self.d
        ref = np.empty((B, 2 * nd + 2))
        if sc.moving_goal:
            t = k.astype(np.float64) * self.dt
            g0 = affine_batch(sc.r, *sc.reference(params, t))
            g1 = affine_batch(sc.r, *sc.reference(params, t + self.dt))
            ref[:, nd : 2 * nd] = ((g1 - g0) / self.dt).reshape(B, nd)
        else:
            g0 = affine_batch(sc.r, params["goal_theta"], params["goal_b"])
            ref[:, nd : 2 * nd] = 0.0
        ref[:, :nd] = g0.reshape(B, nd)
        ref[:, 2 * nd] = 1.0
        ref[:, 2 * nd + 1] = k
        return ref

    # ------------------------------------------------------------------ features
    def _false(self, B: int) -> NDArray[np.bool_]:
        """A read-only all-False (B,) array (cached)."""
        f = self._falses.get(B)
        if f is None:
            f = self._falses[B] = np.zeros(B, dtype=bool)
            f.setflags(write=False)
        return f

    def _aug(self, pos: Array) -> tuple[Array, Array, Array]:
        """[pos, 1] (B, n d + 1), per-agent [p_i, 1] (B, n, d + 1), per-leader [p_l, 1] (B, n_l, d + 1)."""
        B = pos.shape[0]
        paug = np.concatenate([pos, np.ones((B, self.n, 1))], axis=2)
        pos1 = np.concatenate([pos.reshape(B, -1), np.ones((B, 1))], axis=1)
        return pos1, paug, paug[:, self.leaders]

    def _add_offsets(self, q: Array, circles: Array, ref: Array) -> None:
        """Add the episode's constant parts to features Q (B, F) in place: the circle centres (B, C, d + 1) to
        the agent-circle rows (p_i - c_j), the goals in ``ref`` (leaders first) to the goal rows (x_i* - p_i)."""
        if self.n_circ:
            B, d = q.shape[0], self.d
            qc = q[:, self._g["circles"]].reshape(B, self.n, self.n_circ, d)  # a view
            qc -= circles[:, None, :, :d]
        q[:, self._g["delta"]] += ref[:, self._goal_perm]

    def _features(self, pos1: Array, paug: Array, laug: Array, params: dict[str, Array], ref: Array) -> Array:
        """Q features (B, F) from the augmented positions of ``_aug`` (see the template); ``laug`` is unused."""
        q = pos1 @ self._G0
        self._add_offsets(q, params["circles"], ref)
        S = self.n_seg
        if S:
            B = q.shape[0]
            wf = paug @ params["_W"]  # (B, n, 3 S): across, along - length, -along
            qw = q[:, self._g["walls"]].reshape(B, self.n, S, self.d)
            qw[..., 1] = wf[..., :S]
            ex = qw[..., 0]  # excess along the wall: max(along - length, -along, 0)
            np.maximum(wf[..., S : 2 * S], wf[..., 2 * S :], out=ex)
            np.maximum(ex, 0.0, out=ex)
        return q

    @property
    def _goal_perm(self) -> NDArray[np.int64]:
        gp = getattr(self, "_goal_perm_cache", None)
        if gp is None:
            d = self.d
            gp = self._goal_perm_cache = (self._perm[:, None] * d + np.arange(d)).reshape(-1)
        return gp

    def _norms(self, geo: Array) -> Array:
        """[contact distances (Kc), goal distances (n, leaders first), formation error], shape (B, Kc + n + 1)."""
        sq = geo * geo
        kd, d = self._kd, self.d
        out = np.empty((sq.shape[0], kd + 1))
        head = out[:, :kd]
        np.add(sq[:, 0 : kd * d : d], sq[:, 1 : kd * d : d], out=head)  # per row, sum over its d components
        for c in range(2, d):
            head += sq[:, c : kd * d : d]
        out[:, kd] = sq[:, kd * d :].sum(axis=1)  # the residual rows together
        return np.sqrt(out, out=out)

    def _sense(self, laug: Array, params: dict[str, Array]) -> Array:
        """Obstacle sensing of every leader from its [p, 1] (B, n_l, d + 1): 2D ray ranges / range, 3D
        proximity vectors; shape (B, n_l, ks)."""
        if self._const_sense is not None:
            return self._const_sense
        B, nl = laug.shape[0], self.n_l
        pos_l = laug[..., :-1]
        if self.d == 2:
            R, S = self.n_rays, self.n_seg
            if S:  # ranges / sensor range of the rays that hit a wall inside it, else 1 (see _kernel.wall_maps)
                wf = laug @ params["_W"]  # (B, n_l, 3 S): across, along - length, -along per wall
                aml, back = wf[..., S : 2 * S, None], wf[..., 2 * S :, None]
                f = -wf[..., :S, None]
                g = params["_R"][:, 0].reshape(B, 1, S, R)
                t, uf = f * g, params["_R"][:, 1].reshape(B, 1, S, R) * f  # (B, n_l, S, R)
                hit = np.where((g != 0.0) & (t >= 0.0) & (uf >= back) & (aml + uf <= 0.0), t, 1.0)
                ranges = np.minimum(hit[:, :, 0], 1.0)
                for s_ in range(1, S):
                    np.minimum(ranges, hit[:, :, s_], out=ranges)
            else:
                ranges = np.ones((B, nl, R))
            if self.n_circ:
                empty = np.zeros((B, 0, 2))
                rc = geometry.ray_ranges(pos_l, self._dirs, empty, empty, params["circles"], self.sensor_range)
                np.minimum(ranges, rc * (1.0 / self.sensor_range), out=ranges)
            return ranges
        vec = geometry.nearest_obstacle_vectors(pos_l, params["circles"], self.n_nearest, self.sensor_range)
        return vec.reshape(B, nl, -1)

    def _assemble(self, lin: Array, err: Array, sense: Array) -> NDArray[np.float32]:
        """Observations from the linear entries (B, n_l L1), the formation error (B,) and sensing (within bounds)."""
        B, L1 = lin.shape[0], self.L1
        obs = np.empty((B, self.n_l, self.obs_dim), dtype=np.float32)
        head = obs[:, :, :L1]  # clipped in float64, then rounded: the float32 bounds are never crossed
        np.minimum(np.maximum(lin.reshape(B, self.n_l, L1), self._lin_lo), self._lin_hi, out=head, casting="same_kind")
        obs[:, :, L1] = np.minimum(err, self._err_hi)[:, None]
        obs[:, :, L1 + 1 :] = sense
        return obs

    # ------------------------------------------------------------------ observation
    def observe(self, state: EngineState) -> NDArray[np.float32]:
        """Observations of every leader, shape (B, n_l, obs_dim), float32 (layout: ``obs_blocks``)."""
        if self._swarm is not None:
            return self._swarm.observe(state)
        if self._kbatch:
            return self._measure_compiled(state.pos, state.vel, state.ref, state.params)[0]
        B = state.batch_size
        pos1, paug, laug = self._aug(state.pos)
        geo = self._features(pos1, paug, laug, state.params, state.ref)
        lin = np.concatenate([state.pos.reshape(B, -1), state.vel.reshape(B, -1), state.ref], axis=1) @ self._w_obs
        return self._assemble(lin, self._norms(geo)[:, -1], self._sense(laug, state.params))

    def global_state(self, state: EngineState) -> NDArray[np.float32]:
        """Global state vectors, shape (B, state_dim), float32: positions, velocities, goal positions and
        velocities of all agents, formation error, fitted Theta (row-major), scenario parameters, time fraction."""
        B = state.batch_size
        pos = state.pos.reshape(B, -1)
        if _kernel.AVAILABLE:
            return _kernel.global_state(
                np.ascontiguousarray(pos),
                np.ascontiguousarray(state.vel.reshape(B, -1)),
                np.ascontiguousarray(state.ref),
                np.ascontiguousarray(state.err),
                self._theta_map,
                state.params["_pvec"],
                state.k,
                1.0 / self._max_cycles,
                self._state_lo64,
                self._state_hi64,
            )
        parts = [
            pos,
            state.vel.reshape(B, -1),
            state.ref[:, : 2 * self.n * self.d],
            state.err[:, None],
            pos @ self._theta_map,
            state.params["_pvec"],
            state.k[:, None] * (1.0 / self._max_cycles),
        ]
        out = np.concatenate(parts, axis=1)
        np.minimum(np.maximum(out, self._state_lo64, out=out), self._state_hi64, out=out)
        return out.astype(np.float32)

    # ------------------------------------------------------------------ step
    def check_actions(self, actions: ArrayLike, B: int) -> Array:
        """Actions as float64 (B, n_l, p); raise ValueError naming the leader on NaN or inf."""
        a = np.asarray(actions, dtype=np.float64)
        if a.shape != (B, self.n_l, self.p):
            raise ControlDimension(f"actions must have shape (B, n_l, p) = ({B}, {self.n_l}, {self.p}), got {a.shape}")
        if not math.isfinite(a.sum()):
            bad = np.argwhere(~np.isfinite(a).all(axis=-1))
            if bad.size:  # (a finite sum that overflowed is no error: the values are clipped)
                b, i = bad[0]
                raise ValueError(
                    f"action of leader_{i} (batch entry {b}) holds NaN or inf: {a[b, i].tolist()}; "
                    "the state is unchanged"
                )
        return a

    def step(
        self, state: EngineState, actions: ArrayLike
    ) -> tuple[EngineState, NDArray[np.float32], Array, NDArray[np.bool_], NDArray[np.bool_], dict[str, Array]]:
        """One sample of every environment.

        Args:
            state: the current state (not modified).
            actions: leader actions in [-1, 1], shape (B, n_l, p); values outside are clipped,
                NaN or inf raise ValueError (and nothing changes).
        Returns:
            (state', obs (B, n_l, obs_dim) float32, rewards (B, n_l), terminated (B,), truncated (B,), info)
            with info arrays: success, collision, out_of_bounds (B,) bool; formation_error, min_clearance,
            goal_distance, time (B,) in m and s; control_effort (B, n_l), |u_i|^2.
        """
        if self._swarm is not None:
            return self._swarm.step(state, actions)
        B = state.x.shape[0]
        if B == 1 and "_ep1" in state.params:  # the single-env fast path, in arrays
            new, obs, rew, term, trunc, inf = self.step1(state, actions)
            info = {key: np.array([val]) for key, val in inf.items()}
            assert obs is not None
            return new, obs[None], np.array([rew]), np.array([term]), np.array([trunc]), info
        if self._kbatch:
            return self._step_batch(state, actions)
        a = np.minimum(np.maximum(self.check_actions(actions, B), -1.0), 1.0)
        af = a.reshape(B, -1)
        if state.memory is None:
            z = np.concatenate((state.x.reshape(B, -1), af, state.ref), axis=1)
        else:
            z = np.concatenate((state.x.reshape(B, -1), af, state.memory.reshape(B, -1), state.ref), axis=1)
        out = z @ self._M
        cols, params, nl, kc = self._cols, state.params, self.n_l, self._kc
        k = state.k + 1
        sc = self.scenario
        if sc.moving_goal:
            ref = self._ref(params, k)  # replaces the folded ref' = ref + (0, .., 0, 1) in the observation
            lin = out[:, cols["obs"]] + (ref - out[:, cols["ref"]]) @ self._w_obs[-ref.shape[1] :]
        else:
            ref = out[:, cols["ref"]]
            lin = out[:, cols["obs"]]
        laug = out[:, cols["laug"]].reshape(B, self.n_l, self.d + 1)
        paug = out[:, cols["paug"]].reshape(B, self.n, self.d + 1)
        geo = self._features(out[:, cols["pos1"]], paug, laug, params, ref)
        nv = self._norms(geo)
        v = nv - self._thresholds(params)
        clear = v[:, :kc].min(axis=1)
        collision = clear < 0.0
        pos = out[:, cols["pos"]].reshape(B, self.n, self.d)
        if out[:, cols["guard"]].min() >= 0.0:  # the usual step: inside the world box, no agent fast
            oob = self._false(B)
        else:
            oob = self._guarded(out, state.pos, pos, params, clear, collision)
        err = nv[:, -1]
        gd_l = nv[:, kc : kc + nl]
        if self._fused_success:
            ok = (v[:, kc:].max(axis=1) < 0.0) > collision
        else:
            ok = sc.is_success(nv[:, kc:-1].max(axis=1), err) > collision
        streak, success, terminated, truncated = self._episode_end(state, ok, collision, k)
        feats = np.concatenate((success[:, None], collision[:, None], err[:, None], af * af, state.goal_dist, gd_l), 1)
        re = feats @ self._w_rew
        sense = self._const_sense if self._const_sense is not None else self._sense(laug, params)
        obs = self._assemble(lin, err, sense)
        new = EngineState(
            out[:, cols["x"]].reshape(B, self.n, self.q),
            pos,
            out[:, cols["vel"]].reshape(B, self.n, self.d),
            out[:, cols["mem"]].reshape(B, self.n_f, self.p) if self.mem_dim else None,
            k,
            ref,
            gd_l,
            err,
            streak,
            params,
        )
        info = self._info(success, collision, oob, err, clear, nv[:, kc:-1].max(axis=1), re[:, nl:], k * self.dt)
        return new, obs, re[:, :nl], terminated, truncated, info

    def _guarded(
        self,
        out: Array,
        prev: Array,
        pos: Array,
        params: dict[str, Array],
        clear: Array,
        collision: NDArray[np.bool_],
    ) -> NDArray[np.bool_]:
        """The rare part of a step whose guard tripped: leaving the world box, and swept (tunnelling) contacts
        of fast agents from ``prev`` to ``pos`` (B, n, d). Updates ``clear`` and ``collision`` (B,) in place;
        returns out_of_bounds (B,). The numpy reference step's (``_kernel.step1`` does the same in its call)."""
        cols = self._cols
        oob = out[:, cols["box"]].min(axis=1) < 0.0
        collision |= oob
        fast = out[:, cols["speed"]].min(axis=1) < 0.0
        if fast.any():
            self._swept(prev, pos, params, clear, collision, fast)
        return oob

    def _swept_compiled(
        self, flags: NDArray[np.bool_], prev: Array, pos: Array, params: dict[str, Array], dist: Array, col: int
    ) -> NDArray[np.bool_]:
        """``_swept`` by ``_kernel.swept_rows`` in the envs where ``flags[:, 1]`` (flags (B, 2) bool): lowers
        ``dist[:, col]`` (the clearance) in place; returns the envs with a swept contact (B,) bool."""
        hit = np.zeros(flags.shape[0], dtype=bool)
        walls = (params["_a"], params["_e"]) if self.n_seg else (self._no_seg, self._no_seg)
        p0, p1 = np.ascontiguousarray(prev), np.ascontiguousarray(pos)
        _kernel.swept_rows(
            0, flags.shape[0], flags, p0, p1, *walls, params["circles"], self.agent_radius, dist, col, hit
        )
        return hit

    def _swept(
        self,
        prev: Array,
        pos: Array,
        params: dict[str, Array],
        clear: Array,
        collision: NDArray[np.bool_],
        fast: NDArray[np.bool_],
    ) -> None:
        """Swept contacts of the motions ``prev`` -> ``pos`` (B, n, d) with walls and circles (so that a fast
        agent cannot tunnel), in the envs where ``fast`` (B,) bool (the others' motions are too short to
        tunnel); updates ``clear`` and ``collision`` (B,) in place."""
        rows = np.flatnonzero(fast)
        p0, p1 = prev[rows], pos[rows]
        if self.n_seg:
            collision[rows] |= geometry.segment_crossings(p0, p1, params["_a"][rows], params["_e"][rows]).any(axis=1)
        if self.n_circ:
            cc = geometry.circle_clearance(p0, p1, params["circles"][rows]).min(axis=(1, 2)) - self.agent_radius
            clear[rows] = np.minimum(clear[rows], cc)
            collision[rows] |= cc < 0.0

    # ------------------------------------------------------------------ the batched compiled step
    def _build_kernel_batch(self) -> None:
        """Constants of ``_step_batch``: the step's linear part, rows [x, a, mem (, ref)] to columns [x', mem',
        pos', vel'], as its distinct columns ``_Mc`` (``_Mc_csc``: their nonzeros) and the map ``_take`` back; the
        sensing mode."""
        self._kbatch = _kernel.AVAILABLE
        if not self._kbatch:
            return
        n, d, nl, cols = self.n, self.d, self.n_l, self._cols
        names = ("x", "mem", "pos", "vel")
        mk = np.concatenate([self._M[:, cols[k]] for k in names], axis=1)
        zc = self.n * self.q + nl * self.p + self.mem_dim
        self._k_ref = bool(np.any(mk[zc:]))  # the exogenous row ref enters x' (never for the offered laws)
        mk = mk if self._k_ref else mk[:zc]
        widths = [cols[k].stop - cols[k].start for k in names]  # the column blocks _kernel.linear_rows writes
        assert widths == [n * self.q, self.mem_dim, n * d, n * d], widths
        # distinct columns only: pos' and vel' are columns of x' for the integrators
        uniq, take = np.unique(mk, axis=1, return_inverse=True)
        self._Mc = uniq
        csc = sp.csc_array(uniq)  # its nonzeros column by column, rows increasing, for _kernel.linear_rows
        csc.sort_indices()
        self._Mc_csc = tuple(
            np.ascontiguousarray(v, dtype=t)
            for v, t in ((csc.indptr, np.int64), (csc.indices, np.int64), (csc.data, np.float64))
        )
        self._take = take = np.ascontiguousarray(take.reshape(-1), dtype=np.int64)
        # where every entry of [pos', vel'] is a column of x' (the integrators), the kernel copies it from x'
        nx, first = n * self.q, {}
        for j in range(nx - 1, -1, -1):
            first[int(take[j])] = j
        pv = [first.get(int(c), -1) for c in take[nx + self.mem_dim :]]
        self._pv = np.array(pv if min(pv) >= 0 else [], dtype=np.int64)
        self._hfit = np.hstack([self.fw.positions, np.ones((n, 1))])
        self._box = np.ascontiguousarray(np.stack(self.bounds).astype(np.float64))
        ks = self.obs_dim - self.L1 - 1
        if self._const_sense is not None:
            self._bmode = _kernel.SENSE_CONST
        elif self.n_seg and not self.n_circ and d == 2:
            self._bmode = _kernel.SENSE_WALLS
        else:
            self._bmode = _kernel.SENSE_GIVEN
        self._sense_cache: dict[int, Array] = {}
        self._ks = ks
        self._no_success_test = np.zeros(0, dtype=bool)  # episode_rows: the default success test
        self._no_walls = np.zeros((1, d + 1, 0))
        self._no_walls.setflags(write=False)  # like the params arrays: numba compiles per read-only flag
        self._no_seg = np.zeros((1, 0, 2))  # swept_rows: no walls
        self._no_seg.setflags(write=False)

    def _sense_fill(self, B: int) -> Array:
        """A cached (B, n_l, ks) array of the constant sensing (no obstacles), or a (1, n_l, ks) dummy."""
        key = B if self._bmode == _kernel.SENSE_CONST else 0
        arr = self._sense_cache.get(key)
        if arr is None:
            shape = (max(key, 1), self.n_l, self._ks)
            arr = np.zeros(shape) if self._const_sense is None else np.broadcast_to(self._const_sense, shape).copy()
            self._sense_cache[key] = arr
        return arr

    def _kernel_outputs(self, B: int) -> tuple[NDArray[np.float32], Array, NDArray[np.bool_], Array]:
        """Fresh (obs (B, n_l, obs_dim) float32, dist (B, n_l + 4), flags (B, 2) bool, rew (B, 2 n_l)) for
        ``_kernel.measure_rows`` to fill."""
        nl = self.n_l
        return (
            np.empty((B, nl, self.obs_dim), dtype=np.float32),
            np.empty((B, nl + 4)),
            np.empty((B, 2), dtype=np.bool_),
            np.empty((B, 2 * nl)),
        )

    def _geometry_args(self, pos: Array, params: dict[str, Array]) -> tuple[Any, ...]:
        """The arguments of ``_kernel.measure_rows`` from ``circles`` to ``mode``: the episodes' obstacles and
        thresholds, the engine's constants, and the leaders' sensing (computed here from ``pos`` (B, n, d)
        only when the kernel does not cast the rays itself)."""
        B, nl = pos.shape[0], self.n_l
        if self._bmode == _kernel.SENSE_GIVEN:
            laug = np.concatenate([pos[:, self.leaders], np.ones((B, nl, 1))], axis=2)
            sense = np.ascontiguousarray(self._sense(laug, params))
        else:
            sense = self._sense_fill(B)
        walls = params["_W"] if self.n_seg else self._no_walls
        return (
            params["circles"],
            walls,
            params["_R"] if self._bmode == _kernel.SENSE_WALLS else walls,
            self._thresholds(params),
            self._pairs,
            self.leaders,
            self._perm,
            self.affine._pinv,
            self._hfit,
            self._box,
            self._fast,
            1.0 / self._max_cycles,
            self._lin_lo2,
            self._lin_hi2,
            self._err_hi,
            self._w_tail,
            sense,
            self._bmode,
        )

    def _measure_compiled(
        self, pos: Array, vel: Array, ref: Array, params: dict[str, Array]
    ) -> tuple[NDArray[np.float32], Array, NDArray[np.bool_], Array]:
        """``_kernel.measure_rows`` on positions ``pos`` and velocities ``vel`` (B, n, d) with exogenous row
        ``ref``, nothing moving and no actions (``observe`` and resets): (obs, dist, flags, rew), see the kernel."""
        B = pos.shape[0]
        pos = np.ascontiguousarray(pos)
        out = self._kernel_outputs(B)
        _kernel.run_rows(
            _kernel.measure_rows,
            B,
            self.num_threads,
            pos,
            pos,
            np.ascontiguousarray(vel),
            np.ascontiguousarray(ref),
            np.zeros((B, self.n_l * self.p)),
            np.zeros((B, self.n_l)),
            *self._geometry_args(pos, params),
            *out,
        )
        return out

    def _episode_end(
        self, state: EngineState, ok: NDArray[np.bool_], collision: NDArray[np.bool_], k: NDArray[np.int64]
    ) -> tuple[NDArray[np.int64], NDArray[np.bool_], NDArray[np.bool_], NDArray[np.bool_]]:
        """(streak, success, terminated, truncated), each (B,), from this sample's success test ``ok``, the
        collisions and the new sample count ``k`` (``hold_steps`` successes in a row are a success)."""
        sc = self.scenario
        if sc.hold_steps == 1:
            streak, success = ok.astype(np.int64), ok
        else:
            streak = (state.streak + 1) * ok
            success = streak >= sc.hold_steps
        terminated = collision | success if sc.terminate_on_success else collision
        return streak, success, terminated, (k >= self._max_cycles) > terminated

    def _step_batch(
        self, state: EngineState, actions: ArrayLike
    ) -> tuple[EngineState, NDArray[np.float32], Array, NDArray[np.bool_], NDArray[np.bool_], dict[str, Array]]:
        """``step`` compiled (``_kernel.step_rows``, the envs split over ``num_threads`` threads): per env the
        folded matmul for [x', mem', pos', vel'], then contacts, sensing, observations and the reward's linear
        part from the new positions; then the episode ends and the info arrays in numpy. Equal to the numpy step
        up to rounding (tests), and the same for any number of threads."""
        B, n, d, nl = state.x.shape[0], self.n, self.d, self.n_l
        # validated, not yet clipped: the kernels clip (and square, for the effort) as they read
        af = np.require(self.check_actions(actions, B).reshape(B, -1), np.float64, ("C", "W"))
        params, sc = state.params, self.scenario
        k = state.k + 1
        ref0 = np.ascontiguousarray(state.ref)
        if sc.moving_goal:
            ref = self._ref(params, k)
            ref_o = ref[:, :0]  # the kernel writes no row
        else:
            ref = ref_o = np.empty_like(ref0)  # the old row, k in its last column (written by linear_rows)
        x_o, mem_o = np.empty((B, n * self.q)), np.empty((B, self.mem_dim))
        pos, vel = np.empty((B, n, d)), np.empty((B, n, d))
        mem = np.zeros((B, 0)) if state.memory is None else np.ascontiguousarray(state.memory.reshape(B, -1))
        x = np.ascontiguousarray(state.x.reshape(B, -1))
        lin = (x, af, mem, ref0, k, *self._Mc_csc, self._take, self._pv, x_o, mem_o, ref_o)
        obs, dist, flags, re = out = self._kernel_outputs(B)
        meas = (pos, np.ascontiguousarray(state.pos), vel, ref, af, np.ascontiguousarray(state.goal_dist))
        T = self.num_threads
        rew, gd = np.empty((B, nl)), np.empty((B, nl))
        ends, ec, streak = np.empty((5, B), dtype=np.bool_), np.empty((2, B)), np.empty(B, dtype=np.int64)
        consts = (sc.hold_steps, sc.terminate_on_success, self._max_cycles, *self._w_head)
        if self._bmode != _kernel.SENSE_GIVEN and self._fused_success:  # the whole step in one call, on T threads
            hit = np.zeros(B, dtype=np.bool_)
            walls = (params["_a"], params["_e"]) if self.n_seg else (self._no_seg, self._no_seg)
            swept = (*walls, params["circles"], self.agent_radius, nl + 2, hit)
            end = (self._no_success_test, re, state.streak, k, *consts, rew, ends, *ec, gd, streak)
            measure = (*meas, *self._geometry_args(pos, params), *out)
            _kernel.run_rows(_kernel.step_end_rows, B, T, lin, measure, swept, end)
        else:
            if self._bmode == _kernel.SENSE_GIVEN:  # the sensing needs the new positions first
                _kernel.run_rows(_kernel.linear_rows, B, T, *lin, pos, vel)
                _kernel.run_rows(_kernel.measure_rows, B, T, *meas, *self._geometry_args(pos, params), *out)
            else:
                _kernel.run_rows(_kernel.step_rows, B, T, lin, *meas, *self._geometry_args(pos, params), *out)
            hit = self._false(B)
            if flags[:, 1].any():  # an agent was fast: swept checks (lower the clearance in dist, mark crossings)
                hit = self._swept_compiled(flags, meas[1], pos, params, dist, nl + 2)
                hit.setflags(write=False)  # one array type for the kernel
            ok = self._no_success_test if self._fused_success else sc.is_success(dist[:, nl + 1], dist[:, nl])
            ok_in = np.asarray(ok, dtype=np.bool_)
            _kernel.episode_rows(
                0, B, dist, flags, hit, ok_in, re, state.streak, k, *consts, rew, ends, *ec, gd, streak
            )  # fmt: skip
        success, collision, oob, terminated, truncated = ends
        err, clear = ec
        new = EngineState(
            x_o.reshape(B, n, self.q),
            pos,
            vel,
            mem_o.reshape(B, self.n_f, self.p) if self.mem_dim else None,
            k,
            ref,
            gd,
            err,
            streak,
            params,
        )
        info = self._info(success, collision, oob, err, clear, dist[:, nl + 1], re[:, nl:], k * self.dt)
        return new, obs, rew, terminated, truncated, info

    # ------------------------------------------------------------------ the B = 1 step
    def _build_fast1(self) -> None:
        """Static parts of ``step1``'s compiled path (``_kernel.step1``): the engine's constants packed in one vector
        ``_c1`` and the kernel's layout vector (``_kernel.LAYOUT``: sizes and offsets, those of the episodes' packed
        arrays included, then the agents leaders first)."""
        self._fast1 = (
            _kernel.AVAILABLE and self._fused_success and not self.scenario.moving_goal and self.n <= ALL_PAIRS_UP_TO
        )  # else step1 takes the batched step
        if not self._fast1:
            return
        n, d, nl, S = self.n, self.d, self.n_l, self.n_seg
        cols, M, sc = self._cols, self._M, self.scenario
        consts = {  # c1: the engine's constants, in the order of the c_* offsets of LAYOUT
            "c_M": M,
            "c_G": self._G0,
            "c_wt": self._w_tail,
            "c_lo": self._lin_lo2,
            "c_hi": self._lin_hi2,
            "c_tm": self._theta_map,
            "c_slo": self._state_lo64,
            "c_shi": self._state_hi64,
            "c_sense": self._sense_fill(1)[0],  # (n_l, ks): the constant sensing, or a dummy
            "c_scal": np.array([self._err_hi, 1.0 / self._max_cycles, self.agent_radius, *self._w_head, self.dt]),
        }
        sizes = {  # ep: the episode's arrays, in the order of the e_* offsets (see _pack_episode)
            "e_thr": self._thr0.size,
            "e_walls": (d + 1) * 3 * S,
            "e_rays": 2 * S * self.n_rays if S else 0,
            "e_pvec": sc.param_low.size,
            "e_a": 2 * S,
            "e_e": 2 * S,
            "e_circ": self.n_circ * (d + 1),
        }
        layout = dict(zip(consts, np.cumsum([0] + [a.size for a in consts.values()])[:-1].tolist(), strict=True))
        layout.update(zip(sizes, np.cumsum([0, *sizes.values()])[:-1].tolist(), strict=True))
        self._c1 = np.concatenate([np.ravel(a) for a in consts.values()])
        layout.update(
            kc=self._kc,
            kd=self._kd,
            d=d,
            nl=nl,
            n_seg=S,
            n_rays=self.n_rays,
            L1=self.L1,
            obs_dim=self.obs_dim,
            guard0=cols["guard"].start,
            guard1=cols["guard"].stop,
            obs0=cols["obs"].start,
            laug0=cols["laug"].start,
            q1=self._G0.shape[1],
            walls0=self._g["walls"].start,
            circ0=self._g["circles"].start,
            delta0=self._g["delta"].start,
            perm0=len(_kernel.LAYOUT),
            sense_mode=self._bmode,
            pos0=cols["pos"].start,
            vel0=cols["vel"].start,
            ref0=cols["ref"].start,
            x0=cols["x"].start,
            mem0=cols["mem"].start,
            Z=M.shape[0],
            C=M.shape[1],
            n_circ=self.n_circ,
            kp=sc.param_low.size,
            hold_steps=sc.hold_steps,
            terminate_on_success=int(sc.terminate_on_success),
            max_cycles=self._max_cycles,
        )
        self._layout1 = np.concatenate([[layout[k] for k in _kernel.LAYOUT], self._perm]).astype(np.int64)
        # the fixed shapes of step1's outputs, and its dummies (one compiled signature: the same array types always)
        self._shapes1 = ((1, n, self.q), (1, n, d), (1, 2 * n * d + 2), (1, nl))
        self._no_mem = np.zeros((1, 0, 0))
        self._no_obs = np.zeros((0, self.obs_dim), dtype=np.float32)
        self._no_glob = np.zeros(0, dtype=np.float32)

    def _pack_episode(self, params: dict[str, Array]) -> None:
        """``params["_ep1"]`` (1, E): the episode's arrays for ``step1``, packed in the order of ``LAYOUT``'s e_*
        offsets: the thresholds, the wall and ray maps, the scenario parameters, the wall starts and vectors, the
        circles."""
        parts = [self._thresholds(params), params["_pvec"], params["circles"]]
        if self.n_seg:
            parts[1:1] = [params["_W"], params["_R"]]
            parts[-1:-1] = [params["_a"], params["_e"]]
        ep = np.concatenate([np.ravel(a) for a in parts])[None]
        ep.setflags(write=False)
        params["_ep1"] = ep

    def step1(
        self, state: EngineState, actions: ArrayLike, observe: bool = True
    ) -> tuple[EngineState, NDArray[np.float32] | None, list[float], bool, bool, dict[str, Any]]:
        """One sample of a single env (B = 1), with Python scalars out: what a single-env wrapper needs.

        Args:
            state: a B = 1 state (not modified). actions: leader actions, shape (n_l, p) or (1, n_l, p).
        Returns:
            (state', obs (n_l, obs_dim) float32, rewards (n_l floats), terminated, truncated, info) with
            info's values Python scalars (``control_effort`` a list over leaders), as in ``step``; obs is None
            when ``observe`` is False (the sensing is skipped).

        States from ``reset(rng, 1)`` of static-goal scenarios (n <= ``ALL_PAIRS_UP_TO``, the default success
        test) carry the episode's arrays packed for it (``_pack_episode``) and take a fast path: one compiled call
        (``_kernel.step1``), since at this size numpy's ~1 us per call would be the whole cost. It equals the
        batched step up to rounding (tests). Other states go through ``step``.
        """
        return self._step1(state, actions, _kernel.WANT_OBS if observe else 0)

    def step1_global(
        self, state: EngineState, actions: ArrayLike
    ) -> tuple[EngineState, NDArray[np.float32], list[float], bool, bool, dict[str, Any]]:
        """``step1`` that returns the next state's ``global_state`` (state_dim,) float32 in place of the leaders'
        observations: what a single-agent view of the team needs (``FormationCommander-v0``). On the compiled
        path the same call computes it (the same bits as ``global_state``, tested)."""
        new, g, *rest = self._step1(state, actions, _kernel.WANT_GLOBAL)
        return (new, self.global_state(new)[0] if g is None else g, *rest)  # type: ignore[return-value]

    def _step1(
        self, state: EngineState, actions: ArrayLike, want: int
    ) -> tuple[EngineState, NDArray[np.float32] | None, list[float], bool, bool, dict[str, Any]]:
        """``step1`` with ``want`` (``_kernel.WANT_OBS`` | ``WANT_GLOBAL``): obs is the leaders' observations with
        WANT_OBS, else the global state where the compiled path made it (WANT_GLOBAL), else None."""
        params = state.params
        ep = params.get("_ep1")
        a = np.array(actions, dtype=np.float64)  # a writable copy: the kernel's argument types stay the same
        if ep is None or state.x.shape[0] != 1:
            new, obs, rew, term, trunc, arrays = self.step(state, a.reshape(1, self.n_l, self.p))
            inf1: dict[str, Any] = {key: val[0].item() for key, val in arrays.items() if key != "control_effort"}
            inf1["control_effort"] = arrays["control_effort"][0].tolist()
            o1 = obs[0] if want & _kernel.WANT_OBS else None
            return new, o1, rew[0].tolist(), bool(term[0]), bool(trunc[0]), inf1
        flat = a.reshape(-1)
        nl = self.n_l
        if flat.size != nl * self.p:
            self.check_actions(a if a.ndim == 3 else a[None], 1)  # raises on the shape
        sx, sp, sr, sg = self._shapes1
        mem = state.memory
        mem2 = self._no_mem if mem is None else np.empty(mem.shape)
        x2, pos2, vel2, ref2, gd2 = np.empty(sx), np.empty(sp), np.empty(sp), np.empty(sr), np.empty(sg)
        err2, k2, streak2 = np.empty(1), np.empty(1, dtype=np.int64), np.empty(1, dtype=np.int64)
        obs = np.empty((nl, self.obs_dim), dtype=np.float32) if want & _kernel.WANT_OBS else self._no_obs
        glob = np.empty(self.state_dim, dtype=np.float32) if want & _kernel.WANT_GLOBAL else self._no_glob
        scal = np.empty(_kernel.S1_REW + 2 * nl)
        _kernel.step1(
            state.x,
            self._no_mem if mem is None else mem,
            state.ref,
            state.pos,
            state.goal_dist,
            state.k,
            state.streak,
            flat,
            self._c1,
            ep,
            self._layout1,
            want,
            x2,
            mem2,
            pos2,
            vel2,
            ref2,
            gd2,
            err2,
            k2,
            streak2,
            obs,
            glob,
            scal,
        )
        v = scal.tolist()
        if v[_kernel.S1_BAD]:
            self.check_actions(flat.reshape(1, nl, self.p), 1)  # raises, naming the leader
        if want & _kernel.WANT_OBS and self._bmode == _kernel.SENSE_GIVEN:  # circles or 3D: the batched sensing
            laug = np.concatenate([pos2[:, self.leaders], np.ones((1, nl, 1))], axis=2)
            obs[:, self.L1 + 1 :] = self._sense(laug, params)[0]
        new = EngineState(x2, pos2, vel2, None if mem is None else mem2, k2, ref2, gd2, err2, streak2, params)
        r0 = _kernel.S1_REW
        info = self._info(
            v[_kernel.S1_SUCCESS] != 0.0,
            v[_kernel.S1_COLLISION] != 0.0,
            v[_kernel.S1_OOB] != 0.0,
            v[_kernel.S1_ERR],
            v[_kernel.S1_CLEAR],
            v[_kernel.S1_GOAL],
            v[r0 + nl : r0 + 2 * nl],
            v[_kernel.S1_TIME],
        )
        o1 = obs if want & _kernel.WANT_OBS else (glob if want & _kernel.WANT_GLOBAL else None)
        return new, o1, v[r0 : r0 + nl], v[_kernel.S1_TERM] != 0.0, v[_kernel.S1_TRUNC] != 0.0, info

    # ------------------------------------------------------------------ helpers
    def _info(
        self, success: Any, collision: Any, oob: Any, err: Any, clear: Any, goal_distance: Any, effort: Any, time: Any
    ) -> dict[str, Any]:
        """A step's info (the keys of ``step``'s docstring), arrays over envs or scalars of one env; time: k T (s)."""
        return {
            "success": success,
            "collision": collision,
            "out_of_bounds": oob,
            "formation_error": err,
            "min_clearance": clear,
            "goal_distance": goal_distance,
            "control_effort": effort,
            "time": time,
        }

    def affine_targets(self, state: EngineState) -> Array:
        """Where the law drives every agent: leaders where they are, followers at L x_l (Lemma 2), (B, n, d)."""
        out = state.pos.copy()
        out[:, self.followers] = np.einsum("fl,bld->bfd", self.law.part.localisation, state.pos[:, self.leaders])
        return out

    def frame(self, state: EngineState, b: int = 0, trail: Array | None = None, text: str = "") -> dict[str, Any]:
        """The renderer's frame dict for batch entry ``b`` (keys: ``rendering.FRAME_KEYS``)."""
        t = float(state.k[b] * self.dt)
        gd = float(np.max(np.linalg.norm(state.goal[b] - state.pos[b], axis=-1)))
        status = text or f"{self.scenario_name}  t={t:.1f} s  formation error {state.err[b]:.3f} m  goal {gd:.2f} m"
        return {
            "positions": state.pos[b],
            "leaders": self.leaders,
            "edges": self.fw.edge_array(),
            "targets": self.affine_targets(state)[b],
            "obstacles": {"segments": state.params["segments"][b], "circles": state.params["circles"][b]},
            "goal": state.goal[b],
            "trail": np.zeros((0, self.n, self.d)) if trail is None else trail,
            "bounds": self.bounds,
            "agent_radius": self.agent_radius,
            "text": status,
            "time": t,
        }

    @staticmethod
    def concat(states: list[EngineState]) -> EngineState:
        """Join states along the batch dim (e.g. B = 1 resets into one batch), in order."""
        first = states[0]
        keys = [kk for kk in first.params if kk != "_ep1" or len(states) == 1]  # _ep1: the B = 1 step's only
        params = {kk: np.concatenate([s.params[kk] for s in states]) for kk in keys}
        for arr in params.values():
            arr.setflags(write=False)

        def cat(name: str) -> Any:
            return None if getattr(first, name) is None else np.concatenate([getattr(s, name) for s in states])

        return EngineState(
            cat("x"),
            cat("pos"),
            cat("vel"),
            cat("memory"),
            cat("k"),
            cat("ref"),
            cat("goal_dist"),
            cat("err"),
            cat("streak"),
            params,
        )

    def select(self, state: EngineState, index: ArrayLike) -> EngineState:
        """The sub-batch ``index`` of ``state`` (for tests and vectorised resets)."""
        idx = np.atleast_1d(np.asarray(index))
        params = {kk: vv[idx] for kk, vv in state.params.items()}
        for arr in params.values():
            arr.setflags(write=False)
        return EngineState(
            state.x[idx],
            state.pos[idx],
            state.vel[idx],
            None if state.memory is None else state.memory[idx],
            state.k[idx],
            state.ref[idx],
            state.goal_dist[idx],
            state.err[idx],
            state.streak[idx],
            params,
        )
