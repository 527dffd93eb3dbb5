"""B copies of the formation env as one batch: the slots, reset and step that both vector APIs run.

:class:`FormationBatch` holds one batched :class:`~formation_env.env.state.EngineState` of B environments and
steps them with one call of the same pure ``Engine.advance`` that the single envs run with B = 1. Two adapters
expose it, and neither steps anything itself:

* :class:`~formation_env.env.vector.FormationVecEnv`: a Stable-Baselines3 ``VecEnv`` (needs
  stable-baselines3);
* :class:`GymnasiumFormationVecEnv`: a ``gymnasium.vector.VectorEnv`` with Gymnasium's auto-reset modes
  (``NEXT_STEP``, ``SAME_STEP``, ``DISABLED``), what ``gym.make_vec(id, num_envs=N)`` returns for every
  ``formation_env`` Gymnasium id (:func:`formation_env.env.commander.vector`).

Slot layouts (``mode``): ``shared``, B x n_l slots, one per leader (slot ``b * n_l + j`` is leader j of env b);
``commander``, B slots, one per env (the ``FormationCommander-v0`` view). See
:mod:`formation_env.env.vector` for the table of observations and actions.

Seeding: env b draws its episodes from its own generator (``np.random.default_rng(seed + b)`` after a seed
``seed``), so env b replays the single env reset with ``seed + b`` given the same actions, episode after
episode, in either auto-reset mode (tests).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode
from numpy.typing import ArrayLike, NDArray

from formation_env.core.errors import FormationError
from formation_env.core.validation import as_array, check_int, check_mapping, check_seed

from .engine import INFO_KEYS, Engine, EngineState
from .maneuver import Pose, PoseCommand
from .state import StepContext

__all__ = ["MODES", "FormationBatch", "GymnasiumFormationVecEnv"]

#: Slot layouts of :class:`FormationBatch`.
MODES: tuple[str, ...] = ("shared", "commander")


class FormationBatch:
    """B formation envs in one batched engine: slots, seeding, reset and the auto-resetting step.

    Args:
        scenario: a scenario name (``formation_env.env.scenarios.REGISTRY``).
        num_envs: B, the number of environment copies (not of slots).
        mode: ``"shared"`` (one slot per leader) or ``"commander"`` (one slot per env).
        seed: seed of the first reset (env b gets ``seed + b``); None draws fresh entropy.
        engine: an existing ``Engine`` to step (then ``env_kwargs`` must be empty).
        render_mode: None or ``"rgb_array"``.
        action_mode: ``"leaders"`` (every leader's action) or, in ``commander`` mode, ``"maneuver"``: pose rates
            of the whole team (:mod:`formation_env.env.maneuver`; the slot's observation is the global state
            followed by the commanded Theta_c and b_c, as ``FormationCommander-v0``).
        maneuver_kwargs: the :class:`~formation_env.env.maneuver.PoseCommand` rates and scale range.
        critic_state: in ``shared`` mode, each slot's observation is the leader's followed by the global state
            (``state_dim``), for a centralised critic (``agents.central_critic``; the actor reads the first part).
        max_episode_steps: a time limit over the engine's ``max_cycles`` as Gymnasium's ``TimeLimit`` applies
            it: an env is truncated once it has taken ``max_episode_steps`` samples (also when it terminates in
            that sample); None: ``max_cycles`` alone ends episodes.
        **env_kwargs: the ``Engine`` arguments (dynamics, follower_law, dt, max_cycles, framework, ...).

    Attributes:
        engine: the shared ``Engine``. state: the batched ``EngineState`` (B envs). pose: the commanded poses
        (``maneuver`` mode) or None. n_envs: B. num_envs: slots (B n_l in ``shared`` mode, B in ``commander``).
        observation_space, action_space: the spaces of one slot.
        last_info: the engine's info arrays of the last step, before auto-reset.
        last_terminated, last_truncated: the (B,) flags of the last step (with the time limit).
    """

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
        max_episode_steps: int | None = None,
        **env_kwargs: Any,
    ) -> None:
        if mode not in MODES:
            raise FormationError(f"mode must be one of {list(MODES)}, got {mode!r}")
        check_int(num_envs, "num_envs", low=1, what="a positive integer")
        if seed is not None:
            check_seed(seed)
        if max_episode_steps is not None:
            check_int(max_episode_steps, "max_episode_steps", low=1, what="a positive integer or None")
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
        self.max_episode_steps = None if max_episode_steps is None else int(max_episode_steps)
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
        self.num_envs = B * self._per_env
        self.observation_space: spaces.Box = obs_space
        self.action_space: spaces.Box = act_space
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

    def _seed_envs(self, seeds: Sequence[int | None]) -> None:
        """Give env b the generator ``default_rng(seeds[b])``; a None keeps env b's generator (fresh entropy if it
        has none yet), as a Gymnasium env's ``reset(seed=None)`` does."""
        if len(seeds) != self.n_envs:
            raise FormationError(
                f"seed must be an int, None or a list of {self.n_envs} seeds, got a list of {len(seeds)}"
            )
        fresh = np.random.SeedSequence().spawn(self.n_envs)
        self._rngs = [
            np.random.default_rng(check_seed(s))
            if s is not None
            else (self._rngs[b] if self._rngs else np.random.default_rng(fresh[b]))
            for b, s in enumerate(seeds)
        ]
        self._next_seed = None

    def _reset_all(self) -> NDArray[np.float32]:
        """Reset every env (with the pending seed, if any); the slot observations (num_envs, obs dim)."""
        B = self.n_envs
        if self._next_seed is not None:
            self._rngs = [np.random.default_rng(self._next_seed + b) for b in range(B)]
            self._next_seed = None
        elif not self._rngs:
            self._rngs = [np.random.default_rng(s) for s in np.random.SeedSequence().spawn(B)]
        self.state = self.engine.reset_each(self._rngs)
        self.pose = None if self.command is None else self.command.reset(self.state)
        self._actions = None
        self.last_terminated = self.last_truncated = np.zeros(B, dtype=bool)
        return self._observe(self.state, rngs=self._rngs, pose=self.pose)

    def _fresh(self, envs: NDArray[np.int64]) -> tuple[EngineState, Pose | None, NDArray[np.float32]]:
        """New episodes of envs ``envs`` drawn from their generators: (their state, their pose, their slots'
        observations); nothing is written into the batch."""
        rngs = [self._rngs[b] for b in envs.tolist()]
        fresh = self.engine.reset_each(rngs)
        pose = None if self.command is None else self.command.reset(fresh)
        return fresh, pose, self._observe(fresh, rngs=rngs, pose=pose)

    def _put(self, envs: NDArray[np.int64], state: EngineState, pose: Pose | None) -> None:
        """Write the rows of ``state`` (and ``pose``) into the batch at envs ``envs``."""
        assert self.state is not None
        self.state = Engine.replace_rows(self.state, envs, state)
        if self.pose is not None and pose is not None:
            self.pose = self.pose.replace_rows(envs, pose)

    def _set_actions(self, actions: ArrayLike) -> None:
        """Check and store the actions of every slot: (num_envs, p) shared, (num_envs, n_l p) commander."""
        self._actions = None  # a failed call leaves nothing behind for the step
        if self.state is None:
            raise FormationError("reset() must be called before step()")
        expect = (self.num_envs, int(self.action_space.shape[0]))
        a = as_array(actions, "actions", finite=False)
        if a.shape != expect:
            raise FormationError(f"actions must have shape {expect} (slots, action dim), got {a.shape}")
        if self.command is None:
            a = self.engine.check_actions(a.reshape(self.n_envs, self.n_l, self.p), self.n_envs)
        elif not np.all(np.isfinite(a)):
            raise ValueError("maneuver actions hold NaN or inf; the state is unchanged")
        self._actions = a

    def _step_slots(
        self, autoreset: bool = True, rngs: Sequence[np.random.Generator] | None = None
    ) -> tuple[NDArray[np.float32], NDArray[np.float32], NDArray[np.bool_], NDArray[np.int64], NDArray[np.float32]]:
        """Step all B envs with the stored actions and, if ``autoreset``, reset the finished ones in the same step.

        ``rngs``: the generators of the step's observation noise (default: the envs' own). Returns (obs, rewards,
        dones) per slot, the finished envs (sorted; empty if none) and their slots' last observations. The
        engine's info arrays stay in ``last_info``, the flags (with the time limit) in ``last_terminated``,
        ``last_truncated``.
        """
        if self._actions is None:
            raise FormationError("step_wait called without step_async")
        assert self.state is not None
        a, self._actions = self._actions, None
        k = self._per_env
        pose = self.pose
        if self.command is not None and pose is not None:
            pose, a = self.command.step(self.state, pose, a)
        view = "state" if self.mode == "commander" else "leaders"  # a commander reads the global state
        state, ctx, rew, term, trunc, info = self.engine.advance(
            self.state, a, self._rngs if rngs is None else rngs, observe=view
        )
        if self.max_episode_steps is not None:
            trunc = trunc | (state.k >= self.max_episode_steps)
        self.last_info, self.last_terminated, self.last_truncated = info, term, trunc
        obs = self._observe(state, ctx.obs, pose=pose, ctx=ctx)
        rews = (rew.reshape(-1) if k > 1 else rew.mean(axis=1)).astype(np.float32)
        done_env = term | trunc
        dones = np.repeat(done_env, k) if k > 1 else done_env.copy()
        envs = np.flatnonzero(done_env)
        final = obs[self._slots(envs)]
        self.state, self.pose = state, pose
        if autoreset and envs.size:
            fresh, fresh_pose, fresh_obs = self._fresh(envs)
            self._put(envs, fresh, fresh_pose)
            obs[self._slots(envs)] = fresh_obs
        return obs, rews, dones, envs, final

    def _slot_info(self) -> dict[str, NDArray[Any]]:
        """The engine's info of the last step per slot (num_envs,): each env's value in its slots,
        ``control_effort`` the slot's leader's (shared) or the sum over leaders (commander), as the single envs."""
        k = self._per_env
        out: dict[str, NDArray[Any]] = {}
        for key in INFO_KEYS:
            col = self.last_info[key]
            if key == "control_effort":
                out[key] = col.reshape(-1).copy() if k > 1 else col.sum(axis=1)
            else:
                out[key] = np.repeat(col, k) if k > 1 else col.copy()
        return out

    def _reset_info(self, state: EngineState) -> dict[str, NDArray[Any]]:
        """The info of a reset per slot of ``state``'s envs: every key at its neutral value, goal distance and
        formation error measured (as ``SingleEnv._reset_info``)."""
        n = state.batch_size * self._per_env
        gd = np.max(np.linalg.norm(state.goal - state.pos, axis=-1), axis=1)
        values: dict[str, NDArray[Any]] = {
            "success": np.zeros(n, bool),
            "collision": np.zeros(n, bool),
            "out_of_bounds": np.zeros(n, bool),
            "formation_error": np.repeat(state.err.astype(np.float64), self._per_env),
            "min_clearance": np.full(n, np.inf),
            "goal_distance": np.repeat(gd, self._per_env),
            "time": np.zeros(n),
            "control_effort": np.zeros(n),
            "lost_fraction": np.zeros(n),
        }
        assert set(values) == set(INFO_KEYS)
        return values

    def get_images(self) -> Sequence[NDArray[np.uint8] | None]:
        """An RGB frame of every env (a render per env)."""
        if self.state is None:
            return [None] * self.n_envs
        if self._renderer is None:
            from .rendering import Renderer

            self._renderer = Renderer(self.engine.d, "rgb_array")
        return [self._renderer.draw(self.engine.frame(self.state, b)) for b in range(self.n_envs)]

    def close(self) -> None:
        """Close the renderer, if one was opened."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None


class GymnasiumFormationVecEnv(gymnasium.vector.VectorEnv):
    """A ``gymnasium.vector.VectorEnv`` over a :class:`FormationBatch` (same state, same slots).

    ``gym.make_vec(id, num_envs=N)`` returns one for every ``formation_env`` id (commander slots); a
    :class:`~formation_env.env.vector.FormationVecEnv` gives one with ``to_gymnasium()`` (any slot layout).

    ``step`` returns (obs, rewards, terminated, truncated, info) per slot and auto-resets as
    ``metadata["autoreset_mode"]`` says, exactly as Gymnasium's ``SyncVectorEnv`` of the single envs does (test):

    * ``NEXT_STEP`` (the default, as Gymnasium's): a finished env returns its last observation; the next step
      ignores its action, resets it and returns the new episode's first observation, reward 0, no done flags.
    * ``SAME_STEP``: a finished env is reset within the step; its last observation is in ``info["final_obs"]``
      (object array, None where not finished), its step info in ``info["final_info"]``, with the masks
      ``info["_final_obs"]``, ``info["_final_info"]``.
    * ``DISABLED``: no reset; reset finished envs with ``reset(options={"reset_mask": mask})`` before stepping.

    ``info`` holds the step's metrics per slot in Gymnasium's layout (``info["success"]``,
    ``info["formation_error"]``, ... arrays (num_envs,) each with its mask ``info["_success"]``); a slot whose env
    was reset in the step holds the reset's info (neutral values), as its single env would give.

    Args:
        venv: the batch to expose (a :class:`FormationBatch`, e.g. a ``FormationVecEnv``).
        autoreset_mode: a ``gymnasium.vector.AutoresetMode`` (or its value, e.g. ``"NextStep"``).
    """

    def __init__(self, venv: FormationBatch, autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP) -> None:
        if not isinstance(venv, FormationBatch):
            raise TypeError(f"venv must be a FormationVecEnv or FormationBatch, got {type(venv).__name__}")
        try:
            mode = AutoresetMode(autoreset_mode)
        except ValueError:
            raise FormationError(
                f"autoreset_mode must be one of {[m.value for m in AutoresetMode]}, got {autoreset_mode!r}"
            ) from None
        self.venv = venv
        self.autoreset_mode = mode
        self.metadata = {"render_modes": ["rgb_array"], "autoreset_mode": mode}
        self.num_envs = venv.num_envs
        self.single_observation_space = venv.observation_space
        self.single_action_space = venv.action_space
        self.observation_space = gymnasium.vector.utils.batch_space(venv.observation_space, venv.num_envs)
        self.action_space = gymnasium.vector.utils.batch_space(venv.action_space, venv.num_envs)
        self.render_mode = venv.render_mode
        self._obs: NDArray[np.float32] | None = None
        #: (B,) envs that finished in the last step: reset at the next (NEXT_STEP) or refused (DISABLED).
        self._ended = np.zeros(venv.n_envs, dtype=bool)

    def reset(
        self, *, seed: int | Sequence[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[NDArray[np.float32], dict[str, Any]]:
        """Reset every env, or those of ``options["reset_mask"]``; (obs (num_envs, obs dim), info).

        Args:
            seed: None (each env continues its generator; fresh entropy the first time), an int (env b gets
                ``seed + b``, as ``SyncVectorEnv``) or a list of B seeds (int or None), one per env copy.
            options: a dict or None; ``"reset_mask"``: a bool array (num_envs,) of the slots to reset (whole
                envs: all slots of an env, or none), the others keep their episode and last observation. Other
                keys are accepted and unused, as by the single env.
        """
        v = self.venv
        check_mapping(options, "options")
        options = dict(options or {})
        seeds: Sequence[int | None]
        if isinstance(seed, (list, tuple)):
            seeds = list(seed)
        else:  # check_seed refuses anything but None or a non-negative int
            seeds = [None if seed is None else check_seed(seed) + b for b in range(v.n_envs)]
        mask = options.pop("reset_mask", None)
        if mask is None or self._obs is None:
            if seed is not None:
                v._seed_envs(seeds)
            self._obs = v._reset_all()
            self._ended[:] = False
            assert v.state is not None
            return self._obs, self._mask_info(v._reset_info(v.state), np.ones(self.num_envs, bool))
        m = np.asarray(mask)
        if m.dtype != np.bool_ or m.shape != (self.num_envs,) or not m.any():
            raise FormationError(
                f"options['reset_mask'] must be a bool array of shape ({self.num_envs},) with a True, got {mask!r}"
            )
        env_mask = m.reshape(v.n_envs, -1)
        if (env_mask.any(axis=1) != env_mask.all(axis=1)).any():
            raise FormationError("options['reset_mask'] must hold all slots of an env or none")
        envs = np.flatnonzero(env_mask[:, 0])
        if seed is not None:
            v._seed_envs([s if env_mask[b, 0] else None for b, s in enumerate(seeds)])
        fresh, pose, fresh_obs = v._fresh(envs)
        v._put(envs, fresh, pose)
        self._obs = obs = self._obs.copy()
        obs[v._slots(envs)] = fresh_obs
        self._ended[envs] = False
        info = {key: np.zeros(self.num_envs, val.dtype) for key, val in v._reset_info(fresh).items()}
        for key, val in v._reset_info(fresh).items():
            info[key][v._slots(envs)] = val
        return obs, self._mask_info(info, m)

    def _mask_info(self, values: dict[str, NDArray[Any]], mask: NDArray[np.bool_]) -> dict[str, Any]:
        """Gymnasium's info layout: each key beside its mask ``_key``."""
        info: dict[str, Any] = {}
        for key, val in values.items():
            info[key], info["_" + key] = val, mask.copy()
        return info

    def step(
        self, actions: ArrayLike
    ) -> tuple[NDArray[np.float32], NDArray[np.float32], NDArray[np.bool_], NDArray[np.bool_], dict[str, Any]]:
        """Step every slot; see the class docstring for auto-reset and the info layout."""
        v = self.venv
        mode = self.autoreset_mode
        if mode == AutoresetMode.DISABLED and self._ended.any():
            raise FormationError(
                f"envs {np.flatnonzero(self._ended).tolist()} have finished: autoreset_mode is DISABLED, reset them "
                "with reset(options={'reset_mask': mask}) before step()"
            )
        v._set_actions(actions)
        k = v._per_env
        pending = np.flatnonzero(self._ended) if mode == AutoresetMode.NEXT_STEP else np.zeros(0, np.int64)
        rngs: list[np.random.Generator] | None = None
        if pending.size:  # their new episodes, drawn before the step as their single envs do; not stepped
            fresh, fresh_pose, fresh_obs = v._fresh(pending)
            rngs = list(v._rngs)
            for b in pending.tolist():  # the step's noise of a pending env must not draw from its generator
                rngs[b] = np.random.default_rng(0)
        obs, rews, _, envs, final = v._step_slots(autoreset=mode == AutoresetMode.SAME_STEP, rngs=rngs)
        term, trunc = v.last_terminated.copy(), v.last_truncated.copy()
        values = v._slot_info()
        if pending.size:
            v._put(pending, fresh, fresh_pose)
            slots = v._slots(pending)
            obs[slots], rews[slots] = fresh_obs, 0.0
            term[pending] = trunc[pending] = False
            for key, val in v._reset_info(fresh).items():
                values[key][slots] = val
            envs = envs[~np.isin(envs, pending)]
        self._ended = term | trunc
        info = self._mask_info(values, np.ones(self.num_envs, bool))
        if mode == AutoresetMode.SAME_STEP and envs.size:
            slots = v._slots(envs)
            done = np.zeros(self.num_envs, bool)
            done[slots] = True
            final_obs = np.full(self.num_envs, None, dtype=object)
            for s, fin in zip(slots.tolist(), final, strict=True):
                final_obs[s] = fin
            final_info: dict[str, Any] = {}
            for key, val in values.items():
                col = np.zeros(self.num_envs, val.dtype)
                col[slots] = val[slots]
                final_info[key], final_info["_" + key] = col, done.copy()
            fresh_info = v._reset_info(Engine.select(v.state, envs))  # type: ignore[arg-type]
            for key, val in fresh_info.items():  # the slots reset in the step report the reset's info
                info[key][slots] = val
            info.update(final_obs=final_obs, _final_obs=done.copy(), final_info=final_info, _final_info=done)
        self._obs = obs
        return obs, rews, np.repeat(term, k), np.repeat(trunc, k), info

    def render(self) -> tuple[NDArray[np.uint8], ...] | None:  # type: ignore[override]
        """A frame per slot (``rgb_array``; the slots of an env share its frame), or None."""
        if self.render_mode != "rgb_array" or self.venv.state is None:
            return None
        frames = self.venv.get_images()
        return tuple(frames[s // self.venv._per_env] for s in range(self.num_envs))  # type: ignore[misc]

    def close_extras(self, **kwargs: Any) -> None:
        """Close the batch's renderer (nothing to close when the construction was refused before the batch)."""
        venv = self.__dict__.get("venv")
        if venv is not None:
            venv.close()
