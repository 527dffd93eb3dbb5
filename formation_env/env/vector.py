"""B copies of the formation env stepped as one batch: a Stable-Baselines3 ``VecEnv`` and a Gymnasium adapter.

:class:`FormationVecEnv` holds one batched :class:`~formation_env.env.state.EngineState` of B environments
and steps them with one call of the same pure ``Engine.step`` that the PettingZoo env runs with B = 1. Two
slot layouts:

============  ==============  ===========================================  ==========================
mode          slots           observation of a slot                        action of a slot
============  ==============  ===========================================  ==========================
``shared``    B x n_l         one leader's observation (``obs_dim``,)      that leader's (p,) in [-1, 1]
``shared``    B x n_l         that, then the global state (``state_dim``)  that leader's (p,)
+ critic_state
``commander`` B               the global state (``state_dim``,)            every leader's (n_l p,)
``commander`` B               the global state, Theta_c, b_c               pose rates (d (d + 1),)
+ maneuver
============  ==============  ===========================================  ==========================

So ``FormationVecEnv(num_envs=1024, mode="shared")`` has ``num_envs`` = 3,072 slots with 3 leaders (SB3's
``num_envs`` counts slots; ``n_envs`` is B). Slot ``b * n_l + j`` in ``shared`` mode is leader j of env b (one
policy for every leader, parameter sharing). The ``commander`` slot is ``FormationCommander-v0`` with the
same ``action_mode``: its reward is the mean of the leaders' rewards.

Seeding and auto-reset: env b draws its episodes from its own generator ``np.random.default_rng(seed + b)``,
so env b of the batch replays the single env reset with ``seed + b`` and given the same actions, episode
after episode (test). A finished env is reset in the same step (SB3 convention): its slots' ``info`` hold
``terminal_observation``, the step's metrics and, for a time-limit cut that is no true end,
``TimeLimit.truncated = True`` (SB3 then bootstraps its value); other slots get fresh empty dicts. The
engine's info arrays of the last step are ``last_info`` (arrays (B,)).

Gymnasium: :meth:`FormationVecEnv.to_gymnasium` wraps it as a ``gymnasium.vector.VectorEnv`` with same-step
auto-reset (:class:`GymnasiumFormationVecEnv`).

Example::

    from stable_baselines3 import PPO
    from formation_env.env.vector import FormationVecEnv

    venv = FormationVecEnv("narrow_passage", num_envs=64, mode="shared")
    PPO("MlpPolicy", venv, seed=0).learn(10_000)
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces
from numpy.typing import ArrayLike, NDArray
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvIndices

from formation_env.core.errors import FormationError
from formation_env.core.validation import as_array, check_int, check_mapping, check_seed

from .engine import INFO_KEYS, Engine, EngineState
from .maneuver import Pose, PoseCommand
from .state import StepContext

__all__ = ["MODES", "FormationVecEnv", "GymnasiumFormationVecEnv"]

#: Slot layouts of :class:`FormationVecEnv`.
MODES: tuple[str, ...] = ("shared", "commander")

#: Engine info entries copied into a finished slot's info dict.
_DONE_INFO = tuple(key for key in INFO_KEYS if key != "control_effort")


class FormationVecEnv(VecEnv):
    """B formation envs in one batched engine, as an SB3 ``VecEnv`` (see the module docstring).

    Args:
        scenario: a scenario name (``formation_env.env.scenarios.REGISTRY``).
        num_envs: B, the number of environment copies (not of slots).
        mode: ``"shared"`` (one slot per leader) or ``"commander"`` (one slot per env).
        seed: seed of the first reset (env b gets ``seed + b``); None draws fresh entropy.
        engine: an existing ``Engine`` to step (then ``env_kwargs`` must be empty).
        action_mode: ``"leaders"`` (every leader's action) or, in ``commander`` mode, ``"maneuver"``: pose rates
            of the whole team (:mod:`formation_env.env.maneuver`; the slot's observation is the global state
            followed by the commanded Theta_c and b_c, as ``FormationCommander-v0``).
        maneuver_kwargs: the :class:`~formation_env.env.maneuver.PoseCommand` rates and scale range.
        critic_state: in ``shared`` mode, each slot's observation is the leader's followed by the global state
            (``state_dim``), for a centralised critic (``agents.central_critic``; the actor reads the first part).
        **env_kwargs: the ``Engine`` arguments (dynamics, follower_law, dt, max_cycles, framework, ...).

    Attributes:
        engine: the shared ``Engine``. state: the batched ``EngineState`` (B envs).
        n_envs: B. num_envs: slots (B n_l in ``shared`` mode, B in ``commander`` mode).
        last_info: the engine's info arrays of the last step, before auto-reset.
        last_terminated, last_truncated: the engine's (B,) flags of the last step.
    """

    metadata = {"render_modes": ["rgb_array"]}

    def __init__(
        self,
        scenario: str = "narrow_passage",
        num_envs: int = 8,
        mode: str = "shared",
        seed: int | None = None,
        *,
        engine: Engine | None = None,
        render_mode: str | None = None,
        action_mode: str = "leaders",
        maneuver_kwargs: dict[str, Any] | None = None,
        critic_state: bool = False,
        **env_kwargs: Any,
    ) -> None:
        if mode not in MODES:
            raise FormationError(f"mode must be one of {list(MODES)}, got {mode!r}")
        check_int(num_envs, "num_envs", low=1, what="a positive integer")
        if seed is not None:
            check_seed(seed)
        if engine is not None and env_kwargs:
            raise TypeError(f"pass either engine= or engine keyword arguments, not both (got {sorted(env_kwargs)})")
        if engine is not None and not isinstance(engine, Engine):
            raise TypeError(f"engine must be an Engine (or None), got {type(engine).__name__}")
        if render_mode not in (None, "rgb_array"):
            raise FormationError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        if action_mode not in ("leaders", "maneuver") or (action_mode == "maneuver" and mode != "commander"):
            raise FormationError(f"action_mode must be 'leaders', or 'maneuver' in commander mode, got {action_mode!r}")
        if check_mapping(maneuver_kwargs, "maneuver_kwargs") and action_mode != "maneuver":
            raise TypeError("maneuver_kwargs is for action_mode='maneuver' only")
        if critic_state not in (True, False) or (critic_state and mode != "shared"):
            raise FormationError(f"critic_state must be a bool, True only in shared mode, got {critic_state!r}")
        self.engine = eng = engine if engine is not None else Engine(scenario, **env_kwargs)
        self.command = PoseCommand(eng, **(maneuver_kwargs or {})) if action_mode == "maneuver" else None
        self.pose: Pose | None = None
        self.mode = mode
        self.n_envs = B = int(num_envs)
        self.n_l, self.p = eng.n_l, eng.p
        self.render_mode = render_mode
        self.critic_state = bool(critic_state)
        if mode == "shared":
            low, high = eng.obs_low, eng.obs_high
            if critic_state:
                low, high = np.concatenate([low, eng.state_low]), np.concatenate([high, eng.state_high])
            obs_space = spaces.Box(low, high, dtype=np.float32)
            act_space = spaces.Box(-1.0, 1.0, (eng.p,), dtype=np.float32)
        elif self.command is None:
            obs_space = spaces.Box(eng.state_low, eng.state_high, dtype=np.float32)
            act_space = spaces.Box(-1.0, 1.0, (eng.n_l * eng.p,), dtype=np.float32)
        else:
            low = np.concatenate([eng.state_low, self.command.obs_low])
            high = np.concatenate([eng.state_high, self.command.obs_high])
            obs_space = spaces.Box(low, high, dtype=np.float32)
            act_space = spaces.Box(-1.0, 1.0, (self.command.action_dim,), dtype=np.float32)
        self._per_env = eng.n_l if mode == "shared" else 1
        super().__init__(B * self._per_env, obs_space, act_space)
        self._next_seed: int | None = None if seed is None else int(seed)
        self._rngs: list[np.random.Generator] = []
        self.state: EngineState | None = None
        self._actions: NDArray[np.float64] | None = None
        self.last_info: dict[str, Any] = {}
        self.last_terminated = self.last_truncated = np.zeros(B, dtype=bool)
        self._renderer: Any = None

    def _observe(
        self,
        state: EngineState,
        leader_obs: NDArray[np.float32] | None = None,
        rngs: Any = None,
        pose: Pose | None = None,
        ctx: StepContext | None = None,
    ) -> NDArray[np.float32]:
        """Slot observations (num_envs, obs dim) of ``state`` (``leader_obs``: the step's, if at hand; ``rngs``: the
        envs' generators, for observation noise; ``pose``: the commanded poses in ``maneuver`` mode; ``ctx``: the
        context of the step that made ``state``, if any)."""
        if self.mode == "commander":
            g = self.engine.global_state(state, ctx)
            if self.command is None or pose is None:
                return g
            return np.concatenate([g, self.command.observe(pose).astype(np.float32)], axis=1)
        lo = self.engine.observe(state, rngs) if leader_obs is None else leader_obs
        if self.critic_state:
            g = np.repeat(self.engine.global_state(state, ctx)[:, None], self.n_l, axis=1)
            lo = np.concatenate([lo, g], axis=2)
        return lo.reshape(state.batch_size * self.n_l, -1)

    def _slots(self, envs: NDArray[np.int64]) -> NDArray[np.int64]:
        """The slots of envs ``envs``, env by env."""
        k = self._per_env
        return (envs[:, None] * k + np.arange(k)).reshape(-1) if k > 1 else envs

    def seed(self, seed: int | None = None) -> Sequence[int | None]:
        """Seed the next reset: env b (all its slots) gets ``seed + b``; returns the seed of every slot."""
        if seed is None:
            seed = int(np.random.SeedSequence().generate_state(1)[0])
        self._next_seed = check_seed(seed)
        return [self._next_seed + s // self._per_env for s in range(self.num_envs)]

    def reset(self) -> NDArray[np.float32]:
        """Reset every env (with the seed given to :meth:`seed` or the constructor, if any); (num_envs, obs dim)."""
        B = self.n_envs
        if self._next_seed is not None:
            self._rngs = [np.random.default_rng(self._next_seed + b) for b in range(B)]
            self._next_seed = None
        elif not self._rngs:
            self._rngs = [np.random.default_rng(s) for s in np.random.SeedSequence().spawn(B)]
        self.state = self.engine.reset_each(self._rngs)
        self.pose = None if self.command is None else self.command.reset(self.state)
        self._actions = None
        self.reset_infos = [{} for _ in range(self.num_envs)]
        self._reset_options()
        return self._observe(self.state, rngs=self._rngs, pose=self.pose)

    def step_async(self, actions: ArrayLike) -> None:
        """Check and store the actions of every slot: (num_envs, p) shared, (num_envs, n_l p) commander."""
        self._actions = None  # a failed call leaves nothing behind for step_wait
        if self.state is None:
            raise FormationError("reset() must be called before step()")
        expect = (self.num_envs, int(self.action_space.shape[0]))  # type: ignore[index]
        a = as_array(actions, "actions", finite=False)
        if a.shape != expect:
            raise FormationError(f"actions must have shape {expect} (slots, action dim), got {a.shape}")
        if self.command is None:
            a = self.engine.check_actions(a.reshape(self.n_envs, self.n_l, self.p), self.n_envs)
        elif not np.all(np.isfinite(a)):
            raise ValueError("maneuver actions hold NaN or inf; the state is unchanged")
        self._actions = a

    def _step_slots(
        self,
    ) -> tuple[NDArray[np.float32], NDArray[np.float32], NDArray[np.bool_], NDArray[np.int64], NDArray[np.float32]]:
        """Step all B envs and auto-reset the finished ones: (obs, rewards, dones) per slot, the finished envs
        (sorted; empty if none) and their slots' last observations. The engine's info arrays and flags stay in
        ``last_info``, ``last_terminated``, ``last_truncated``."""
        if self._actions is None:
            raise FormationError("step_wait called without step_async")
        assert self.state is not None
        a, self._actions = self._actions, None
        k = self._per_env
        pose = self.pose
        if self.command is not None and pose is not None:
            pose, a = self.command.step(self.state, pose, a)
        state, ctx, rew, term, trunc, info = self.engine.advance(self.state, a, self._rngs)
        self.last_info, self.last_terminated, self.last_truncated = info, term, trunc
        lobs = ctx.obs if self.mode == "shared" else None  # a commander reads the global state
        obs = self._observe(state, lobs, pose=pose, ctx=ctx)
        rews = (rew.reshape(-1) if k > 1 else rew.mean(axis=1)).astype(np.float32)
        done_env = term | trunc
        dones = np.repeat(done_env, k) if k > 1 else done_env.copy()
        envs = np.flatnonzero(done_env)
        final = obs[self._slots(envs)]
        if envs.size:
            fresh = self.engine.reset_each([self._rngs[b] for b in envs.tolist()])
            state = Engine.replace_rows(state, envs, fresh)
            fresh_pose = None
            if self.command is not None and pose is not None:
                fresh_pose = self.command.reset(fresh)
                pose = pose.replace_rows(envs, fresh_pose)
            obs[self._slots(envs)] = self._observe(fresh, rngs=[self._rngs[b] for b in envs.tolist()], pose=fresh_pose)
        self.state, self.pose = state, pose
        return obs, rews, dones, envs, final

    def step_wait(self) -> tuple[NDArray[np.float32], NDArray[np.float32], NDArray[np.bool_], list[dict[str, Any]]]:
        """Step all B envs, auto-reset the finished ones; (obs, rewards, dones, infos) per slot."""
        obs, rews, dones, envs, final = self._step_slots()
        infos: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        if envs.size:
            info, term, trunc = self.last_info, self.last_terminated, self.last_truncated
            cols = [info[key][envs].tolist() for key in _DONE_INFO] + [(trunc[envs] & ~term[envs]).tolist()]
            per_env = [dict(zip((*_DONE_INFO, "TimeLimit.truncated"), v, strict=True)) for v in zip(*cols, strict=True)]
            for row, (slot, fin) in enumerate(zip(self._slots(envs).tolist(), final, strict=True)):
                infos[slot] = {**per_env[row // self._per_env], "terminal_observation": fin}
        return obs, rews, dones, infos

    def close(self) -> None:
        """Close the renderer, if one was opened."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    def render(self, mode: str | None = None) -> NDArray[np.uint8] | None:
        """An RGB frame of env 0 (``rgb_array``), or None."""
        if (mode or self.render_mode) != "rgb_array" or self.state is None:
            return None
        return self.get_images()[0]

    def get_images(self) -> Sequence[NDArray[np.uint8] | None]:
        """An RGB frame of every env (a render per env)."""
        if self.state is None:
            return [None] * self.n_envs
        if self._renderer is None:
            from .rendering import Renderer

            self._renderer = Renderer(self.engine.d, "rgb_array")
        return [self._renderer.draw(self.engine.frame(self.state, b)) for b in range(self.n_envs)]

    # ---------------------------------------------------------------- attribute plumbing
    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        """The attribute of this env (or its engine) once per slot in ``indices``."""
        owner = self if hasattr(self, attr_name) else self.engine
        if not hasattr(owner, attr_name):  # AttributeError, as SB3's has_attr expects
            raise AttributeError(f"attr_name {attr_name!r} is an attribute of neither FormationVecEnv nor its Engine")
        value = getattr(owner, attr_name)
        return [value for _ in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        """Set an attribute shared by every slot (all slots share one engine)."""
        setattr(self, attr_name, value)

    def env_method(
        self, method_name: str, *method_args: Any, indices: VecEnvIndices = None, **method_kwargs: Any
    ) -> list[Any]:
        """Call an engine method once per slot in ``indices``."""
        fn = getattr(self.engine, method_name, None)
        if not callable(fn):  # AttributeError, as SB3's VecEnv.env_method raises
            raise AttributeError(f"method_name {method_name!r} is not a method of the Engine")
        return [fn(*method_args, **method_kwargs) for _ in self._get_indices(indices)]

    def env_is_wrapped(self, wrapper_class: type, indices: VecEnvIndices = None) -> list[bool]:
        """No slot is wrapped by a Gymnasium wrapper."""
        return [False for _ in self._get_indices(indices)]

    def to_gymnasium(self) -> GymnasiumFormationVecEnv:
        """This env as a ``gymnasium.vector.VectorEnv`` (same-step auto-reset)."""
        return GymnasiumFormationVecEnv(self)


class GymnasiumFormationVecEnv(gymnasium.vector.VectorEnv):
    """A ``gymnasium.vector.VectorEnv`` view of a :class:`FormationVecEnv` (same state, same slots).

    ``step`` returns (obs, rewards, terminated, truncated, info) per slot, auto-resetting
    finished envs in the same step (``metadata["autoreset_mode"] = AutoresetMode.SAME_STEP``), in
    the layout of Gymnasium's own vector envs (``SyncVectorEnv``): ``info["final_obs"]`` (object
    array, None where not finished) and ``info["final_info"]``, a dict of arrays over slots (``success``,
    ``collision``, ``out_of_bounds``, ``formation_error``, ``goal_distance``, ``time``, each with its mask
    ``_success`` etc.), and the boolean masks ``info["_final_obs"]``, ``info["_final_info"]``: the finished
    slots.

    Args:
        venv: the SB3 vec env to expose (or build one: ``GymnasiumFormationVecEnv(FormationVecEnv(...))``).
    """

    metadata = {"render_modes": ["rgb_array"], "autoreset_mode": gymnasium.vector.AutoresetMode.SAME_STEP}

    def __init__(self, venv: FormationVecEnv) -> None:
        if not isinstance(venv, FormationVecEnv):
            raise TypeError(f"venv must be a FormationVecEnv, got {type(venv).__name__}")
        self.venv = venv
        self.num_envs = venv.num_envs
        self.single_observation_space = venv.observation_space
        self.single_action_space = venv.action_space
        self.observation_space = gymnasium.vector.utils.batch_space(venv.observation_space, venv.num_envs)
        self.action_space = gymnasium.vector.utils.batch_space(venv.action_space, venv.num_envs)
        self.render_mode = venv.render_mode

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[NDArray[np.float32], dict[str, Any]]:
        """Reset every env; ``seed`` seeds env b with ``seed + b`` (``options``, a dict, is accepted and unused)."""
        check_mapping(options, "options")
        if seed is not None:
            self.venv.seed(seed)
        return self.venv.reset(), {}

    def step(
        self, actions: ArrayLike
    ) -> tuple[NDArray[np.float32], NDArray[np.float32], NDArray[np.bool_], NDArray[np.bool_], dict[str, Any]]:
        """Step every slot; see the class docstring for the info layout (no per-slot dicts: arrays over slots)."""
        v = self.venv
        v.step_async(actions)
        obs, rews, dones, envs, final = v._step_slots()
        k = v._per_env
        term = np.repeat(v.last_terminated, k)
        trunc = np.repeat(v.last_truncated, k)
        info: dict[str, Any] = {}
        if envs.size:
            slots = v._slots(envs)
            final_obs = np.empty(self.num_envs, dtype=object)  # None-filled
            for s, fin in zip(slots.tolist(), final, strict=True):
                final_obs[s] = fin
            final_info: dict[str, Any] = {}
            for key in _DONE_INFO:  # the engine's info of the finished envs, at their slots (0 elsewhere)
                col = v.last_info[key]
                arr = np.zeros(self.num_envs, dtype=col.dtype)
                arr.reshape(v.n_envs, k)[envs] = col[envs, None]  # env b's value in its k slots
                final_info[key], final_info["_" + key] = arr, dones.copy()
            info = {"final_obs": final_obs, "_final_obs": dones.copy(), "final_info": final_info, "_final_info": dones}
        return obs, rews, term, trunc, info

    def render(self) -> NDArray[np.uint8] | None:  # type: ignore[override]
        """Env 0's frame."""
        return self.venv.render()
