"""``gym.make_vec(id, num_envs=N)``: the batched env behind Gymnasium's vector API equals N single envs.

Gymnasium 1.2.2 ships no checker for vector envs (``gymnasium.utils.env_checker`` checks a single ``Env``), so
the reference is Gymnasium's own ``SyncVectorEnv`` over ``gym.make(id)`` (``vectorization_mode="sync"``): the
same seeds and actions must give the same observations, rewards, flags and infos in every auto-reset mode, over
many steps with auto-resets (terminations and time-limit cuts).
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import formation_env
from formation_env.core.errors import FormationError
from formation_env.env.batch import GymnasiumFormationVecEnv

ALL_IDS = sorted([*formation_env.SCENARIO_IDS.values(), *formation_env.SCENARIO_IDS_V1.values(),
                  formation_env.COMMANDER_ID, formation_env.COMMANDER_ID_V1])  # fmt: skip


def _same(got: Any, want: Any, where: str) -> None:
    """Equal up to float round-off (the batch runs the kernel with B = N, the single env with B = 1)."""
    if isinstance(want, tuple):  # (obs, info) or a step's five
        assert isinstance(got, tuple) and len(got) == len(want), where
        for i, (g, w) in enumerate(zip(got, want, strict=True)):
            _same(g, w, f"{where}[{i}]")
    elif isinstance(want, dict):
        assert isinstance(got, dict) and set(got) == set(want), f"{where}: keys {sorted(got)} != {sorted(want)}"
        for key in want:
            _same(got[key], want[key], f"{where}[{key!r}]")
    elif want is None:
        assert got is None, where
    elif isinstance(want, np.ndarray) and want.dtype == object:
        assert isinstance(got, np.ndarray) and got.shape == want.shape, where
        for i, (g, w) in enumerate(zip(got, want, strict=True)):
            _same(g, w, f"{where}[{i}]")
    elif np.asarray(want).dtype == np.bool_:
        np.testing.assert_array_equal(got, want, err_msg=where)
    else:
        np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-5, err_msg=where)


@pytest.mark.parametrize("env_id", ALL_IDS)
def test_make_vec_default_is_the_batched_env(env_id):
    venv = gym.make_vec(env_id, num_envs=3)
    assert isinstance(venv, GymnasiumFormationVecEnv) and isinstance(venv, gym.vector.VectorEnv)
    assert venv.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP  # Gymnasium's default, as SyncVectorEnv
    sync = gym.make_vec(env_id, num_envs=3, vectorization_mode="sync")
    assert isinstance(sync, gym.vector.SyncVectorEnv)
    assert venv.single_observation_space == sync.single_observation_space
    assert venv.single_action_space == sync.single_action_space
    assert venv.observation_space == sync.observation_space and venv.action_space == sync.action_space
    assert venv.spec is not None and venv.spec.id == env_id
    assert venv.spec.kwargs["vectorization_mode"] == "vector_entry_point"
    obs, _ = venv.reset(seed=0)
    assert venv.observation_space.contains(obs)


# (id, kwargs of gym.make / make_vec): both versions, both action modes, the time limit and observation noise
# (whose draws share each env's generator with its resets).
CASES = [
    ("formation_env/NarrowPassage-v1", {"max_episode_steps": 12, "obs_noise": 0.05}),
    ("formation_env/ObstacleField-v0", {"max_episode_steps": 30}),
    ("formation_env/Maneuver-v1", {"max_episode_steps": 9, "action_mode": "maneuver"}),
    ("formation_env/FormationCommander-v1", {"scenario": "moving_obstacles", "max_cycles": 15}),
    # a communication network (its draws from each env's generator, seeded at the reset)
    (
        "formation_env/MovingObstacles-v1",
        {
            "max_episode_steps": 20,
            "follower_law": "linear",
            "network": {"delay": 1, "loss": 0.3, "jitter": (0.08, 0.12)},
        },
    ),
]


@pytest.mark.parametrize("mode", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP])
@pytest.mark.parametrize(("env_id", "kwargs"), CASES)
def test_make_vec_equals_sync_vector_env_of_single_envs(env_id, kwargs, mode):
    n, steps = 4, 45
    venv = gym.make_vec(env_id, num_envs=n, autoreset_mode=mode, **kwargs)
    # vector_kwargs reach SyncVectorEnv as before: the reference runs in the same auto-reset mode
    sync = gym.make_vec(env_id, n, vectorization_mode="sync", vector_kwargs={"autoreset_mode": mode}, **kwargs)
    assert sync.metadata["autoreset_mode"] == mode
    _same(venv.reset(seed=7), sync.reset(seed=7), "reset")
    rng = np.random.default_rng(0)
    ends = {"terminated": 0, "truncated": 0}
    for t in range(steps):
        act = (1.5 * rng.uniform(-1, 1, venv.action_space.shape)).astype(np.float32)
        got, want = venv.step(act), sync.step(act)
        for name, g, w in zip(("obs", "reward", "terminated", "truncated", "info"), got, want, strict=True):
            _same(g, w, f"step {t} {name}")
        ends["terminated"] += int(want[2].sum())
        ends["truncated"] += int(want[3].sum())
    assert ends["terminated"] + ends["truncated"] >= n and ends["truncated"] >= 1  # auto-resets happened
    if env_id.startswith("formation_env/ObstacleField"):
        assert ends["terminated"] >= 1


def test_seed_list_and_seed_none_continue_like_single_envs():
    env_id = "formation_env/Hold-v0"
    venv = gym.make_vec(env_id, num_envs=3, max_episode_steps=5)
    sync = gym.make_vec(env_id, num_envs=3, vectorization_mode="sync", max_episode_steps=5)
    _same(venv.reset(seed=[4, 9, 2]), sync.reset(seed=[4, 9, 2]), "seed list")
    for _ in range(7):
        _same(venv.step(np.zeros(venv.action_space.shape)), sync.step(np.zeros(sync.action_space.shape)), "step")
    _same(venv.reset(), sync.reset(), "seed None: each env continues its generator")
    _same(venv.reset(seed=[None, 3, None]), sync.reset(seed=[None, 3, None]), "mixed list")


def test_disabled_autoreset_and_reset_mask_equal_sync_vector_env():
    env_id, n = "formation_env/NarrowPassage-v0", 3
    venv = gym.make_vec(env_id, num_envs=n, autoreset_mode="Disabled", max_episode_steps=4)
    sync = gym.make_vec(env_id, n, vectorization_mode="sync", vector_kwargs={"autoreset_mode": "Disabled"},
                        max_episode_steps=4)  # fmt: skip
    _same(venv.reset(seed=1), sync.reset(seed=1), "reset")
    act = np.full(venv.action_space.shape, 0.3, np.float32)
    for _ in range(4):
        got, want = venv.step(act), sync.step(act)
        _same(got, want, "step")
    assert got[3].all()
    with pytest.raises(FormationError, match=r"DISABLED.*reset_mask"):
        venv.step(act)
    mask = np.array([True, False, True])
    _same(venv.reset(seed=[5, None, 6], options={"reset_mask": mask}),
          sync.reset(seed=[5, None, 6], options={"reset_mask": mask}), "masked reset")  # fmt: skip
    with pytest.raises(FormationError, match="DISABLED"):  # env 1 is still over
        venv.step(act)
    _same(venv.reset(options={"reset_mask": ~mask}), sync.reset(options={"reset_mask": ~mask}), "masked reset 2")
    _same(venv.step(act), sync.step(act), "step after the masked resets")


def test_gymnasium_vector_wrappers_run_on_it():
    """Gymnasium's stateful vector wrappers read ``metadata["autoreset_mode"]`` (NormalizeObservation accepts
    NEXT_STEP only); RecordEpisodeStatistics counts the same episodes as over the single envs."""
    from gymnasium.wrappers.vector import NormalizeObservation, RecordEpisodeStatistics

    def episodes(vectorization_mode: str) -> list[tuple[int, float]]:
        env = gym.make_vec("formation_env/Hold-v1", 2, vectorization_mode=vectorization_mode, max_episode_steps=6)
        env = RecordEpisodeStatistics(NormalizeObservation(env))
        env.reset(seed=0)
        out = []
        for _ in range(20):
            *_, info = env.step(np.zeros(env.action_space.shape, np.float32))
            if "episode" in info:
                out += [(int(ln), float(r)) for ln, r, m in zip(info["episode"]["l"], info["episode"]["r"],
                                                                info["_episode"], strict=True) if m]  # fmt: skip
        return out

    got, want = episodes("vector_entry_point"), episodes("sync")
    assert len(got) == len(want) >= 4 and [ln for ln, _ in got] == [ln for ln, _ in want] == [6] * len(want)
    np.testing.assert_allclose([r for _, r in got], [r for _, r in want], rtol=1e-5, atol=1e-6)


def test_vector_entry_point_refuses_what_it_cannot_honour():
    env_id = "formation_env/Hold-v0"
    with pytest.raises(gym.error.Error, match="vector_kwargs"):  # Gymnasium's own refusal
        gym.make_vec(env_id, 2, vector_kwargs={"autoreset_mode": AutoresetMode.SAME_STEP})
    with pytest.raises(FormationError, match="autoreset_mode"):
        gym.make_vec(env_id, 2, autoreset_mode="sometimes")
    with pytest.raises(FormationError, match="render_mode"):
        gym.make_vec(env_id, 2, render_mode="human")
    with pytest.raises(TypeError, match="pose_speed"):
        gym.make_vec(env_id, 2, pose_speed=1.0)
    venv = gym.make_vec(env_id, 2)
    with pytest.raises(FormationError, match="reset"):
        venv.step(np.zeros(venv.action_space.shape))
    venv.reset(seed=0)
    with pytest.raises(FormationError, match="reset_mask"):
        venv.reset(options={"reset_mask": np.array([1, 0])})
    with pytest.raises(FormationError, match="seed"):
        venv.reset(seed=[1, 2, 3])
    with pytest.raises(FormationError, match="seed"):
        venv.reset(seed=-1)


def test_render_gives_a_frame_per_env():
    venv = gym.make_vec("formation_env/Hold-v0", 2, render_mode="rgb_array")
    venv.reset(seed=0)
    frames = venv.render()
    assert isinstance(frames, tuple) and len(frames) == 2 and frames[0].ndim == 3 and frames[0].dtype == np.uint8
    venv.close()


def test_a_refused_construction_leaves_nothing_to_close():
    """An env whose arguments are refused before its batch exists is closed when collected without an error."""
    import gc
    import sys

    seen: list[Any] = []
    hook, sys.unraisablehook = sys.unraisablehook, seen.append
    try:
        with pytest.raises(FormationError, match="autoreset_mode"):
            gym.make_vec("formation_env/Hold-v0", 2, autoreset_mode="sometimes")
        gc.collect()
    finally:
        sys.unraisablehook = hook
    assert [str(u.exc_value) for u in seen] == []
