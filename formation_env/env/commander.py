"""``FormationCommander-v0``: one Gymnasium policy commands every leader (single-agent view).

Registered on ``import formation_env`` as ``gym.make("formation_env/FormationCommander-v0", ...)``.
Same engine and scenarios as the PettingZoo env (B = 1).
"""

from __future__ import annotations

from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode
from numpy.typing import NDArray

from formation_env.core.errors import FormationError
from formation_env.core.validation import as_array

from .engine import Engine, EngineState, StepInfo
from .formation import SingleEnv
from .maneuver import Pose, PoseCommand
from .state import StepContext
from .versions import with_version

__all__ = ["ACTION_MODES", "FormationCommanderEnv", "vector", "versioned"]

ACTION_MODES = ("leaders", "maneuver")


# gymnasium types Env.render() with an unbound TypeVar (RenderFrame): SingleEnv.render's (H, W, 3) uint8 array
# is such a frame, which mypy cannot tell
class FormationCommanderEnv(SingleEnv, gym.Env[NDArray[np.float32], NDArray[np.float32]]):  # type: ignore[misc]
    """A single-agent view of the formation env: one action commands all leaders.

    ## Description

    The scenario, dynamics, follower law and reward terms of ``formation_v0`` (see
    :class:`formation_env.env.formation.FormationEnv`), with one policy for the whole team.

    ## Action Space

    ``action_mode="leaders"``: ``Box(-1, 1, (n_l p,))``, every leader's action concatenated in
    leader order (scaled by ``u_max`` as in ``formation_v0``; clipped; NaN/inf raise ValueError; another
    shape, e.g. (n_l, p), is refused).

    ``action_mode="maneuver"``: ``Box(-1, 1, (d (d + 1),))`` sets rates of a commanded pose
    Theta_c = R (I + H) diag(s), b_c: [velocity of b_c (d) | log-scale rates of s per axis (d) |
    rotation rate (2D: 1, angle; 3D: 3, rotation vector) | shear rates of the strictly upper
    triangle of H (d (d - 1) / 2)], scaled by ``pose_speed`` (m/s), ``scale_rate`` (1/s),
    ``rotation_rate`` (rad/s), ``shear_rate`` (1/s). s is kept in ``scale_range``, H in [-1, 1],
    b_c in the world box. The leaders track their targets Theta_c r_l + b_c with saturated
    commands (``control.track_targets``). The pose starts as the QR factors of the start pose.

    ## Observation Space

    The global state (``FormationEnv.state()``), float32, finite bounds; in ``maneuver`` mode
    followed by the commanded Theta_c (d^2, row-major, in [-6, 6]) and b_c (d, world box).

    ## Rewards

    The mean over leaders of the ``formation_v0`` leader rewards.

    ## Starting State, Episode End

    As ``formation_v0``. ``info`` holds the same metrics (``control_effort`` summed over leaders).

    ## Arguments

    ``gym.make("formation_env/FormationCommander-v0", scenario="narrow_passage",
    action_mode="leaders", render_mode=None, **kwargs)`` with the keyword arguments of
    ``formation_v0.parallel_env`` and, for ``maneuver`` only, ``pose_speed`` (1.0), ``scale_rate`` (0.5),
    ``rotation_rate`` (0.5), ``shear_rate`` (0.5), ``scale_range`` ((0.2, 2.0)) (None: the default).

    ## Version History

    * v0: initial version.
    """

    metadata: dict[str, Any] = {"render_modes": ["human", "rgb_array"], "render_fps": 10}

    def __init__(
        self,
        scenario: str = "narrow_passage",
        action_mode: str = "leaders",
        render_mode: str | None = None,
        *,
        pose_speed: float | None = None,
        scale_rate: float | None = None,
        rotation_rate: float | None = None,
        shear_rate: float | None = None,
        scale_range: tuple[float, float] | None = None,
        **kwargs: Any,
    ) -> None:
        if action_mode not in ACTION_MODES:
            raise FormationError(f"action_mode must be one of {list(ACTION_MODES)}, got {action_mode!r}")
        self._check_render_mode(render_mode)
        given: dict[str, Any] = {"pose_speed": pose_speed, "scale_rate": scale_rate, "rotation_rate": rotation_rate,
                                 "shear_rate": shear_rate, "scale_range": scale_range}  # fmt: skip
        pose_kwargs = {key: val for key, val in given.items() if val is not None}
        if pose_kwargs and action_mode != "maneuver":
            raise TypeError(f"{', '.join(pose_kwargs)} apply to action_mode='maneuver' only, not to {action_mode!r}")
        self.engine = eng = Engine(scenario, **kwargs)
        self.action_mode = action_mode
        self.render_mode = render_mode
        self.command = PoseCommand(eng, **pose_kwargs) if action_mode == "maneuver" else None
        low, high = eng.state_low, eng.state_high
        n_act = eng.n_l * eng.p if self.command is None else self.command.action_dim
        self.action_space = spaces.Box(-1.0, 1.0, (n_act,), dtype=np.float32)
        if self.command is not None:
            low = np.concatenate([low, self.command.obs_low])
            high = np.concatenate([high, self.command.obs_high])
        self.observation_space = spaces.Box(low, high, dtype=np.float32)
        self._state: EngineState | None = None
        self._done = False
        self._pose: Pose | None = None

    # ------------------------------------------------------------------ gym API
    def _obs(self, ctx: StepContext | None = None) -> NDArray[np.float32]:
        """The observation of the current state (``ctx``: the context of the step that made it, if any)."""
        g = self.engine.global_state(self._state_or_raise("step"), ctx)[0]
        if self.command is None or self._pose is None:
            return g
        return np.concatenate([g, self.command.observe(self._pose)[0].astype(np.float32)])

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[NDArray[np.float32], dict[str, Any]]:
        self._check_reset(seed, options)
        super().reset(seed=seed)
        self._state = self.engine.reset(self.np_random, 1)
        self._done = False
        if self.command is not None:
            self._pose = self.command.reset(self._state)
        self._show(reset=True)
        return self._obs(), self._reset_info()

    def step(self, action: Any) -> tuple[NDArray[np.float32], SupportsFloat, bool, bool, dict[str, Any]]:
        state = self._state_or_raise("step")
        if self._done:
            raise FormationError("the episode is over: call reset() before step()")
        eng = self.engine
        a = as_array(action, "action", finite=False)
        if a.shape != self.action_space.shape:
            raise ValueError(f"action must have shape {self.action_space.shape}, got {a.shape}")
        if self.command is None or self._pose is None:
            leader_a = a.reshape(1, eng.n_l, eng.p)
        else:
            self._pose, leader_a = self.command.step(state, self._pose, a[None])
        self._state, ctx, rew, term, trunc, inf = eng.advance(state, leader_a, self.np_random, observe="state")
        out = StepInfo({key: val[0].item() for key, val in inf.items() if key != "control_effort"})
        out["control_effort"] = float(inf["control_effort"][0].sum())
        terminated, truncated = bool(term[0]), bool(trunc[0])
        self._done = terminated or truncated
        self._show()
        return self._obs(ctx), float(rew[0].mean()), terminated, truncated, out


def versioned(version: int, **kwargs: Any) -> FormationCommanderEnv:
    """The commander env with env version ``version``'s defaults under ``kwargs`` (the ``-v1`` Gymnasium ids)."""
    return FormationCommanderEnv(**with_version(version, kwargs))


def vector(
    num_envs: int = 1,
    *,
    scenario: str = "narrow_passage",
    version: int = 0,
    action_mode: str = "leaders",
    render_mode: str | None = None,
    max_episode_steps: int | None = None,
    autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
    pose_speed: float | None = None,
    scale_rate: float | None = None,
    rotation_rate: float | None = None,
    shear_rate: float | None = None,
    scale_range: tuple[float, float] | None = None,
    **kwargs: Any,
) -> Any:
    """``num_envs`` commander envs in one batch: the ``vector_entry_point`` of every ``formation_env`` Gymnasium id.

    ``gym.make_vec(id, num_envs=N, **kwargs)`` calls it with the id's ``scenario`` (and ``version``), its
    ``max_episode_steps`` and the caller's keyword arguments (those of :class:`FormationCommanderEnv`), and gets a
    :class:`~formation_env.env.batch.GymnasiumFormationVecEnv` whose env b replays ``gym.make(id, **kwargs)``
    reset with ``seed + b`` (time limit included), stepped as one batch. ``autoreset_mode``: a
    ``gymnasium.vector.AutoresetMode`` (default ``NEXT_STEP``, as Gymnasium's ``SyncVectorEnv``).
    ``render_mode``: None or ``"rgb_array"``.
    """
    from .batch import FormationBatch, GymnasiumFormationVecEnv

    if action_mode not in ACTION_MODES:
        raise FormationError(f"action_mode must be one of {list(ACTION_MODES)}, got {action_mode!r}")
    given: dict[str, Any] = {"pose_speed": pose_speed, "scale_rate": scale_rate, "rotation_rate": rotation_rate,
                             "shear_rate": shear_rate, "scale_range": scale_range}  # fmt: skip
    pose_kwargs = {key: val for key, val in given.items() if val is not None}
    if pose_kwargs and action_mode != "maneuver":
        raise TypeError(f"{', '.join(pose_kwargs)} apply to action_mode='maneuver' only, not to {action_mode!r}")
    batch = FormationBatch(
        num_envs=num_envs,
        mode="commander",
        render_mode=render_mode,
        action_mode=action_mode,
        maneuver_kwargs=pose_kwargs or None,
        max_episode_steps=max_episode_steps,
        **with_version(version, {"scenario": scenario, **kwargs}),
    )
    return GymnasiumFormationVecEnv(batch, autoreset_mode)
