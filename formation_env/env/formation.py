"""The PettingZoo parallel env: the batched engine at B = 1, leaders as agents, followers inside."""

from __future__ import annotations

import textwrap
import warnings
from typing import Any

import numpy as np
from gymnasium import spaces
from gymnasium.utils import EzPickle
from numpy.typing import NDArray
from pettingzoo import AECEnv, ParallelEnv
from pettingzoo.utils.conversions import parallel_to_aec_wrapper
from pettingzoo.utils.wrappers import OrderEnforcingWrapper

from formation_env.core.errors import ControlDimension, FormationError
from formation_env.core.validation import as_array, check_int, check_mapping, check_seed

from .engine import INFO_KEYS, Engine, EngineState, StepInfo
from .observations import observation_table
from .rewards import reward_table

__all__ = ["CheckedAEC", "FormationAEC", "FormationEnv", "aec_env", "neutral_info"]


def neutral_info(goal_distance: float, formation_error: float) -> StepInfo:
    """An info dict with every step key at its neutral value (for ``reset``: nothing happened yet)."""
    values: dict[str, Any] = {"success": False, "collision": False, "out_of_bounds": False}
    values.update(formation_error=formation_error, min_clearance=float("inf"), goal_distance=goal_distance)
    values.update(time=0.0, control_effort=0.0, lost_fraction=0.0)
    assert set(values) == set(INFO_KEYS)
    return StepInfo(values)


class SingleEnv:
    """What the PettingZoo and the Gymnasium envs share: checks, the reset info, the trail and rendering."""

    metadata: dict[str, Any]
    engine: Engine
    render_mode: str | None
    _state: EngineState | None
    _trail: list[NDArray[np.float64]]
    _renderer: Any = None
    #: Samples of the positions' trail drawn behind the agents.
    trail_length = 60

    def _check_render_mode(self, render_mode: str | None) -> None:
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise FormationError(
                f"render_mode must be None or one of {self.metadata['render_modes']}, got {render_mode!r}"
            )

    @staticmethod
    def _check_reset(seed: Any, options: Any) -> None:
        """Refuse a seed that is not a non-negative integer (or None) and options that are not a dict (or None)."""
        if seed is not None:
            check_seed(seed)
        check_mapping(options, "options")

    def _state_or_raise(self, method: str) -> EngineState:
        if self._state is None:
            raise FormationError(f"call reset() before {method}()")
        return self._state

    def _reset_info(self) -> StepInfo:
        """The info of a reset: every key at its neutral value; goal distance and formation error measured."""
        st = self._state_or_raise("reset")
        gd = float(np.max(np.linalg.norm(st.goal[0] - st.pos[0], axis=-1)))
        return neutral_info(gd, float(st.err[0]))

    def _show(self, reset: bool = False) -> None:
        """Extend the trail by the current positions (start it anew at a reset) and draw in ``human`` mode."""
        pos = self._state_or_raise("reset").pos[0]
        if reset:
            self._trail = [pos]
        elif self.render_mode is not None:  # the trail is drawn only
            self._trail.append(pos)
            del self._trail[: -self.trail_length]
        if self.render_mode == "human":
            self.render()

    def render(self) -> NDArray[np.uint8] | None:
        """Draw the current frame: an (H, W, 3) uint8 array (``rgb_array``), or a window (``human``)."""
        if self.render_mode is None:
            warnings.warn("render() called with render_mode=None: nothing to draw", stacklevel=2)
            return None
        state = self._state_or_raise("render")
        if self._renderer is None:
            from .rendering import Renderer

            self._renderer = Renderer(self.engine.d, self.render_mode, fps=self.metadata["render_fps"])
        return self._renderer.draw(self.engine.frame(state, 0, np.stack(self._trail)))

    def close(self) -> None:
        """Close the renderer (if one was opened)."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None


class FormationEnv(SingleEnv, ParallelEnv, EzPickle):
    """Leader-follower affine formation control (Zhao & Zelazo's stress-matrix laws, sampled in discrete time).

        ## Description

        n agents in R^d (d = 2 or 3) form an affine image x_i* = Theta r_i + b of a nominal
        configuration r (paper eq. 7). Only the n_l leaders are agents of this env; the n_f
        followers run an analytic sampled-data law on the stress matrix Omega inside the step
        (``follower_law``: ``stationary`` eq. 17, ``dynamic`` eq. 21 solved exactly,
        ``dynamic_distributed`` with m Jacobi rounds, ``linear`` with the Riccati gain of Theorem 3).
        By moving, the leaders steer the whole formation through translation, rotation, scaling
        and shear (the affine image), e.g. shrinking it to pass a gap. ``scenario`` is a name of
        ``formation_env.env.scenarios.REGISTRY`` (each file's docstring gives its geometry and success test).

        ## Action Space

        ``Box(-1, 1, (p,), float32)`` per leader, p = the input dimension (d for single and double
        integrators). The action is scaled by ``u_max``: a velocity (m/s, single integrator) or an
        acceleration (m/s^2, double integrator) per axis. Out-of-range actions are clipped to [-1, 1];
        an action holding NaN or inf raises ``ValueError`` naming the agent and leaves the env unchanged.
        Every leader's input also feeds the follower law as u_leaders (the dynamic laws use it).

        ## Observation Space

        ``Box(low, high, (obs_dim,), float32)``, the same for every leader, in world axes and SI units;
        every entry is clipped to its (finite) bounds. The observation is a list of declared blocks
        (``observation=[...]``; ``obs_blocks`` maps each name to its slice). The default, ``formation_v0``'s,
        is ``position, velocity, other_leaders, goal, goal_velocity, theta, time, formation_error, obstacles``:
        obs_dim = 34 for the 2D default framework (3 leaders, 16 rays). The registered blocks
        (:mod:`formation_env.env.observations`; d the dimension, W the world box, E its extent, v ``max_speed``,
        k ``k_nearest``, R ``n_rays``, N ``n_nearest``):

    OBSERVATION_TABLE

        Options for decentralised leaders: ``nearest_agents`` with ``k_nearest`` and ``sense_radius`` (m), which
        also limits the obstacle range; ``agent_id``; ``obs_noise`` (Gaussian, each entry's units, on the
        measurement blocks). ``state()`` (``state_space``) is the global vector (``Engine.global_state``).

        ## Rewards

        Per leader i at each step, r_i = sum_t w_t term_t (:mod:`formation_env.env.rewards`; weights
        ``reward_weights`` over the scenario's over the defaults; T = dt):

    REWARD_TABLE

        g_i: distance (m) of leader i to its goal position; e: affine-image formation error (m); a_i: the
        clipped action. ``maneuver`` uses distance 1, progress 0, success 0; ``hold`` adds distance 0.1.

        ## Starting State

        Drawn by the scenario from the env's ``np.random.Generator`` (reseeded by ``reset(seed=...)``):
        leaders on a start pose at rest, followers near their targets.

        ## Episode End

        Terminated (all agents) on a collision or on success (all agents within ``goal_tol`` of their
        goal positions and formation error below ``formation_tol`` for ``hold_steps`` samples;
        ``maneuver`` does not end on success). Truncated after ``max_cycles`` steps (a positive integer, also when set
        on the env).

        ## Arguments

        ``formation_v0.parallel_env(scenario="narrow_passage", dynamics="double_integrator",
        follower_law="dynamic", dt=0.1, max_cycles=400, render_mode=None, **kwargs)`` with the keyword
        arguments of :class:`~formation_env.env.engine.Engine` (``framework``, ``omega``, ``u_max``, ``network``,
        ...) and the scenario's own (e.g. ``gap_width``); unknown ones raise TypeError. ``stationary`` needs single
        integrators. ``network`` (a ``core.network.Network`` or a dict of its fields) puts delay, packet loss,
        jitter or quantisation between the agents (follower_law ``linear`` or ``stationary``; docs/networks.md).

        Info per agent per step (a fresh dict; ``reset`` gives every key with its neutral value): ``success``,
        ``collision``, ``out_of_bounds`` (bool), ``formation_error``, ``min_clearance`` (m; smallest agent-agent
        or agent-obstacle gap between surfaces), ``goal_distance`` (m; largest agent distance to its goal
        position), ``time`` (s), ``control_effort`` (|u_i|^2 of this leader's applied input), ``lost_fraction``
        (the share of the link samples into the followers lost since the reset; 0.0 without loss).

        ## Version History

        * v0: initial version.
    """

    __doc__ = (
        (__doc__ or "")
        .replace("OBSERVATION_TABLE", textwrap.indent(observation_table(), "    "))
        .replace("REWARD_TABLE", textwrap.indent(reward_table(), "    "))
    )

    metadata: dict[str, Any] = {
        "name": "formation_v0",
        "render_modes": ["human", "rgb_array"],
        "render_fps": 10,
        "is_parallelizable": True,
    }

    def __init__(
        self,
        scenario: str = "narrow_passage",
        dynamics: Any = "double_integrator",
        follower_law: str = "dynamic",
        dt: float = 0.1,
        max_cycles: int = 400,
        render_mode: str | None = None,
        **kwargs: Any,
    ) -> None:
        EzPickle.__init__(
            self,
            scenario=scenario,
            dynamics=dynamics,
            follower_law=follower_law,
            dt=dt,
            max_cycles=max_cycles,
            render_mode=render_mode,
            **kwargs,
        )
        self._check_render_mode(render_mode)
        self.engine = Engine(scenario, dynamics, follower_law, dt, max_cycles, **kwargs)
        eng = self.engine
        self.render_mode = render_mode
        self.possible_agents = [f"leader_{i}" for i in range(eng.n_l)]
        self.agents: list[str] = []
        self._index = list(enumerate(self.possible_agents))
        self._obs_space = spaces.Box(eng.obs_low, eng.obs_high, dtype=np.float32)
        self._act_space = spaces.Box(-1.0, 1.0, (eng.p,), dtype=np.float32)
        self._act_shape = (eng.n_l, eng.p)
        self.observation_spaces = dict.fromkeys(self.possible_agents, self._obs_space)
        self.action_spaces = dict.fromkeys(self.possible_agents, self._act_space)
        self.state_space = spaces.Box(eng.state_low, eng.state_high, dtype=np.float32)
        self.obs_blocks = eng.obs_blocks
        self._rng: np.random.Generator | None = None
        self._state: EngineState | None = None
        self._trail: list[NDArray[np.float64]] = []

    # ------------------------------------------------------------------ spaces
    def _check_agent(self, agent: Any) -> None:
        if agent not in self.observation_spaces:
            raise ValueError(f"agent must be one of {self.possible_agents}, got {agent!r}")

    def observation_space(self, agent: str) -> spaces.Box:
        """The (shared) observation space; the same object on every call."""
        self._check_agent(agent)
        return self._obs_space

    def action_space(self, agent: str) -> spaces.Box:
        """The (shared) action space; the same object on every call."""
        self._check_agent(agent)
        return self._act_space

    def check_action(self, agent: str, action: Any) -> NDArray[np.float64]:
        """``agent``'s action as float64 (p,): a real array of the action space's shape, without NaN or inf
        (values beyond [-1, 1] are clipped by the step). For the AEC view, which checks each action as it comes."""
        a = as_array(action, f"action of {agent}", finite=False)
        if a.shape != self._act_space.shape:
            raise ControlDimension(f"action of {agent} must have shape {self._act_space.shape}, got {a.shape}")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"action of {agent} holds NaN or inf: {a.tolist()}; the state is unchanged")
        return a

    @property
    def max_cycles(self) -> int:
        """Steps per episode before truncation: a positive integer (PettingZoo's ``parallel_api_test`` sets it).
        A scenario's time windows (``maneuver``'s) keep the length the env was made with."""
        return self.engine.max_cycles

    @max_cycles.setter
    def max_cycles(self, value: Any) -> None:
        self.engine.max_cycles = check_int(value, "max_cycles", low=1, what="a positive integer number of steps")

    @property
    def engine_state(self) -> EngineState | None:
        """The current batched engine state (B = 1), or None before ``reset``."""
        return self._state

    # ------------------------------------------------------------------ API
    def reset(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, NDArray[np.float32]], dict[str, dict[str, Any]]]:
        """Start an episode; ``seed`` (an integer >= 0) reseeds the env's generator. ``options`` (a dict) is
        accepted and unused, as PettingZoo's own checkers pass arbitrary keys."""
        self._check_reset(seed, options)
        if seed is not None or self._rng is None:
            self._rng = np.random.default_rng(seed)
        self._state = self.engine.reset(self._rng, 1)
        self.agents = self.possible_agents[:]
        obs = self.engine.observe(self._state, self._rng)[0]
        self._show(reset=True)
        info = self._reset_info()
        return {a: obs[i] for i, a in self._index}, {a: StepInfo(info) for a in self.agents}

    def step(
        self, actions: dict[str, Any]
    ) -> tuple[dict[str, Any], dict[str, float], dict[str, bool], dict[str, bool], dict[str, dict[str, Any]]]:
        """Advance one sample with every live leader's action (see the class docstring)."""
        state = self._state_or_raise("step")
        if not self.agents:  # every agent is done: an empty step is a no-op (PettingZoo's loop), an action an error
            if actions:
                raise FormationError("the episode is over: call reset() before step()")
            return {}, {}, {}, {}, {}
        if not isinstance(actions, dict) or set(actions) != set(self.agents):
            got = sorted(actions) if isinstance(actions, dict) else type(actions).__name__
            raise ValueError(
                f"actions must be a dict with an action for exactly the live agents {self.agents}, got {got}"
            )
        a = as_array([actions[ag] for ag in self.possible_agents], "actions", finite=False)
        if a.shape != self._act_shape:
            raise ValueError(f"each action must have shape {self._act_space.shape}, got actions of shape {a.shape[1:]}")
        self._state, ob, rw, te, trn, inf = self.engine.step(state, a[None], self._rng)
        o, t, tr = ob[0], bool(te[0]), bool(trn[0])
        agents = self.possible_agents
        shared = {key: val[0].item() for key, val in inf.items() if key != "control_effort"}
        effort = inf["control_effort"][0].tolist()
        infos: dict[str, dict[str, Any]] = {ag: StepInfo(shared, control_effort=effort[i]) for i, ag in self._index}
        out = (
            {ag: o[i] for i, ag in self._index},
            dict(zip(agents, rw[0].tolist(), strict=True)),
            dict.fromkeys(agents, t),
            dict.fromkeys(agents, tr),
            infos,
        )
        if t or tr:
            self.agents = []
        self._show()
        return out

    def state(self) -> NDArray[np.float32]:
        """The global state vector (``state_space``)."""
        return self.engine.global_state(self._state_or_raise("state"))[0]

    # ------------------------------------------------------------------ copies
    def __getstate__(self) -> dict[str, Any]:
        """The constructor's arguments (``EzPickle``) and the episode in progress: a pickled or deep-copied env
        continues the episode where the original is, with the same generator."""
        return {**EzPickle.__getstate__(self), "episode": (self._state, self._rng, list(self.agents), self._trail)}

    def __setstate__(self, d: dict[str, Any]) -> None:
        d = dict(d)
        episode = d.pop("episode", None)
        EzPickle.__setstate__(self, d)
        if episode is not None:
            self._state, self._rng, self.agents, self._trail = episode

    def __str__(self) -> str:
        return "formation_v0"


class CheckedAEC(parallel_to_aec_wrapper):
    """PettingZoo's AEC view of a :class:`FormationEnv` that checks each action as it is given
    (:meth:`FormationEnv.check_action`), not only when the last agent's action runs the parallel step."""

    def step(self, action: Any) -> None:
        agent = self.agent_selection
        if self.terminations[agent] or self.truncations[agent]:
            if action is not None:
                raise ValueError(f"action of {agent} must be None: the agent is done, got {action!r}")
        else:
            action = self.env.check_action(agent, action)
        super().step(action)


class FormationAEC(OrderEnforcingWrapper):
    """PettingZoo's order-enforcing wrapper of the AEC view, with ``max_cycles`` passed to the parallel env
    (checked there) instead of kept by the wrapper, unseen by the env."""

    @property
    def max_cycles(self) -> int:
        """Steps per episode before truncation (the env's)."""
        return int(self.env.unwrapped.max_cycles)

    @max_cycles.setter
    def max_cycles(self, value: Any) -> None:
        self.env.unwrapped.max_cycles = value


def aec_env(parallel: FormationEnv) -> AECEnv:
    """The AEC view of ``parallel`` (PettingZoo's ``parallel_to_aec`` with :class:`CheckedAEC`, order enforced)."""
    return FormationAEC(CheckedAEC(parallel))
