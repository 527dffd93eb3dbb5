"""B copies of the formation env stepped as one batch: a Stable-Baselines3 ``VecEnv`` and a Gymnasium adapter.

:class:`FormationVecEnv` holds one batched :class:`~formation_env.env.engine.EngineState`
of B environments and steps them with one call of the same pure ``Engine.step`` that the
PettingZoo env runs with B = 1, so there is one step function and no per-env Python loop
on the hot path. Two slot layouts:

============  ==============  ===========================================  ==========================
mode          slots           observation of a slot                        action of a slot
============  ==============  ===========================================  ==========================
``shared``    B x n_l         one leader's observation (``obs_dim``,)      that leader's (p,) in [-1, 1]
``commander`` B               the global state (``state_dim``,)            every leader's (n_l p,)
============  ==============  ===========================================  ==========================

Slot ``b * n_l + j`` in ``shared`` mode is leader j of env b (one policy for every leader,
parameter sharing). The ``commander`` slot is ``FormationCommander-v0`` with ``action_mode="leaders"``: its reward
is the mean of the leaders' rewards.

Seeding and auto-reset: env b draws its episodes from its own generator
``np.random.default_rng(seed + b)`` (B = 1 draws each), so env b of the batch replays,
to rounding, the single env reset with ``seed + b`` and given the same actions, episode
after episode. Episodes are drawn ahead: once ``draw_ahead`` envs (default B / 4) have
used up their next episode, the next episode of every such env is drawn in one batch, since
a reset costs much less per env in a large batch than in the few envs that finish in a step. The
draws of an env still come from its generator in order, so the episodes are the same.
A finished env is reset in the same step (SB3 convention): its slot's
``info`` holds ``terminal_observation`` and, for a time-limit cut that is no true end,
``TimeLimit.truncated = True`` (SB3 then bootstraps its value). Other slots get empty
info dicts, a fresh one each (as SB3's own vec envs give them); with ``share_empty_infos=True`` they
share one read-only empty dict instead (:data:`EMPTY_INFO`), which saves making and freeing
B n_l dicts a step (see :class:`FormationVecEnv`). The batched engine info of the last step is
``last_info`` (arrays (B,)).

Gymnasium: :meth:`FormationVecEnv.to_gymnasium` (or :class:`GymnasiumFormationVecEnv`)
wraps it as a ``gymnasium.vector.VectorEnv`` with same-step auto-reset
(``AutoresetMode.SAME_STEP``: ``info["final_obs"]``, ``info["final_info"]`` (a dict of arrays over
slots, as Gymnasium's ``SyncVectorEnv`` makes it) and the masks ``info["_final_obs"]``), separate
``terminated`` / ``truncated`` arrays.

Example::

    from stable_baselines3 import PPO
    from formation_env.env.vector import FormationVecEnv

    venv = FormationVecEnv("narrow_passage", num_envs=64, mode="shared")
    PPO("MlpPolicy", venv, seed=0).learn(10_000)
"""

from __future__ import annotations

import pickle
import pickletools
from collections.abc import Sequence
from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces
from numpy.typing import ArrayLike, NDArray
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvIndices

from formation_env.core.errors import FormationError

from . import _kernel
from .engine import Engine, EngineState

__all__ = ["EMPTY_INFO", "MODES", "FormationVecEnv", "GymnasiumFormationVecEnv", "reset_batch", "stack_states"]

#: Slot layouts of :class:`FormationVecEnv`.
MODES: tuple[str, ...] = ("shared", "commander")

#: Engine info entries copied into a finished slot's info dict.
_DONE_INFO = ("success", "collision", "out_of_bounds", "formation_error", "goal_distance", "time")
_INFO_KEYS = (*_DONE_INFO, "TimeLimit.truncated")


class _EmptyInfo(dict[str, Any]):
    """An empty info dict that refuses to be written: shared by the slots that did not finish a step
    (``FormationVecEnv(share_empty_infos=True)``). Reads (``get``, ``in``, iteration, ``**info``) are a dict's;
    a write that would add a key raises TypeError naming the option; copies (``copy``, ``dict(info)``,
    ``copy.deepcopy``, pickling) are plain writable dicts."""

    __slots__ = ()

    def _refuse(self, what: str) -> TypeError:
        return TypeError(
            f"info dict {what}: the slots that did not finish this step share one read-only empty info dict "
            "(FormationVecEnv(share_empty_infos=True)); copy it first (dict(info)), or make the env with "
            "share_empty_infos=False for a fresh dict per slot"
        )

    def __setitem__(self, key: Any, value: Any) -> None:
        raise self._refuse(f"write of {key!r}")

    def setdefault(self, key: Any, default: Any = None) -> Any:
        raise self._refuse(f"setdefault({key!r})")

    def update(self, *args: Any, **kwargs: Any) -> None:
        if dict(*args, **kwargs):
            raise self._refuse("update")

    def __ior__(self, other: Any) -> _EmptyInfo:  # type: ignore[misc,override]
        if dict(other):
            raise self._refuse("|=")
        return self

    def __copy__(self) -> dict[str, Any]:
        return {}

    def __deepcopy__(self, memo: dict[int, Any]) -> dict[str, Any]:
        return {}

    def __reduce__(self) -> tuple[type, tuple[()]]:
        return (dict, ())


#: The read-only empty info of every slot that did not finish a step, with ``share_empty_infos=True``.
EMPTY_INFO: dict[str, Any] = _EmptyInfo()


def stack_states(states: Sequence[EngineState]) -> EngineState:
    """Concatenate engine states along the batch dim (params stay read-only): ``Engine.concat``."""
    return Engine.concat(list(states))


def reset_batch(engine: Engine, rngs: Sequence[np.random.Generator]) -> EngineState:
    """One new episode per generator, batched: entry b equals ``engine.reset(rngs[b], 1)``.

    Uses ``Engine.reset_each`` (scenario draws per generator, the rest batched) where the engine
    has it, else stacks one ``Engine.reset`` per generator.
    """
    each = getattr(engine, "reset_each", None)
    if each is not None:
        return each(list(rngs))
    return stack_states([engine.reset(g, 1) for g in rngs])


_FIELDS = ("x", "pos", "vel", "memory", "k", "ref", "goal_dist", "err", "streak")


def _scatter(
    dst: EngineState, idx: NDArray[np.int64], src: EngineState, src_idx: NDArray[np.int64] | None = None
) -> None:
    """Write ``src`` (len(idx) envs, or its rows ``src_idx``) into rows ``idx`` of ``dst``, in place (``dst`` is
    owned by the vec env)."""
    for f in _FIELDS:
        a = getattr(dst, f)
        if a is not None and a.size:
            a[idx] = getattr(src, f) if src_idx is None else getattr(src, f)[src_idx]
    for key, arr in dst.params.items():
        if not arr.size:  # no obstacles of that kind: nothing to copy (a fancy copy costs ~4 us even so)
            continue
        arr.setflags(write=True)
        arr[idx] = src.params[key] if src_idx is None else src.params[key][src_idx]
        arr.setflags(write=False)


def _own(state: EngineState) -> tuple[EngineState, dict[str, NDArray[np.uint8]]]:
    """A copy of ``state`` that shares no array with it (params read-only, as the engine makes them), and
    writable byte rows (:func:`_byte_rows`) of its params, made before they were locked: the vec env owns the
    copy and writes new episodes into it."""
    params, rows = {}, {}
    for key, arr in state.params.items():
        params[key] = own = np.array(arr)
        view = _byte_rows(own)
        if view is not None:
            rows[key] = view
        own.setflags(write=False)
    fields = {f: None if getattr(state, f) is None else np.array(getattr(state, f)) for f in _FIELDS}
    return EngineState(**fields, params=params), rows


def _byte_rows(a: NDArray[Any]) -> NDArray[np.uint8] | None:
    """A (B, row bytes) uint8 view of the (B, ...) array ``a`` for ``_kernel.copy_rows``; None where ``a`` is not
    C-contiguous and writable, or its rows are empty."""
    if not a.size or not a.flags.c_contiguous or not a.flags.writeable:
        return None
    return a.reshape(a.shape[0], -1).view(np.uint8)


class FormationVecEnv(VecEnv):
    """B formation envs in one batched engine, as an SB3 ``VecEnv`` (see the module docstring).

    Args:
        scenario: a scenario name (``formation_env.env.scenarios.REGISTRY``).
        num_envs: B, the number of environment copies (not of slots).
        mode: ``"shared"`` (one slot per leader) or ``"commander"`` (one slot per env).
        seed: seed of the first reset (env b gets ``seed + b``); None draws fresh entropy.
        engine: an existing ``Engine`` to step (then ``env_kwargs`` must be empty).
        draw_ahead: draw the next episodes of the envs that have used theirs up, in one batch, once this many
            have (0: draw an env's next episode when it finishes). None: ``num_envs // 4``, or 0 below 8 envs.
        share_empty_infos: False (default): every slot's info is a dict of its own, as SB3's vec envs make them.
            True: the slots that did not finish the step all hold :data:`EMPTY_INFO`, one read-only empty dict
            (a finished slot still gets its own dict with ``terminal_observation``). SB3's algorithms, buffers and
            wrappers only read those infos (they write only into finished slots'), and a write raises TypeError;
            it saves making and freeing B n_l dicts a step (3,072 at B = 1024 in shared mode), about a fifth of
            the step's time there (``python -m benchmarks.vec_profile``).
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
        draw_ahead: int | None = None,
        share_empty_infos: bool = False,
        **env_kwargs: Any,
    ) -> None:
        if mode not in MODES:
            raise FormationError(f"mode must be one of {list(MODES)}, got {mode!r}")
        if int(num_envs) != num_envs or num_envs < 1:
            raise FormationError(f"num_envs must be a positive integer, got {num_envs}")
        if engine is not None and env_kwargs:
            raise TypeError(f"pass either engine= or engine keyword arguments, not both (got {sorted(env_kwargs)})")
        if render_mode not in (None, "rgb_array"):
            raise FormationError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        if not isinstance(share_empty_infos, bool):
            raise FormationError(f"share_empty_infos must be True or False, got {share_empty_infos!r}")
        if draw_ahead is None:
            draw_ahead = int(num_envs) // 4 if num_envs >= 8 else 0
        if int(draw_ahead) != draw_ahead or draw_ahead < 0:
            raise FormationError(f"draw_ahead must be a non-negative integer, got {draw_ahead}")
        self.engine = eng = engine if engine is not None else Engine(scenario, **env_kwargs)
        self.mode = mode
        self.n_envs = B = int(num_envs)
        self.n_l, self.p = eng.n_l, eng.p
        self.render_mode = render_mode
        if mode == "shared":
            obs_space = spaces.Box(eng.obs_low, eng.obs_high, dtype=np.float32)
            act_space = spaces.Box(-1.0, 1.0, (eng.p,), dtype=np.float32)
            slots = B * eng.n_l
        else:
            obs_space = spaces.Box(eng.state_low, eng.state_high, dtype=np.float32)
            act_space = spaces.Box(-1.0, 1.0, (eng.n_l * eng.p,), dtype=np.float32)
            slots = B
        self._per_env = eng.n_l if mode == "shared" else 1
        super().__init__(slots, obs_space, act_space)
        self.share_empty_infos = share_empty_infos
        # a list of `slots` distinct empty dicts, pickled without its memo entries (``pickletools.optimize``: none is
        # referred to again): loading it was the quickest way we measured to make the step's infos (against the
        # pickle with its memo, marshal, map(dict.copy, ...) and a list comprehension)
        empty = pickle.dumps([{} for _ in range(slots)], protocol=pickle.HIGHEST_PROTOCOL)
        self._empty_infos = pickletools.optimize(empty)
        self._next_seed: int | None = seed
        self._rngs: tuple[np.random.Generator, ...] = ()  # env b's generator (a tuple: none is replaced alone)
        self._bits: tuple[NDArray[np.int64], NDArray[np.int64]] | None = None  # their bit generators' addresses
        self._bits_of: tuple[np.random.Generator, ...] = ()  # the generators those addresses are of
        self.state: EngineState | None = None
        self.draw_ahead = int(draw_ahead)
        self._spare: EngineState | None = None  # the next episode of each env (rows where _has_spare), drawn ahead
        self._spare_obs: NDArray[np.float32] | None = None  # and its first observation, per slot
        self._spare_rows: dict[str, NDArray[np.uint8]] = {}  # byte rows of the spares' arrays (fields, params, obs)
        self._param_rows: dict[str, NDArray[np.uint8]] = {}  # and of self.state's params (for _kernel.copy_rows)
        self._params_owned: dict[str, NDArray[Any]] | None = None  # the params those rows belong to
        self._row_keys: tuple[str, ...] = ()  # _cache_param_rows: the fields (and obs) _take_spares copies
        self._param_views: list[NDArray[np.uint8]] = []  # and the byte rows of params, state's and spares'
        self._param_src: tuple[NDArray[np.uint8], ...] = ()
        self._has_spare = np.zeros(B, dtype=bool)
        self._actions: NDArray[np.float64] | None = None
        self.last_info: dict[str, Any] = {}
        self.last_terminated = self.last_truncated = np.zeros(self.n_envs, dtype=bool)
        self._renderer: Any = None

    # ---------------------------------------------------------------- batched observation
    def _observe(self, state: EngineState, leader_obs: NDArray[np.float32] | None = None) -> NDArray[np.float32]:
        """Slot observations (num_envs, obs dim) of ``state`` (``leader_obs``: the step's, if at hand)."""
        if self.mode == "commander":
            return self.engine.global_state(state)
        lo = self.engine.observe(state) if leader_obs is None else leader_obs
        return lo.reshape(state.batch_size * self.n_l, -1)

    def _draw(self, envs: NDArray[np.int64]) -> tuple[EngineState, NDArray[np.float32]]:
        """New episodes for envs ``envs``, each from its own generator (B = 1 draws, as the single env), and their
        leaders' observations (``Engine.reset_each_observed``: from the reset's own measurement)."""
        if self._bits_of is not self._rngs:  # looked up once per set of generators (held here: the addresses stay)
            self._bits, self._bits_of = _kernel.bit_generators(list(self._rngs)), self._rngs
        bits = None if self._bits is None else (self._bits[0][envs], self._bits[1])
        return self.engine.reset_each_observed([self._rngs[b] for b in envs], bits)

    def _slots(self, envs: NDArray[np.int64]) -> NDArray[np.int64]:
        """The slots of envs ``envs``, env by env."""
        k = self._per_env
        return (envs[:, None] * k + np.arange(k)).reshape(-1) if k > 1 else envs

    def _next_episodes(self, envs: NDArray[np.int64], obs: NDArray[np.float32]) -> None:
        """Start the next episode of envs ``envs`` (sorted) in ``self.state`` and their slots of ``obs``.

        With ``draw_ahead`` > 0 they come from the spares; when one of them has none, or ``draw_ahead`` envs
        have none, every env without a spare draws its next episode first, in one batch."""
        if self.draw_ahead == 0:
            fresh, lobs = self._draw(envs)
            _scatter(self.state, envs, fresh)
            obs[self._slots(envs)] = self._observe(fresh, lobs)
            return
        empty = ~self._has_spare
        if empty[envs].any() or np.count_nonzero(empty) >= self.draw_ahead:
            fill = np.flatnonzero(empty)
            fresh, lobs = self._draw(fill)
            if self._spare is None:
                self._spare, params = _own(self.state)
                self._spare_obs = np.empty_like(obs)
                rows = {f: _byte_rows(getattr(self._spare, f)) for f in _FIELDS if getattr(self._spare, f) is not None}
                rows.update({"params." + key: v for key, v in params.items()})
                rows["obs"] = _byte_rows(self._spare_obs.reshape(self.n_envs, -1))
                self._spare_rows = {key: v for key, v in rows.items() if v is not None}
                self._cache_param_rows()
            _scatter(self._spare, fill, fresh)
            self._spare_obs[self._slots(fill)] = self._observe(fresh, lobs)
            self._has_spare[fill] = True
        self._take_spares(envs, obs)
        self._has_spare[envs] = False

    def _cache_param_rows(self) -> None:
        """The fixed parts of ``_take_spares``' copy: the byte rows of the state's params and of the spares' (both
        owned by the vec env, kept across steps), and the state fields (and obs) it copies."""
        arrays = [(f, getattr(self.state, f)) for f in _FIELDS]
        self._row_keys = tuple(f for f, a in arrays if a is not None and a.size) + ("obs",)
        pairs = [(v, self._spare_rows.get("params." + k)) for k, v in self._param_rows.items()]
        self._param_views = [v for v, src in pairs if src is not None]
        self._param_src = tuple(src for _, src in pairs if src is not None)

    def _take_spares(self, envs: NDArray[np.int64], obs: NDArray[np.float32]) -> None:
        """Rows ``envs`` of the spares into ``self.state`` and into the slots of ``obs`` (those of env b are rows
        b k to b k + k - 1): one ``_kernel.copy_rows`` for every C-contiguous array, numpy for the rest."""
        state, spare, B = self.state, self._spare, self.n_envs
        if not _kernel.AVAILABLE or state.params is not self._params_owned:
            _scatter(state, envs, spare, envs)
            slots = self._slots(envs)
            obs[slots] = self._spare_obs[slots]
            return
        src, rows = [], self._spare_rows
        dst: list[NDArray[np.uint8]] = []
        for key in self._row_keys:  # the state's arrays are new each step: their byte rows too
            a = obs.reshape(B, -1) if key == "obs" else getattr(state, key)
            view = _byte_rows(a)
            if view is None or key not in rows:
                a[envs] = (getattr(spare, key) if key != "obs" else self._spare_obs.reshape(B, -1))[envs]
            else:
                dst.append(view)
                src.append(rows[key])
        dst += self._param_views
        _kernel.copy_rows(tuple(dst), envs, (*src, *self._param_src), envs)

    # ---------------------------------------------------------------- VecEnv API
    def seed(self, seed: int | None = None) -> Sequence[int | None]:
        """Seed the next reset: env b (all its slots) gets ``seed + b``; returns the seed of every slot."""
        if seed is None:
            seed = int(np.random.SeedSequence().generate_state(1)[0])
        self._next_seed = int(seed)
        return [self._next_seed + s // self._per_env for s in range(self.num_envs)]

    def reset(self) -> NDArray[np.float32]:
        """Reset every env (with the seed given to :meth:`seed` or the constructor, if any); (num_envs, obs dim)."""
        B = self.n_envs
        if self._next_seed is not None:
            self._rngs = tuple(np.random.default_rng(self._next_seed + b) for b in range(B))
            self._next_seed = None
            self._has_spare[:] = False  # drawn from the old generators
        elif not self._rngs:
            root = np.random.SeedSequence()
            self._rngs = tuple(np.random.default_rng(s) for s in root.spawn(B))
        if self._has_spare.any():  # the envs' next episodes, drawn ahead (the same generators go on)
            state, self._param_rows = _own(self._spare)
            need = np.flatnonzero(~self._has_spare)
            if need.size:
                _scatter(state, need, self._draw(need)[0])
            self._has_spare[:] = False
        else:  # own every array: auto-resets write rows in place
            state, self._param_rows = _own(self._draw(np.arange(B))[0])
        self.state = state
        self._params_owned = state.params
        self._cache_param_rows()
        self.reset_infos = [{} for _ in range(self.num_envs)]
        self._reset_options()
        return self._observe(self.state)

    def step_async(self, actions: ArrayLike) -> None:
        """Store the actions of every slot: (num_envs, p) shared, (num_envs, n_l p) commander."""
        self._actions = np.asarray(actions, dtype=np.float64)

    def _step_slots(
        self,
    ) -> tuple[NDArray[np.float32], NDArray[np.float32], NDArray[np.bool_], NDArray[np.int64], NDArray[np.float32]]:
        """Step all B envs and auto-reset the finished ones, with no per-slot Python objects: (obs, rewards,
        dones) per slot, the finished envs (sorted; empty if none) and their slots' last observations, rows
        of a copy. The engine's info arrays and flags stay in ``last_info``, ``last_terminated``,
        ``last_truncated``."""
        if self._actions is None:
            raise RuntimeError("step_wait called before step_async")
        if self.state is None:
            raise RuntimeError("reset() must be called before step()")
        B, k = self.n_envs, self._per_env
        expect = (self.num_envs, self.action_space.shape[0])  # type: ignore[index]
        if self._actions.shape != expect:
            raise FormationError(f"actions must have shape {expect} (slots, action dim), got {self._actions.shape}")
        a = self._actions.reshape(B, self.n_l, self.p)
        self._actions = None
        state, lobs, rew, term, trunc, info = self.engine.step(self.state, a)
        self.state = state
        self.last_info = info
        self.last_terminated, self.last_truncated = term, trunc
        obs = self._observe(state, lobs)
        if k > 1:
            rews = rew.astype(np.float32).reshape(-1)
        else:  # the mean over leaders (np.mean costs ~10 µs more at B = 1)
            rews = (rew.sum(axis=1) * (1.0 / self.n_l)).astype(np.float32)
        done_env = term | trunc
        dones = np.repeat(done_env, k) if k > 1 else done_env.copy()
        envs = np.flatnonzero(done_env)
        if not envs.size:
            return obs, rews, dones, envs, obs[:0]
        # a copy (obs is overwritten next): env rows of the (B, k, obs dim) view, one index per env, not per slot
        final = obs.reshape(B, k, -1)[envs].reshape(envs.size * k, -1)
        self._next_episodes(envs, obs)
        return obs, rews, dones, envs, final

    def _done_infos(self, envs: NDArray[np.int64]) -> list[dict[str, Any]]:
        """The info of each finished env of ``envs``: ``last_info``'s scalars and ``TimeLimit.truncated``; one dict
        per env, to copy for each of its slots."""
        info, term, trunc = self.last_info, self.last_terminated, self.last_truncated
        cols = [info[key][envs].tolist() for key in _DONE_INFO]
        cols.append((trunc[envs] & ~term[envs]).tolist())
        return [dict(zip(_INFO_KEYS, v, strict=True)) for v in zip(*cols, strict=True)]

    def _slot_infos(
        self, envs: NDArray[np.int64], final: NDArray[np.float32]
    ) -> tuple[list[int], list[dict[str, Any]], list[NDArray[np.float32]]]:
        """(slot, its own info dict, its last observation) of every slot of the finished envs ``envs``."""
        k = self._per_env
        infos = [inf if j == 0 else inf.copy() for inf in self._done_infos(envs) for j in range(k)]
        return self._slots(envs).tolist(), infos, list(final)

    def step_wait(self) -> tuple[NDArray[np.float32], NDArray[np.float32], NDArray[np.bool_], list[dict[str, Any]]]:
        """Step all B envs, auto-reset the finished ones; (obs, rewards, dones, infos) per slot."""
        obs, rews, dones, envs, final = self._step_slots()
        if self.share_empty_infos:
            infos = [EMPTY_INFO] * self.num_envs
        else:
            infos = pickle.loads(self._empty_infos)  # fresh empty dicts, made in C
        if envs.size:
            for s, inf, fin in zip(*self._slot_infos(envs, final), strict=True):
                inf["terminal_observation"] = fin
                infos[s] = inf
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
        value = getattr(owner, attr_name)
        return [value for _ in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        """Set an attribute shared by every slot (all slots share one engine)."""
        setattr(self, attr_name, value)

    def env_method(
        self, method_name: str, *method_args: Any, indices: VecEnvIndices = None, **method_kwargs: Any
    ) -> list[Any]:
        """Call an engine method once per slot in ``indices``."""
        fn = getattr(self.engine, method_name)
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
        """Reset every env; ``seed`` seeds env b with ``seed + b``."""
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

    def close_extras(self, **kwargs: Any) -> None:
        """Nothing to release."""
