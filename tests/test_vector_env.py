"""The batched VecEnv: env b replays the single env seeded ``seed + b`` over many steps and auto-resets."""

from __future__ import annotations

import numpy as np
import pytest

from formation_env.core.errors import FormationError
from formation_env.env.commander import FormationCommanderEnv
from formation_env.env.engine import Engine
from formation_env.env.formation import FormationEnv
from formation_env.env.scenarios import REGISTRY
from formation_env.env.vector import FormationVecEnv, GymnasiumFormationVecEnv, reset_batch, stack_states

TOL = {"rtol": 1e-5, "atol": 1e-5}
SCENARIOS = sorted(REGISTRY)


def _actions(rng: np.random.Generator, shape: tuple[int, ...], scale: float) -> np.ndarray:
    return (scale * rng.uniform(-1.0, 1.0, size=shape)).astype(np.float32)


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_reset_batch_equals_engine_reset(scenario):
    eng = Engine(scenario)
    got = reset_batch(eng, [np.random.default_rng(s) for s in (3, 4, 5)])
    want = stack_states([eng.reset(np.random.default_rng(s), 1) for s in (3, 4, 5)])
    for f in ("x", "pos", "vel", "k", "ref", "goal_dist", "err", "streak"):
        np.testing.assert_allclose(getattr(got, f), getattr(want, f), rtol=0, atol=1e-12, err_msg=f)
    assert set(got.params) == set(want.params)
    for key in want.params:
        np.testing.assert_allclose(got.params[key], want.params[key], rtol=0, atol=1e-12, err_msg=key)


@pytest.mark.parametrize(
    ("scenario", "kwargs"),
    [
        ("narrow_passage", {}),
        ("obstacle_field", {"dynamics": "single_integrator", "follower_law": "stationary"}),
        ("maneuver", {"follower_law": "dynamic_distributed"}),
        ("hold", {"framework": "bipyramid_3d"}),
    ],
)
def test_shared_mode_replays_the_parallel_env(scenario, kwargs):
    """Slot b n_l + j is leader j of the PettingZoo env reset with seed + b, across auto-resets."""
    B, seed, steps = 3, 11, 90
    venv = FormationVecEnv(scenario, num_envs=B, mode="shared", max_cycles=25, **kwargs)
    venv.seed(seed)
    obs = venv.reset()
    singles = [FormationEnv(scenario, max_cycles=25, **kwargs) for _ in range(B)]
    nl = venv.n_l
    ref = [env.reset(seed=seed + b)[0] for b, env in enumerate(singles)]
    for b, o in enumerate(ref):
        np.testing.assert_allclose(obs[b * nl : (b + 1) * nl], np.stack([o[a] for a in singles[b].agents]), **TOL)
    rng = np.random.default_rng(0)
    n_done = n_cut = 0
    for _ in range(steps):
        act = _actions(rng, (B * nl, venv.p), 1.5)
        obs, rew, done, infos = venv.step(act)
        for b, env in enumerate(singles):
            sl = slice(b * nl, (b + 1) * nl)
            o, r, te, tr, _ = env.step({a: act[b * nl + i] for i, a in enumerate(env.possible_agents)})
            agents = env.possible_agents
            np.testing.assert_allclose(rew[sl], [r[a] for a in agents], **TOL)
            ended = te[agents[0]] or tr[agents[0]]
            assert done[sl].tolist() == [ended] * nl
            if ended:
                n_done += 1
                n_cut += tr[agents[0]]
                for i, a in enumerate(agents):
                    inf = infos[b * nl + i]
                    np.testing.assert_allclose(inf["terminal_observation"], o[a], **TOL)
                    assert inf["TimeLimit.truncated"] is bool(tr[a])
                o, _ = env.reset()
            np.testing.assert_allclose(obs[sl], np.stack([o[a] for a in agents]), **TOL)
    assert n_done >= B  # auto-resets happened
    assert n_cut >= 1  # and time-limit cuts


def test_commander_mode_replays_the_commander_env():
    B, seed = 4, 5
    venv = FormationVecEnv("narrow_passage", num_envs=B, mode="commander", seed=seed, max_cycles=20)
    obs = venv.reset()
    singles = [FormationCommanderEnv("narrow_passage", max_cycles=20) for _ in range(B)]
    assert venv.observation_space == singles[0].observation_space
    assert venv.action_space == singles[0].action_space
    for b, env in enumerate(singles):
        np.testing.assert_allclose(obs[b], env.reset(seed=seed + b)[0], **TOL)
    rng = np.random.default_rng(1)
    n_done = 0
    for _ in range(70):
        act = _actions(rng, (B, venv.action_space.shape[0]), 1.0)
        obs, rew, done, infos = venv.step(act)
        for b, env in enumerate(singles):
            o, r, te, tr, _ = env.step(act[b])
            np.testing.assert_allclose(rew[b], r, **TOL)
            assert bool(done[b]) == (te or tr)
            if te or tr:
                n_done += 1
                np.testing.assert_allclose(infos[b]["terminal_observation"], o, **TOL)
                assert infos[b]["TimeLimit.truncated"] is tr
                o, _ = env.reset()
            np.testing.assert_allclose(obs[b], o, **TOL)
    assert n_done >= B


def test_same_seed_same_trajectory_and_seed_list():
    def roll(seed: int) -> list[np.ndarray]:
        v = FormationVecEnv("obstacle_field", num_envs=2, max_cycles=10)
        seeds = v.seed(seed)
        assert seeds == [seed, seed, seed, seed + 1, seed + 1, seed + 1][: v.num_envs]
        out = [v.reset()]
        rng = np.random.default_rng(2)
        for _ in range(25):
            out.append(v.step(_actions(rng, (v.num_envs, v.p), 1.0))[0])
        return out

    for a, b in zip(roll(3), roll(3), strict=True):
        np.testing.assert_array_equal(a, b)
    assert not np.array_equal(roll(3)[0], roll(4)[0])


def test_gymnasium_adapter_same_step_autoreset():
    import gymnasium

    venv = FormationVecEnv("hold", num_envs=2, mode="commander", max_cycles=3)
    genv = venv.to_gymnasium()
    assert isinstance(genv, gymnasium.vector.VectorEnv) and isinstance(genv, GymnasiumFormationVecEnv)
    obs, _ = genv.reset(seed=0)
    assert obs.shape == (2, *genv.single_observation_space.shape)
    assert genv.observation_space.shape == (2, *genv.single_observation_space.shape)
    for _ in range(3):
        obs, rew, term, trunc, info = genv.step(np.zeros((2, genv.single_action_space.shape[0])))
        assert rew.shape == term.shape == trunc.shape == (2,)
    assert trunc.all() and not term.any()
    assert info["_final_obs"].all() and info["final_obs"][0].shape == genv.single_observation_space.shape
    assert "terminal_observation" not in info["final_info"][0]


def test_get_attr_and_env_method():
    venv = FormationVecEnv("hold", num_envs=2, mode="shared")
    assert venv.get_attr("n_l") == [venv.n_l] * venv.num_envs
    assert venv.get_attr("dt", indices=[0]) == [venv.engine.dt]
    assert venv.env_is_wrapped(object) == [False] * venv.num_envs


def test_errors():
    with pytest.raises(FormationError, match="mode must be one of"):
        FormationVecEnv("hold", mode="central")
    with pytest.raises(FormationError, match="num_envs must be a positive integer"):
        FormationVecEnv("hold", num_envs=0)
    with pytest.raises(TypeError, match="either engine= or engine keyword"):
        FormationVecEnv("hold", engine=Engine("hold"), dt=0.05)
    v = FormationVecEnv("hold", num_envs=2)
    with pytest.raises(RuntimeError, match="reset"):
        v.step(np.zeros((v.num_envs, v.p)))
    v.reset()
    with pytest.raises(FormationError, match="actions must have shape"):
        v.step(np.zeros((v.num_envs + 1, v.p)))
    with pytest.raises(ValueError, match="NaN or inf"):
        v.step(np.full((v.num_envs, v.p), np.nan))


def test_render_rgb_array():
    v = FormationVecEnv("narrow_passage", num_envs=2, render_mode="rgb_array")
    v.reset()
    img = v.render()
    assert img is not None and img.ndim == 3 and img.shape[2] == 3 and img.dtype == np.uint8
    v.close()


@pytest.mark.parametrize("mode", ["shared", "commander"])
def test_sb3_ppo_runs(mode):
    from stable_baselines3 import PPO

    venv = FormationVecEnv("narrow_passage", num_envs=4, mode=mode, max_cycles=16)
    model = PPO("MlpPolicy", venv, n_steps=16, batch_size=32, n_epochs=1, seed=0, device="cpu")
    model.learn(total_timesteps=2 * 16 * venv.num_envs)
    act, _ = model.predict(venv.reset(), deterministic=True)
    assert act.shape == (venv.num_envs, venv.action_space.shape[0])
