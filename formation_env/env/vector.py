"""B copies of the formation env stepped as one batch: a Stable-Baselines3 ``VecEnv`` and a Gymnasium adapter.

:class:`FormationVecEnv` is the SB3 face of :class:`~formation_env.env.batch.FormationBatch`: one batched
:class:`~formation_env.env.state.EngineState` of B environments stepped with one call of the same pure
``Engine.advance`` that the PettingZoo env runs with B = 1. Two slot layouts:

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

Gymnasium: :meth:`FormationVecEnv.to_gymnasium` wraps the same batch as a ``gymnasium.vector.VectorEnv``
(:class:`~formation_env.env.batch.GymnasiumFormationVecEnv`, Gymnasium's auto-reset modes); ``gym.make_vec(id,
num_envs=N)`` builds one for any ``formation_env`` id without stable-baselines3.

Example::

    from stable_baselines3 import PPO
    from formation_env.env.vector import FormationVecEnv

    venv = FormationVecEnv("narrow_passage", num_envs=64, mode="shared")
    PPO("MlpPolicy", venv, seed=0).learn(10_000)
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode
from numpy.typing import ArrayLike, NDArray
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvIndices

from formation_env.core.validation import check_seed

from .batch import MODES, FormationBatch, GymnasiumFormationVecEnv
from .engine import INFO_KEYS

__all__ = ["MODES", "FormationVecEnv", "GymnasiumFormationVecEnv"]

#: Engine info entries copied into a finished slot's info dict.
_DONE_INFO = tuple(key for key in INFO_KEYS if key != "control_effort")


class FormationVecEnv(FormationBatch, VecEnv):  # type: ignore[misc]  # Box spaces narrow VecEnv's Space
    """B formation envs in one batched engine, as an SB3 ``VecEnv`` (see the module docstring).

    Takes the arguments of :class:`~formation_env.env.batch.FormationBatch`: ``scenario``, ``num_envs`` (B, the
    number of environment copies, not of slots), ``mode`` (``"shared"``: one slot per leader, ``"commander"``:
    one per env), ``seed`` (env b gets ``seed + b``), ``engine``, ``render_mode``, ``action_mode``,
    ``maneuver_kwargs``, ``critic_state``, ``max_episode_steps`` and the ``Engine`` keyword arguments.

    Attributes:
        engine: the shared ``Engine``. state: the batched ``EngineState`` (B envs).
        n_envs: B. num_envs: slots (B n_l in ``shared`` mode, B in ``commander`` mode).
        last_info: the engine's info arrays of the last step, before auto-reset.
        last_terminated, last_truncated: the (B,) flags of the last step.
    """

    metadata = {"render_modes": ["rgb_array"]}

    def __init__(self, scenario: str = "narrow_passage", num_envs: int = 8, mode: str = "shared",
                 seed: int | None = None, **kwargs: Any) -> None:  # fmt: skip
        FormationBatch.__init__(self, scenario, num_envs, mode, seed, **kwargs)
        VecEnv.__init__(self, self.num_envs, self.observation_space, self.action_space)

    def seed(self, seed: int | None = None) -> Sequence[int | None]:
        """Seed the next reset: env b (all its slots) gets ``seed + b``; returns the seed of every slot."""
        if seed is None:
            seed = int(np.random.SeedSequence().generate_state(1)[0])
        self._next_seed = check_seed(seed)
        return [self._next_seed + s // self._per_env for s in range(self.num_envs)]

    def reset(self) -> NDArray[np.float32]:
        """Reset every env (with the seed given to :meth:`seed` or the constructor, if any); (num_envs, obs dim)."""
        obs = self._reset_all()
        self.reset_infos = [{} for _ in range(self.num_envs)]
        self._reset_options()
        return obs

    def step_async(self, actions: ArrayLike) -> None:
        """Check and store the actions of every slot: (num_envs, p) shared, (num_envs, n_l p) commander."""
        self._set_actions(actions)

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

    def render(self, mode: str | None = None) -> NDArray[np.uint8] | None:
        """An RGB frame of env 0 (``rgb_array``), or None."""
        if (mode or self.render_mode) != "rgb_array" or self.state is None:
            return None
        return self.get_images()[0]

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

    def to_gymnasium(self, autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP) -> GymnasiumFormationVecEnv:
        """This env as a ``gymnasium.vector.VectorEnv`` over the same state (``autoreset_mode``: Gymnasium's)."""
        return GymnasiumFormationVecEnv(self, autoreset_mode)
