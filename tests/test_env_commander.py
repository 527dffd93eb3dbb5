"""The single-agent commander env: Gymnasium and SB3 checkers in both action modes, registration, behaviour."""

from __future__ import annotations

import os
import warnings

os.environ.setdefault("SDL_VIDEODRIVER", "dummy")

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import formation_env  # noqa: F401  (registers the env)
from formation_env.core.errors import FormationError
from formation_env.env.commander import FormationCommanderEnv
from formation_env.env.scenarios import REGISTRY

ENV_ID = "formation_env/FormationCommander-v0"


@pytest.mark.parametrize("mode", ["leaders", "maneuver"])
@pytest.mark.parametrize(
    ("scenario", "dynamics"),
    [
        ("narrow_passage", "double_integrator"),
        ("maneuver_3d", "single_integrator"),
        ("obstacle_field", "single_integrator"),
    ],
)
def test_checkers(mode, scenario, dynamics):
    env = FormationCommanderEnv(scenario=scenario, action_mode=mode, dynamics=dynamics)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # any checker warning fails the test
        gym_check_env(env, skip_render_check=True)
        sb3_check_env(FormationCommanderEnv(scenario=scenario, action_mode=mode, dynamics=dynamics), warn=True)


@pytest.mark.parametrize("scenario", sorted(REGISTRY))
def test_checkers_with_a_network(scenario):
    kw = {"scenario": scenario, "follower_law": "linear", "network": {"delay": 1, "loss": 0.25, "jitter": (0.08, 0.12)}}
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # any checker warning fails the test
        gym_check_env(FormationCommanderEnv(**kw), skip_render_check=True)
        sb3_check_env(FormationCommanderEnv(**kw), warn=True)
    env = FormationCommanderEnv(**kw)
    env.reset(seed=0)
    _, _, _, _, info = env.step(env.action_space.sample())
    assert 0.0 <= info["lost_fraction"] <= 1.0


def test_registered_and_makes():
    env = gym.make(ENV_ID, scenario="narrow_passage")
    obs, info = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    obs, rew, _, _, info = env.step(env.action_space.sample())
    assert isinstance(rew, float) and {"success", "collision", "formation_error", "min_clearance"} <= set(info)
    env.close()


def test_render_modes():
    env = gym.make(ENV_ID, scenario="hold", render_mode="rgb_array")
    env.reset(seed=1)
    env.step(env.action_space.sample())
    img = env.render()
    assert img.dtype == np.uint8 and img.ndim == 3 and img.shape[2] == 3
    env.close()


def test_leaders_mode_equals_the_parallel_env():
    from formation_env import formation_v0

    cmd = FormationCommanderEnv(scenario="obstacle_field")
    par = formation_v0.parallel_env(scenario="obstacle_field")
    cmd.reset(seed=3)
    par.reset(seed=3)
    cmd._state = par.engine_state  # the commander draws from its own np_random: align the two episodes
    rng = np.random.default_rng(0)
    for _ in range(30):
        a = rng.uniform(-1, 1, size=cmd.action_space.shape).astype(np.float32)
        obs, rew, term, _, _ = cmd.step(a)
        _, prew, pterm, _, _ = par.step({ag: a[2 * i : 2 * i + 2] for i, ag in enumerate(par.possible_agents)})
        assert rew == pytest.approx(np.mean(list(prew.values())))
        assert term == pterm["leader_0"]
        np.testing.assert_allclose(obs, par.state(), atol=1e-6)
        if term:
            break


def test_state_blocks_append_what_the_leaders_sense():
    """``state_blocks``: the commander's state ends with every leader's chosen blocks (noise-free), the planner's
    decoding of the state is unchanged, and a check_env passes."""
    from agents.policy import decode_state

    plain = FormationCommanderEnv(scenario="obstacle_field")
    env = FormationCommanderEnv(scenario="obstacle_field", state_blocks=["obstacles"], obs_noise=0.5)
    eng = env.engine
    assert env.observation_space.shape == (plain.observation_space.shape[0] + eng.n_l * eng.n_rays,)
    env.reset(seed=2)
    rng = np.random.default_rng(0)
    for _ in range(10):
        obs, *_ = env.step(rng.uniform(-1, 1, env.action_space.shape).astype(np.float32))
    rays = eng.observe(env._state)[0][:, eng.obs_blocks["obstacles"]]  # without noise
    np.testing.assert_allclose(obs[-eng.n_l * eng.n_rays :], rays.reshape(-1), atol=1e-6)
    assert rays.min() < 1.0  # some obstacle is in sight
    decoded = decode_state(eng, obs[None])
    np.testing.assert_allclose(decoded.pos, env._state.pos, atol=1e-5)
    assert decoded.k[0] == 10
    sb3_check_env(FormationCommanderEnv(scenario="narrow_passage", state_blocks=["task", "obstacles"]), warn=True)
    sb3_check_env(FormationCommanderEnv(scenario="obstacle_field", state_blocks=["task"]), warn=True)
    with pytest.raises(TypeError, match="state_blocks must be a sequence of block names"):
        FormationCommanderEnv(scenario="hold", state_blocks="obstacles")
    with pytest.raises(ValueError, match="state_blocks must name distinct registered blocks"):
        FormationCommanderEnv(scenario="hold", state_blocks=["rays"])


def test_maneuver_mode_scales_the_formation():
    """Commanding a negative y scale rate shrinks the formation along y; the followers keep the affine shape."""
    env = FormationCommanderEnv(scenario="hold", action_mode="maneuver", dynamics="single_integrator")
    env.reset(seed=2)
    a = np.zeros(env.action_space.shape, np.float32)
    a[3] = -1.0  # log-scale rate of axis y
    theta0 = env.engine.affine.fit(env._state.pos)[0][0]
    s0 = env._pose.s[0].copy()
    for _ in range(30):
        _, _, term, _, info = env.step(a)
        assert not term
    theta = env.engine.affine.fit(env._state.pos)[0][0]
    assert np.linalg.norm(theta[:, 1]) < 0.5 * np.linalg.norm(theta0[:, 1])
    assert info["formation_error"] < 0.05
    np.testing.assert_allclose(env._pose.s[0] / s0, [1.0, np.exp(-0.5 * 0.1 * 30)], rtol=1e-9)


def test_bad_arguments_and_actions():
    with pytest.raises(FormationError, match="action_mode"):
        FormationCommanderEnv(action_mode="joystick")
    with pytest.raises(TypeError, match="foo"):
        FormationCommanderEnv(foo=3)
    env = FormationCommanderEnv()
    env.reset(seed=0)
    state = env._state
    with pytest.raises(ValueError, match="NaN"):
        env.step(np.full(env.action_space.shape, np.nan, np.float32))
    assert env._state is state
