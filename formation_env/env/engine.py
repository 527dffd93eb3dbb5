"""The batched formation engine: one pure ``step(state, actions)`` for every batch size and swarm size.

Every array starts with the batch dim B (VMAS style), so the PettingZoo env (B = 1), ``FormationVecEnv``
(B in the thousands) and large swarms (n up to 10,000 with a sparse stress) run this one step. The engine
holds only constants; the state is passed in and a new one returned (gymnax style). Randomness comes only
from the generators given to :meth:`Engine.reset` and :meth:`Engine.step` (observation noise).

One step, in order (``docs/architecture.md`` has the picture), compiled by :mod:`~formation_env.env.kernel`:
the followers' law and the sampled dynamics (:mod:`~formation_env.env.config`); the obstacles' capsules at the
new time (:mod:`~formation_env.env.obstacles`); contacts; goal distances, the affine fit, success and the
episode end; then the rewards and the observations.
"""

from __future__ import annotations

import math
import operator
import warnings
from collections.abc import Sequence
from typing import Any

import numba
import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray

from formation_env.core.affine import AffineImage
from formation_env.core.dynamics import LinearDynamics
from formation_env.core.errors import ControlDimension, FormationError, StabilityWarning
from formation_env.core.framework import Framework
from formation_env.core.network import NETWORK_LAWS, Network, check_network, check_network_law
from formation_env.core.validation import as_array, check_mapping

from . import config
from .config import DYNAMICS, FOLLOWER_LAWS, check_combination, offered_combinations, resolve_dynamics
from .kernel import (
    FLAG_COLLISION,
    FLAG_OOB,
    FLAG_SUCCESS,
    FLAG_TERMINATED,
    FLAG_TRUNCATED,
    NOMINAL_OUTPUTS,
    Consts,
    Episode,
    NetConsts,
    Outputs,
    compose,
    fit_rows,
    step_inputs,
)
from .network import NetworkSetup, network_seeds
from .observations import DEFAULT_OBSERVATION, Observer
from .obstacles import Capsules, ray_directions
from .rewards import REWARD_TERMS, TERMS
from .scenarios import REGISTRY
from .scenarios._base import Scenario, affine_batch, check_number
from .state import EngineState, StepContext, StepInfo

__all__ = [
    "DYNAMICS",
    "FOLLOWER_LAWS",
    "INFO_KEYS",
    "REWARD_TERMS",
    "Engine",
    "EngineState",
    "StepInfo",
    "check_combination",
    "offered_combinations",
    "resolve_dynamics",
]

Array = NDArray[np.float64]

#: Above this many agents, agent-agent contacts are checked along the graph's edges only.
ALL_PAIRS_UP_TO = 64
#: From this batch size on, the compiled step runs its rows on numba's threads, if numba has more than one.
PARALLEL_FROM = 64
#: Placeholders of the compiled step's optional inputs (no law state given, no observation noise).
_NO_STATE = np.zeros((0, 0, 0))
_NO_NOISE = np.zeros((0, 0, 0))
#: What :meth:`Engine.advance` can observe of the new state: the leaders' observations or the global state's blocks.
OBSERVE = ("leaders", "state")
#: The fields of ``EngineState`` but ``params``.
_FIELDS = tuple(f for f in EngineState._fields if f != "params")
#: The state's fields the compiled step takes, in its argument order (``kernel.step_inputs``), without and with a
#: network.
_STATE_SPECS = {net: step_inputs(net) for net in (False, True)}
_STATE_ARGS = {net: operator.attrgetter(*(spec.state for spec in specs)) for net, specs in _STATE_SPECS.items()}
_MEMORY_AT = [spec.state for spec in _STATE_SPECS[False]].index("memory")  # the same with a network
#: The outputs a step without a network does not return.
_NO_NET_OUT = (None,) * (len(Outputs._fields) - len(NOMINAL_OUTPUTS))
#: What a networked step gets for a state field that is None (no jitter): an empty array.
_PLACEHOLDERS: dict[str, Any] = {"net_time": np.zeros(0)}
#: The info entries of a step (arrays (B,) from :meth:`Engine.step`), with their units.
INFO_KEYS: dict[str, str] = {
    "success": "bool",
    "collision": "bool",
    "out_of_bounds": "bool",
    "formation_error": "m",
    "min_clearance": "m",
    "goal_distance": "m",
    "time": "s",
    "control_effort": "(m/s)^2 or (m/s^2)^2, per leader",
    "lost_fraction": "1, lost link samples / all link samples into the followers since the reset (0 without loss)",
}


class Engine:
    """Scenario + framework + dynamics + follower law + observation + rewards, stepped in batches.

    Args:
        scenario: a ``scenarios.REGISTRY`` name.
        dynamics: ``"single_integrator"`` | ``"double_integrator"`` | a ``LinearDynamics`` (every agent).
        follower_law: one of ``FOLLOWER_LAWS``; the followers run it inside the engine.
        dt: sampling period T (s).
        max_cycles: samples per episode before truncation.
        framework: a framework name, a ``Framework`` (2D or 3D), or None for the scenario's default.
        omega: stress matrix (n, n), dense or scipy.sparse (None: the named one, or designed).
        law_params: parameters of the law (``make_law``: gain, K, Q, eps, rounds); defaults in ``config``.
        u_max: leader input limit per axis: action 1 means u_max (m/s single, m/s^2 double integrator).
        agent_radius: agent disc (ball) radius (m).
        n_rays: 2D range-sensor rays per leader. n_nearest: 3D nearest obstacles sensed per leader.
        sensor_range: obstacle sensing range (m).
        max_speed: velocity bound (m/s) of observations and state (values beyond are clipped).
        reward_weights: overrides of the scenario's reward weights (keys ``rewards.TERMS``).
        observation: the observation blocks, in order (``observations.OBS_BLOCKS``; None: ``formation_v0``'s).
        state_blocks: observation blocks of every leader (noise-free) appended to the global state, leader by
            leader (none by default): a commander then reads what the leaders sense, e.g. ``("obstacles",)``.
        k_nearest: agents in the ``nearest_agents`` block.
        sense_radius: how far a leader sees other agents (``nearest_agents``) and obstacles (m; None: no limit
            beyond ``sensor_range``).
        obs_noise: standard deviation of Gaussian noise added to the measurement blocks (each entry's units).
        network: a communication network between the agents (``core.network.Network`` or a dict of its fields;
            None: perfect): delay, packet loss, jitter, quantisation of what the followers receive, applied in the
            compiled step (``env.network``; docs/networks.md, "In the env"). Needs follower_law ``linear`` (or
            ``stationary`` with single integrators); each copy's draws come from a generator seeded at the reset.
        **scenario_kwargs: the scenario's own arguments (unknown ones raise TypeError).

    Contacts (collisions): two agents closer than 2 radii, an agent centre within one radius of an obstacle's
    surface, an agent centre outside the world box. They are judged at the samples, and along the whole step
    (the agent's straight motion relative to each obstacle) in an env where the largest move of an agent plus
    that of an obstacle along an axis exceeds 2 radii / sqrt(d) in that step, so that nothing fast tunnels
    through a wall or past a moving disc.
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
        observation: Sequence[str] | None = None,
        state_blocks: Sequence[str] = (),
        k_nearest: int = 3,
        sense_radius: float | None = None,
        obs_noise: float = 0.0,
        network: Network | dict[str, Any] | None = None,
        **scenario_kwargs: Any,
    ) -> None:
        if not isinstance(scenario, str) or scenario not in REGISTRY:
            raise FormationError(f"unknown scenario {scenario!r}; choose one of {sorted(REGISTRY)}")
        check_number("dt", dt)
        check_number("max_cycles", max_cycles, integer=True)
        for nm, val in (("u_max", u_max), ("sensor_range", sensor_range), ("max_speed", max_speed)):
            check_number(nm, val)
        check_number("agent_radius", agent_radius, positive=False)
        for nm, val in (("n_rays", n_rays), ("n_nearest", n_nearest), ("k_nearest", k_nearest)):
            check_number(nm, val, integer=True)
        check_number("obs_noise", obs_noise, positive=False)
        if sense_radius is not None:
            check_number("sense_radius", sense_radius)
        law_params = check_mapping(law_params, "law_params")
        reward_weights = check_mapping(reward_weights, "reward_weights")
        for arg, names in (("observation", observation), ("state_blocks", state_blocks)):
            if names is not None and (
                isinstance(names, str)
                or not isinstance(names, Sequence)
                or not all(isinstance(name, str) for name in names)
            ):
                raise TypeError(f"{arg} must be a sequence of block names (or None), got {names!r}")
        self.scenario_name = scenario
        cls = REGISTRY[scenario]
        fw, om = config.resolve_framework(framework, omega, cls.default_framework)
        self.fw, self.omega = fw, om
        self.sparse = sp.issparse(om)
        self.dynamics = dyn = resolve_dynamics(dynamics, fw.d)
        check_combination(follower_law, dyn)
        self.network = _checked_network(network, follower_law)
        self.follower_law = follower_law
        self.dt = float(dt)
        self.max_cycles = int(max_cycles)
        self.u_max = float(u_max)
        self.agent_radius = float(agent_radius)
        self.sensor_range = float(sensor_range)
        self.scenario: Scenario = cls(fw, agent_radius=self.agent_radius, horizon=self.dt * self.max_cycles,
                                      **scenario_kwargs)  # fmt: skip
        self.reward_weights = self._weights(reward_weights)
        #: The reward terms the compiled step computes (nonzero at construction), in the order of its weights.
        self._terms = [name for name, w in self.reward_weights.items() if w != 0.0]

        n, d, q, p = fw.n, fw.d, dyn.q, dyn.p
        self.n: int = n
        self.d: int = d
        self.q: int = q
        self.p: int = p
        self.leaders = np.asarray(fw.leaders, dtype=np.int64)
        self.followers = np.asarray(fw.followers, dtype=np.int64)
        self.n_l: int = int(self.leaders.size)
        self.n_f: int = int(self.followers.size)
        self.other_leaders = np.array([[j for j in range(self.n_l) if j != i] for i in range(self.n_l)], dtype=np.int64)
        self.kind = "double_integrator" if dyn.name == "double_integrator" else "general"
        if dyn.is_single_integrator:
            self.kind = "single_integrator"
        lp = dict(law_params or {})
        self.law, self._M, rho = config.make_follower_law(om, fw.leaders, dyn, follower_law, self.dt, lp)
        self.law_params = lp
        #: The network's constants and loop (None without a network).
        self._net = NetworkSetup.build(self.network, self.law, dyn, self.dt) if self.network is not None else None
        #: The env time is the sum of the drawn periods (state ``net_time``), not k T.
        self._timed = self.network is not None and self.network.jitter is not None
        over = ""
        if self._net is not None and self.network is not None:
            from formation_env.core.analysis import network_stability

            net_rho = network_stability(self.law.part, dyn, self.dt, self._net.loop.G, self.network)
            rho = rho if net_rho is None else net_rho  # None: beyond the analysed size
            over = f" over {self.network} (decay factor per sample)"
        self.spectral_radius = rho
        if rho >= 1.0:
            warnings.warn(
                f"follower_law={follower_law!r} at dt={dt} is unstable on this framework{over}: spectral radius "
                f"{rho:.4g} >= 1 (see formation_env.core.analysis.stability_report)",
                StabilityWarning,
                stacklevel=2,
            )
        self._C_T = np.ascontiguousarray(dyn.C.T)
        self._vel_from_state = not dyn.discrete and not np.any(dyn.C @ dyn.B)  # velocity is C A x
        self._CA_T = np.ascontiguousarray((dyn.C @ dyn.A).T) if self._vel_from_state else None
        self._at_rest = np.linalg.pinv(dyn.C).T  # x at rest from positions
        self.affine = AffineImage(fw.positions)
        self._pinv = np.ascontiguousarray(self.affine._pinv)  # (d + 1, n)
        self.v_bound: float = max(float(max_speed), self.u_max if self.kind == "single_integrator" else 0.0)
        for term, weight in self.reward_weights.items():
            kinds = TERMS[term].kinds
            if weight != 0.0 and kinds is not None and self.kind not in kinds:
                raise FormationError(
                    f"reward_weights[{term!r}] is defined for {' and '.join(kinds)} agents only, not {self.kind} "
                    "ones: give it weight 0"
                )
        self.bounds: Array = self.scenario.bounds
        self.n_rays: int = int(n_rays)
        self.n_nearest: int = int(n_nearest)
        self.k_nearest: int = int(k_nearest)
        self.ray_dirs = ray_directions(self.n_rays) if d == 2 else np.zeros((0, d))
        self.sense_radius = math.inf if sense_radius is None else float(sense_radius)
        self.obstacle_range = min(self.sensor_range, self.sense_radius)
        self.obstacles = self.scenario.obstacles
        self._moving = [ob for ob in self.obstacles if ob.moves()]
        pairs = np.stack(np.triu_indices(n, 1), axis=1) if n <= ALL_PAIRS_UP_TO else fw.edge_array()
        #: The agent pairs (pair_i[k], pair_j[k]) checked for contact (all up to ALL_PAIRS_UP_TO agents, else edges).
        self.pair_i, self.pair_j = (np.ascontiguousarray(pairs[:, c], dtype=np.int64) for c in (0, 1))
        if self.pair_i.size:
            gaps = np.linalg.norm(fw.positions[self.pair_i] - fw.positions[self.pair_j], axis=1)
            if gaps.min() < 2.0 * self.agent_radius:
                warnings.warn(
                    f"agents touch in the nominal formation: the closest pair is {gaps.min():.3g} m apart, less than "
                    f"2 agent_radius = {2 * self.agent_radius:.3g} m; every episode would start in a collision "
                    "(pass a smaller agent_radius)",
                    stacklevel=2,
                )
        self.observer = Observer(self, tuple(DEFAULT_OBSERVATION if observation is None else observation),
                                 float(obs_noise))  # fmt: skip
        self.obs_blocks = self.observer.slices
        self.obs_dim = self.observer.dim
        self.obs_low = self.observer.low.astype(np.float32)
        self.obs_high = self.observer.high.astype(np.float32)
        self.state_observer = Observer(self, tuple(state_blocks), 0.0, "state_blocks") if state_blocks else None
        self._build_state_bounds()
        self._compiled: tuple[Array, Any, Any] | None = None
        self._consts: Consts | None = None
        self._net_consts: NetConsts | None = None
        self._compose()  # every component's parameters are checked now, not at the first step

    # ------------------------------------------------------------------ construction
    def _weights(self, overrides: dict[str, float] | None, arg: str = "reward_weights") -> dict[str, float]:
        """The reward weights: the terms' defaults, then the scenario's, then ``overrides`` (the argument ``arg``,
        which errors name)."""
        weights = {name: t.weight for name, t in TERMS.items()}
        for source, given in (("scenario", self.scenario.weights), (arg, overrides or {})):
            for key, val in given.items():
                if key not in TERMS:
                    raise TypeError(f"{source} got unknown reward term {key!r}; terms are {list(TERMS)}")
                if isinstance(val, bool) or not isinstance(val, (int, float, np.integer, np.floating)):
                    raise TypeError(f"{source}[{key!r}] must be a number, got {type(val).__name__}")
                if not math.isfinite(val):
                    raise FormationError(f"{source}[{key!r}] must be finite, got {val}")
                weights[key] = float(val)
        return weights

    def set_reward_weights(self, weights: dict[str, float]) -> None:
        """Change the weights of reward terms this engine composed (nonzero at construction), in place: the next
        step pays the new weights, with no recompilation (a curriculum on the reward, e.g. a collision penalty
        that grows during training). Terms with weight 0 at construction are not in the compiled step: giving one
        a weight here is an error (construct the engine with it nonzero). Every weight is checked before any changes.

        Args:
            weights: ``{term: weight}``, each a finite number (0 switches a composed term off).
        """
        weights = check_mapping(weights, "weights")
        new = self._weights(weights, "weights")
        off = [k for k in weights if new[k] != 0.0 and k not in self._terms]
        if off:
            raise FormationError(
                f"weights: reward term(s) {off} had weight 0 at construction, so the compiled step does not compute "
                "them; construct the engine with them nonzero (reward_weights) to schedule them"
            )
        for key in weights:
            self.reward_weights[key] = new[key]
        if self._compiled is not None:
            self._compiled[0][:] = [self.reward_weights[t] for t in self._terms]

    def _build_state_bounds(self) -> None:
        n, d = self.n, self.d
        lo_w, hi_w = self.bounds
        v, emax = self.v_bound, float(np.linalg.norm(hi_w - lo_w))
        sc = self.scenario
        lo: list[ArrayLike] = [np.tile(lo_w, n), np.full(n * d, -v), np.tile(lo_w, n), np.full(n * d, -v), [0.0]]
        hi: list[ArrayLike] = [np.tile(hi_w, n), np.full(n * d, v), np.tile(hi_w, n), np.full(n * d, v), [emax]]
        lo += [np.full(d * d, -self.theta_clip), sc.param_low]
        hi += [np.full(d * d, self.theta_clip), sc.param_high]
        probe = sc.reset(np.random.default_rng(0), 1)
        for ob in self.obstacles:
            o_lo, o_hi = ob.state_bounds(probe[ob.key].shape[1], d, self.bounds)
            lo.append(o_lo)
            hi.append(o_hi)
        lo.append([0.0])
        hi.append([1.0])
        if self.state_observer is not None:
            lo.append(np.tile(self.state_observer.low, self.n_l))
            hi.append(np.tile(self.state_observer.high, self.n_l))
        self.state_low = np.concatenate(lo).astype(np.float32)
        self.state_high = np.concatenate(hi).astype(np.float32)
        self._state_lo64 = self.state_low.astype(np.float64)
        self._state_hi64 = self.state_high.astype(np.float64)
        self.state_dim = int(self.state_low.size)

    # ------------------------------------------------------------------ reset
    def reset(self, rng: np.random.Generator, B: int = 1) -> EngineState:
        """Draw B new episodes from ``rng``: agents at rest on the scenario's start, law memory empty."""
        if isinstance(B, bool) or not isinstance(B, (int, np.integer)) or B < 1:
            raise FormationError(f"batch size B must be a positive integer, got {B!r}")
        if not isinstance(rng, np.random.Generator):
            raise TypeError(f"rng must be a np.random.Generator, got {type(rng).__name__}")
        params = self.scenario.reset(rng, int(B))
        return self._start(params, network_seeds(rng, int(B)) if self._net is not None else None)

    def reset_each(self, rngs: Sequence[np.random.Generator]) -> EngineState:
        """One new episode per generator, batched: entry b equals ``reset(rngs[b], 1)`` (the same draws; for
        vectorised envs whose copies are seeded one by one)."""
        params = self.scenario.reset_each(rngs)
        return self._start(params, network_seeds(list(rngs), len(rngs)) if self._net is not None else None)

    def _start(self, params: dict[str, Array], seeds: NDArray[np.int64] | None = None) -> EngineState:
        start = np.array(params.pop("start"), dtype=np.float64)
        B = start.shape[0]
        static = [ob.capsules(params[ob.key], np.zeros(B), self.bounds) for ob in self.obstacles if not ob.moves()]
        caps = Capsules.join(static, B, self.d)
        params["_ca"], params["_ce"], params["_cr"] = (np.ascontiguousarray(f) for f in caps)
        params["_pvec"] = np.ascontiguousarray(self.scenario.param_vector(params), dtype=np.float64)
        params["_goal_p"] = np.ascontiguousarray(self.scenario.goal_vector(params), dtype=np.float64)
        for ob in self._moving:
            params[ob.key] = np.ascontiguousarray(params[ob.key], dtype=np.float64)
        for arr in params.values():
            arr.setflags(write=False)
        k = np.zeros(B, dtype=np.int64)
        goal, goal_vel = self._goal(params, k)
        gd = np.sqrt(np.einsum("bnd,bnd->bn", goal - start, goal - start))
        x = start @ self._at_rest
        net: dict[str, Any] = {}
        if self._net is not None and seeds is not None:
            params["_net_seed"] = seeds  # type: ignore[assignment]  # int64 seeds among the float params
            seeds.setflags(write=False)
            net = self._net.initial(x, seeds)
        return EngineState(
            x=x,
            pos=start,
            vel=np.zeros_like(start),
            memory=self.law.initial_memory((B,)),
            k=k,
            goal=goal,
            goal_vel=goal_vel,
            goal_dist=np.ascontiguousarray(gd[:, self.leaders]),
            err=self._fit(start)[2],
            streak=np.zeros(B, dtype=np.int64),
            params=params,
            **net,
        )

    # ------------------------------------------------------------------ parts of the step
    def _goal(self, params: dict[str, Array], k: NDArray[np.int64]) -> tuple[Array, Array]:
        """Goal positions x*(k T) (B, n, d) and their velocity (x*((k+1) T) - x*(k T)) / T (zero if static)."""
        sc = self.scenario
        if not sc.moving_goal:
            g = affine_batch(sc.r, params["goal_theta"], params["goal_b"])
            return g, np.zeros_like(g)
        t = self.dt * k.astype(np.float64)
        g0 = affine_batch(sc.r, *sc.reference(params, t))
        g1 = affine_batch(sc.r, *sc.reference(params, t + self.dt))
        return g0, (g1 - g0) * (1.0 / self.dt)

    def capsules(self, params: dict[str, Array], k: NDArray[np.int64], t: Array | None = None) -> Capsules:
        """Every obstacle's capsules after k samples (B,): the static ones of the episode and the moving ones
        at t = k T (or at the given env times t (B,) s, under jitter: :meth:`time`)."""
        static = Capsules(params["_ca"], params["_ce"], params["_cr"])
        if not self._moving:
            return static
        parts = [static] if static.a.shape[1] else []
        t = self.dt * k.astype(np.float64) if t is None else t
        parts += [ob.capsules(params[ob.key], t, self.bounds) for ob in self._moving]
        return Capsules.join(parts, k.shape[0], self.d)

    def _fit(self, pos: Array) -> tuple[Array, Array, Array]:
        """Least-squares affine fit of positions (B, n, d): Theta (B, d, d), b (B, d), RMS residual (B,) m."""
        return fit_rows(self.fw.positions, self._pinv, np.ascontiguousarray(pos))

    def __getstate__(self) -> dict[str, Any]:
        """Everything but the compiled step (a module), which the copy composes again on its first step."""
        return {**self.__dict__, "_compiled": None, "_consts": None, "_net_consts": None}

    # ------------------------------------------------------------------ the compiled step
    def _compose(self) -> tuple[Array, Any, Any]:
        """The reward weights of the composed terms, the compiled step's module observing the leaders and the one
        observing the global state's blocks (``advance(observe="state")``; its ``observe`` serves
        :meth:`global_state`): :func:`~formation_env.env.kernel.compose` of this engine's components."""
        if self._compiled is None:
            terms = self._terms
            mod = self._module(self.observer, terms)
            smod = self._module(self.state_observer, terms)
            self._compiled = (np.array([self.reward_weights[t] for t in terms]), mod, smod)
        return self._compiled

    def _module(self, observer: Observer | None, terms: Sequence[str]) -> Any:
        """The compiled module of this engine's step whose observation is ``observer``'s blocks (None: no
        observation at all), with the reward ``terms``."""
        sc = self.scenario
        blocks = []
        if observer is not None:
            blocks = [(blk.name, blk.row if blk.name != "task" else sc.task_row, observer.slices[blk.name].start)
                      for blk in observer.blocks]  # fmt: skip
        return compose(blocks, [(t, TERMS[t].row) for t in terms], sc.route_row, [ob.row for ob in self._moving],
                       sc.pose_row, network=self._net is not None, timed=self._timed)  # fmt: skip

    def _state_kernel(self) -> tuple[Consts, Any]:
        """The constants and module of the step that observes the global state's blocks in place of the leaders'
        observations (``advance(observe="state")``)."""
        c, _ = self._kernel()
        return self._state_consts(c), (self._compiled or self._compose())[2]

    def _state_consts(self, c: Consts) -> Consts:
        """``c`` with the state blocks' bounds and no noise (no blocks: empty bounds)."""
        so = self.state_observer
        if so is None:
            return c._replace(obs_low=np.zeros(0), obs_high=np.zeros(0), noise_mask=np.zeros(0))
        return c._replace(obs_low=so.low, obs_high=so.high, noise_mask=so.noise_mask)

    def _kernel(self) -> tuple[Consts, Any]:
        """The constants of the compiled step and its module (composed once per engine; the constants again
        when ``max_cycles`` changed)."""
        weights, mod, _ = self._compiled or self._compose()
        if self._consts is None or self._consts.max_cycles != self.max_cycles:
            d = self.d
            self._consts = Consts(
                leaders=self.leaders, others=self.other_leaders, pair_i=self.pair_i, pair_j=self.pair_j,
                r=self.fw.positions, pinv=self._pinv, law=self._M if self._M is not None else np.zeros((0, 0)),
                c_t=self._C_T, ca_t=self._CA_T if self._CA_T is not None else np.zeros((0, d)), bounds=self.bounds,
                ray_dirs=self.ray_dirs, obs_low=self.observer.low, obs_high=self.observer.high,
                noise_mask=self.observer.noise_mask, weights=weights, dt=self.dt, u_max=self.u_max,
                radius=self.agent_radius, fast=2.0 * self.agent_radius / math.sqrt(d), goal_tol=self.scenario.goal_tol,
                formation_tol=self.scenario.formation_tol, v_bound=self.v_bound, obstacle_range=self.obstacle_range,
                sense_radius=self.sense_radius, max_cycles=self.max_cycles, hold_steps=self.scenario.hold_steps,
                n_nearest=self.n_nearest, k_nearest=self.k_nearest,
                end_on_success=self.scenario.terminate_on_success,
            )  # fmt: skip
            self._net_consts = NetConsts(**self._net.consts) if self._net is not None else None
        return self._consts, mod

    def _noise(self, B: int, rng: np.random.Generator | Sequence[np.random.Generator] | None) -> Array:
        """Observation noise (B, n_l, obs_dim) drawn from ``rng`` (or one generator per env), or none."""
        if self.observer.noise <= 0.0 or rng is None:
            return _NO_NOISE
        shape = (self.n_l, self.obs_dim)
        if isinstance(rng, np.random.Generator):
            return rng.normal(0.0, self.observer.noise, (B, *shape))
        return np.stack([g.normal(0.0, self.observer.noise, shape) for g in rng])  # env b draws as alone

    def _args(self, c: Consts, state: EngineState, a: Array, x1: Array, mem1: Array, noise: Array) -> tuple[Any, ...]:
        p = state.params
        mov = tuple([p[ob.key] for ob in self._moving]) if self._moving else ()
        ep = Episode(p["_pvec"], p["_ca"], p["_ce"], p["_cr"], mov, p["_goal_p"])
        net = self._net_consts is not None
        given = _STATE_ARGS[net](state)
        if state.memory is None:  # an empty array stands for no memory
            given = (*given[:_MEMORY_AT], np.zeros((state.x.shape[0], 0, 0)), *given[_MEMORY_AT + 1 :])
        if net and state.net_time is None:  # nor for no jitter
            specs = _STATE_SPECS[net]
            given = tuple(_PLACEHOLDERS[sp.state] if v is None else v for sp, v in zip(specs, given, strict=True))
        if net:
            return (c, self._net_consts, ep, *given, a, x1, mem1, noise)
        return (c, ep, *given, a, x1, mem1, noise)

    # ------------------------------------------------------------------ the API
    def observe(
        self, state: EngineState, rng: np.random.Generator | Sequence[np.random.Generator] | None = None
    ) -> NDArray[np.float32]:
        """Observations of every leader, shape (B, n_l, obs_dim), float32 (layout: ``obs_blocks``)."""
        c, mod = self._kernel()
        B = state.batch_size
        acts = np.zeros((B, self.n_l, self.p))
        return mod.observe(*self._args(c, state, acts, _NO_STATE, _NO_STATE, self._noise(B, rng)))[0]

    def check_actions(self, actions: ArrayLike, B: int) -> Array:
        """Actions as float64 (B, n_l, p); raise ValueError naming the leader on NaN or inf."""
        a = as_array(actions, "actions", finite=False)
        if a.shape != (B, self.n_l, self.p):
            raise ControlDimension(f"actions must have shape (B, n_l, p) = ({B}, {self.n_l}, {self.p}), got {a.shape}")
        bad = ~np.isfinite(a).all(axis=-1)
        if bad.any():
            b, i = np.argwhere(bad)[0]
            raise ValueError(
                f"action of leader_{i} (batch entry {b}) holds NaN or inf: {a[b, i].tolist()}; the state is unchanged"
            )
        return a

    def step(
        self,
        state: EngineState,
        actions: ArrayLike,
        rng: np.random.Generator | Sequence[np.random.Generator] | None = None,
    ) -> tuple[EngineState, NDArray[np.float32], Array, NDArray[np.bool_], NDArray[np.bool_], dict[str, NDArray[Any]]]:
        """One sample of every environment: :meth:`advance`, and every leader's observation of the new state."""
        new, ctx, rew, terminated, truncated, info = self.advance(state, actions, rng)
        assert ctx.obs is not None  # observe="leaders"
        return new, ctx.obs, rew, terminated, truncated, info

    def advance(
        self,
        state: EngineState,
        actions: ArrayLike,
        rng: np.random.Generator | Sequence[np.random.Generator] | None = None,
        observe: str = "leaders",
    ) -> tuple[EngineState, StepContext, Array, NDArray[np.bool_], NDArray[np.bool_], dict[str, NDArray[Any]]]:
        """One sample of every environment (the compiled step of :mod:`~formation_env.env.kernel`).

        Args:
            state: the current state (not modified).
            actions: leader actions in [-1, 1], shape (B, n_l, p); values outside are clipped, NaN or inf raise
                ValueError (and nothing changes).
            rng: the generator of observation noise (needed only with ``obs_noise`` > 0), or one per env.
            observe: what the step observes of the new state: ``"leaders"``, every leader's observation
                (``StepContext.obs``); ``"state"``, the global state's blocks (``StepContext.blocks``, the
                ``state_blocks`` of every leader, None without them; no leader observation is computed and no
                noise drawn): what a commander reads, which :meth:`global_state` then takes from the context.
        Returns:
            (state', the step's :class:`StepContext` (observations and affine fit), rewards (B, n_l),
            terminated (B,), truncated (B,), info) with the arrays (B,) of ``INFO_KEYS`` (control_effort
            (B, n_l): |u_i|^2); :meth:`step` returns the observations (B, n_l, obs_dim) float32 in the
            context's place.
        """
        if not isinstance(state, EngineState):
            raise TypeError(f"state must be an EngineState (from reset), got {type(state).__name__}")
        if observe not in OBSERVE:
            raise FormationError(f"observe must be one of {list(OBSERVE)}, got {observe!r}")
        B = state.batch_size
        a = np.array(self.check_actions(actions, B), dtype=np.float64)
        leaders = observe == "leaders"
        c, mod = self._kernel() if leaders else self._state_kernel()
        x1: Array = _NO_STATE
        mem1: Array = _NO_STATE
        if self._M is None and self._net is None:  # sparse stress: the core law itself, then the compiled rest
            x1, law_mem = self.law.step(state.x, self.u_max * np.clip(a, -1.0, 1.0), state.memory)
            mem1 = _NO_STATE if law_mem is None else law_mem
        args = self._args(c, state, a, x1, mem1, self._noise(B, rng) if leaders else _NO_NOISE)
        threaded = B >= PARALLEL_FROM and numba.get_num_threads() > 1
        raw, obs, rew = (mod.step_parallel if threaded else mod.step)(*args)
        out: Any = Outputs._make(raw if self._net is not None else (*raw, *_NO_NET_OUT))  # fields: kernel.ARRAYS
        f = out.flags
        mem = out.mem if state.memory is not None else None
        net: dict[str, Any] = {}
        lost = np.zeros(B)
        if self._net is not None:
            net = {"net_sent": out.sent, "net_corr": out.corr, "net_held": out.held, "net_rng": out.rng,
                   "net_lost": out.lost, "net_time": out.time if self._timed else None}  # fmt: skip
            lost = out.lost / np.maximum(out.k * max(self._net.loop.m, 1), 1)
        new = EngineState(out.x, out.pos, out.vel, mem, out.k, out.goal, out.gvel, out.gdist, out.err, out.streak,
                          state.params, **net)  # fmt: skip
        info = {
            "success": f[:, FLAG_SUCCESS],
            "collision": f[:, FLAG_COLLISION],
            "out_of_bounds": f[:, FLAG_OOB],
            "formation_error": out.err,
            "min_clearance": out.clear,
            "goal_distance": out.gmax,
            "time": out.time if self._timed else out.k * self.dt,
            "control_effort": out.effort,
            "lost_fraction": lost,
        }
        blocks = None if leaders or self.state_observer is None else obs
        ctx = StepContext(obs if leaders else None, out.theta, blocks)
        return new, ctx, rew, f[:, FLAG_TERMINATED], f[:, FLAG_TRUNCATED], info

    def global_state(self, state: EngineState, ctx: StepContext | None = None) -> NDArray[np.float32]:
        """Global state vectors, shape (B, state_dim), float32: positions, velocities, goal positions and
        velocities of all agents, formation error, fitted Theta (row-major), the scenario's parameters, the
        moving obstacles' current state, time fraction; then the ``state_blocks`` of every leader, if any.
        ``ctx``: the context of the step that made ``state`` (from :meth:`advance`), if at hand: its affine fit
        is reused, and so are its state blocks (``advance(observe="state")``)."""
        B = state.batch_size
        blocks = None
        if ctx is not None and ctx.blocks is not None:
            blocks, theta = ctx.blocks, ctx.theta
        elif self.state_observer is not None:
            c, smod = self._state_kernel()
            acts = np.zeros((B, self.n_l, self.p))
            blocks, theta = smod.observe(*self._args(c, state, acts, _NO_STATE, _NO_STATE, _NO_NOISE))
        else:
            theta = self._fit(state.pos)[0] if ctx is None else ctx.theta
        t = self.time(state)
        parts = [state.pos.reshape(B, -1), state.vel.reshape(B, -1), state.goal.reshape(B, -1)]
        parts += [state.goal_vel.reshape(B, -1), state.err[:, None], theta.reshape(B, -1), state.params["_pvec"]]
        parts += [ob.state_vector(state.params[ob.key], t, self.bounds) for ob in self.obstacles]
        parts.append(state.k[:, None].astype(np.float64) * (1.0 / self.max_cycles))
        if blocks is not None:
            parts.append(blocks.reshape(B, -1).astype(np.float64))
        out = np.concatenate(parts, axis=1)
        np.clip(out, self._state_lo64, self._state_hi64, out=out)
        return out.astype(np.float32)

    # ------------------------------------------------------------------ helpers
    def affine_targets(self, state: EngineState) -> Array:
        """Where the law drives every agent: leaders where they are, followers at L x_l (Lemma 2), (B, n, d)."""
        out = state.pos.copy()
        out[:, self.followers] = np.einsum("fl,bld->bfd", self.law.part.localisation, state.pos[:, self.leaders])
        return out

    def time(self, state: EngineState) -> Array:
        """The env time of every copy (B,) s: k T, or under jitter the sum of the drawn periods."""
        return state.net_time if state.net_time is not None else self.dt * state.k.astype(np.float64)

    def frame(self, state: EngineState, b: int = 0, trail: Array | None = None, text: str = "") -> dict[str, Any]:
        """The renderer's frame dict for batch entry ``b`` (keys: ``rendering.FRAME_KEYS``)."""
        t = float(self.time(state)[b])
        gd = float(np.max(np.linalg.norm(state.goal[b] - state.pos[b], axis=-1)))
        status = text or f"{self.scenario_name}  t={t:.1f} s  formation error {state.err[b]:.3f} m  goal {gd:.2f} m"
        d = self.d
        shapes: dict[str, list[Array]] = {"segments": [np.zeros((0, 2, d))], "circles": [np.zeros((0, d + 1))]}
        for ob in self.obstacles:
            for key, arr in ob.shapes(state.params[ob.key][b], t, self.bounds).items():
                shapes[key].append(arr)
        return {
            "positions": state.pos[b],
            "leaders": self.leaders,
            "edges": self.fw.edge_array(),
            "targets": self.affine_targets(state)[b] if not self.sparse else state.pos[b],
            "obstacles": {key: np.concatenate(parts) for key, parts in shapes.items()},
            "goal": state.goal[b],
            "trail": np.zeros((0, self.n, self.d)) if trail is None else trail,
            "bounds": self.bounds,
            "agent_radius": self.agent_radius,
            "text": status,
            "time": t,
        }

    @staticmethod
    def concat(states: Sequence[EngineState]) -> EngineState:
        """Join states along the batch dim (e.g. B = 1 resets into one batch), in order."""
        columns = [[getattr(s, f) for s in states] for f in _FIELDS]  # each field but params, over the states
        fields = {f: None if x[0] is None else np.concatenate(x) for f, x in zip(_FIELDS, columns, strict=True)}
        return _frozen(fields, {kk: np.concatenate([s.params[kk] for s in states]) for kk in states[0].params})

    @staticmethod
    def select(state: EngineState, index: ArrayLike) -> EngineState:
        """The sub-batch ``index`` of ``state`` (for tests and vectorised resets)."""
        idx = np.atleast_1d(np.asarray(index))
        values = [getattr(state, f) for f in _FIELDS]
        fields = {f: None if v is None else v[idx] for f, v in zip(_FIELDS, values, strict=True)}
        return _frozen(fields, {kk: vv[idx] for kk, vv in state.params.items()})

    @staticmethod
    def replace_rows(state: EngineState, rows: NDArray[np.int64], new: EngineState) -> EngineState:
        """``state`` with batch rows ``rows`` replaced by the rows of ``new`` (auto-resets)."""

        def put(old: Any, val: Any) -> Any:
            if old is None or val is None:
                return old
            out = old.copy()
            out[rows] = val
            return out

        fields = {f: put(getattr(state, f), getattr(new, f)) for f in _FIELDS}
        return _frozen(fields, {kk: put(vv, new.params[kk]) for kk, vv in state.params.items()})


def _checked_network(network: Any, follower_law: str) -> Network | None:
    """``network`` as a Network (or None); errors name ``network``; a law it does not apply to is refused with
    the core's reason (``core.network.check_network_law``)."""
    try:
        net = check_network(network)
    except (TypeError, ValueError) as exc:
        raise type(exc)(f"network: {exc}") from None
    if net is not None and follower_law not in NETWORK_LAWS:
        try:
            check_network_law(follower_law)
        except FormationError as exc:
            raise FormationError(
                f"{exc}. Pass follower_law='linear' (or 'stationary' with single_integrator dynamics) with network="
            ) from None
    return net


def _frozen(fields: dict[str, Any], params: dict[str, Array]) -> EngineState:
    """An ``EngineState`` of ``fields`` whose ``params`` are made read-only."""
    for arr in params.values():
        arr.setflags(write=False)
    return EngineState(**fields, params=params)
