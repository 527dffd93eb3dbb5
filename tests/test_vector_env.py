"""The batched VecEnv: env b replays the single env seeded ``seed + b`` over many steps and auto-resets."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import crowded_followers

from formation_env.core.errors import FormationError
from formation_env.env.commander import FormationCommanderEnv
from formation_env.env.engine import INFO_KEYS, Engine
from formation_env.env.formation import FormationEnv
from formation_env.env.scenarios import REGISTRY
from formation_env.env.vector import FormationVecEnv, GymnasiumFormationVecEnv

TOL = {"rtol": 1e-5, "atol": 1e-5}
SCENARIOS = sorted(REGISTRY)


def _actions(rng: np.random.Generator, shape: tuple[int, ...], scale: float) -> np.ndarray:
    return (scale * rng.uniform(-1.0, 1.0, size=shape)).astype(np.float32)


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_reset_each_equals_engine_resets(scenario):
    eng = Engine(scenario)
    got = eng.reset_each([np.random.default_rng(s) for s in (3, 4, 5)])
    want = Engine.concat([eng.reset(np.random.default_rng(s), 1) for s in (3, 4, 5)])
    for f in ("x", "pos", "vel", "k", "goal", "goal_vel", "goal_dist", "err", "streak"):
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
        ("moving_obstacles", {"follower_law": "linear", "network": {"loss": 0.3, "delay": 1, "jitter": (0.08, 0.12)}}),
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


@pytest.mark.parametrize("action_mode", ["leaders", "maneuver"])
def test_commander_mode_replays_the_commander_env(action_mode):
    B, seed = 4, 5
    venv = FormationVecEnv(
        "narrow_passage", num_envs=B, mode="commander", seed=seed, max_cycles=20, action_mode=action_mode
    )
    obs = venv.reset()
    singles = [FormationCommanderEnv("narrow_passage", action_mode, max_cycles=20) for _ in range(B)]
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
    genv = venv.to_gymnasium(gymnasium.vector.AutoresetMode.SAME_STEP)
    assert genv.metadata["autoreset_mode"] == gymnasium.vector.AutoresetMode.SAME_STEP
    assert isinstance(genv, gymnasium.vector.VectorEnv) and isinstance(genv, GymnasiumFormationVecEnv)
    obs, _ = genv.reset(seed=0)
    assert obs.shape == (2, *genv.single_observation_space.shape)
    assert genv.observation_space.shape == (2, *genv.single_observation_space.shape)
    for _ in range(3):
        obs, rew, term, trunc, info = genv.step(np.zeros((2, genv.single_action_space.shape[0])))
        assert rew.shape == term.shape == trunc.shape == (2,)
    assert trunc.all() and not term.any()
    assert info["_final_obs"].all() and info["final_obs"][0].shape == genv.single_observation_space.shape
    fi = info["final_info"]  # Gymnasium's layout (SyncVectorEnv): a dict of arrays over envs, with masks
    assert isinstance(fi, dict) and "terminal_observation" not in fi and info["_final_info"].all()
    assert fi["success"].dtype == bool and fi["formation_error"].shape == (2,) and fi["_success"].all()
    np.testing.assert_array_equal(fi["time"], venv.last_info["time"])


def test_gymnasium_final_info_matches_sync_vector_env_layout():
    """Shared mode, some envs finishing: final_obs / final_info only at the finished envs' slots, with masks, in
    the layout that gymnasium's own _add_info gives for the same per-slot infos."""
    import gymnasium

    venv = FormationVecEnv("narrow_passage", num_envs=6, mode="shared", seed=3)
    genv = venv.to_gymnasium("SameStep")
    genv.reset(seed=3)
    rng = np.random.default_rng(0)
    for _ in range(400):
        _, _, term, trunc, info = genv.step(rng.uniform(-1, 1, (genv.num_envs, venv.p)))
        done = term | trunc
        if done.any() and not done.all():
            break
    assert done.any() and not done.all()
    ref = gymnasium.vector.SyncVectorEnv.__new__(gymnasium.vector.SyncVectorEnv)
    ref.num_envs = genv.num_envs
    want: dict = {}
    for s in np.flatnonzero(done):
        b, j = divmod(s, venv.n_l)
        single = {key: venv.last_info[key][b].item() for key in info["final_info"] if not key.startswith("_")
                  and key != "control_effort"}  # fmt: skip
        single["control_effort"] = venv.last_info["control_effort"][b, j].item()  # the slot's leader's
        want = ref._add_info(want, {"final_obs": info["final_obs"][s], "final_info": single}, s)
    step_keys = {k for key in INFO_KEYS for k in (key, "_" + key)}  # every slot's step (or reset) info
    assert set(want) | step_keys == set(info) and set(want["final_info"]) == set(info["final_info"])
    np.testing.assert_array_equal(want["_final_obs"], info["_final_obs"])
    for key, arr in want["final_info"].items():
        np.testing.assert_array_equal(arr, info["final_info"][key], err_msg=key)
        assert arr.dtype == info["final_info"][key].dtype, key
    assert all(info["final_obs"][s] is None for s in np.flatnonzero(~done))


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
    with pytest.raises(FormationError, match="reset"):
        v.step(np.zeros((v.num_envs, v.p)))
    v.reset()
    with pytest.raises(FormationError, match="actions must have shape"):
        v.step(np.zeros((v.num_envs + 1, v.p)))
    with pytest.raises(ValueError, match="NaN or inf"):
        v.step(np.full((v.num_envs, v.p), np.nan))
    with pytest.raises(FormationError, match="step_async"):  # the failed step left no actions behind
        v.step_wait()


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


# ---------------------------------------------------------------------------- fast auto-reset path
RESET_CASES = [
    ("hold", {}),
    ("hold", {"framework": "bipyramid_3d"}),
    ("hold", {"start": "paper"}),
    ("hold", {"goal_shear": (0.0, 0.0), "follower_noise": 0.0}),
    ("hold", {"framework": "many", "follower_noise": 0.5}),  # ~9 in 10 draws redrawn
    ("hold", {"framework": "many", "follower_noise": 0.5, "agent_radius": 0.15}),  # most use up all 20 draws
    ("narrow_passage", {"wall_x": (0.2, 0.2)}),
    ("maneuver", {}),
    ("maneuver_3d", {}),
    ("obstacle_field", {"framework": "bipyramid_3d"}),
]


def _engine(scenario: str, kwargs: dict) -> Engine:
    kw = dict(kwargs)
    if kw.get("framework") == "many":
        kw["framework"] = crowded_followers()
    return Engine(scenario, **kw)


@pytest.mark.parametrize(("scenario", "kwargs"), RESET_CASES)
def test_reset_each_consumes_each_stream_as_a_single_reset(scenario, kwargs):
    """Entry b of reset_each equals reset(rng_b, 1), and every generator is left where that reset leaves it."""
    eng = _engine(scenario, kwargs)
    seeds = range(12)
    rngs = [np.random.default_rng(s) for s in seeds]
    got = eng.scenario.reset_each(rngs)
    for b, s in enumerate(seeds):
        g = np.random.default_rng(s)
        want = eng.scenario.reset(g, 1)
        assert set(got) == set(want)
        for key, arr in want.items():
            np.testing.assert_allclose(got[key][b], arr[0], rtol=0, atol=1e-12, err_msg=key)
        assert rngs[b].random() == g.random()  # the same numbers were consumed


def test_episodes_of_a_seed_are_pinned():
    """The draws of a seed are those of formation_env 0.x (changing them changes every published episode)."""
    p = Engine("narrow_passage").scenario.reset(np.random.default_rng(0), 1)
    np.testing.assert_allclose(p["gap_width"], [1.024584114361717], rtol=1e-12)
    np.testing.assert_allclose(p["start"][0, 3], [-5.476649904768345, 0.7172732784031389], rtol=1e-12)
    p = Engine("hold").scenario.reset(np.random.default_rng(0), 1)
    np.testing.assert_allclose(p["goal_b"][0], [0.9179862439359936, 0.17449996586169148], rtol=1e-12)
    np.testing.assert_allclose(p["start"][0, 4], [-1.759904963329976, -2.6906820570808994], rtol=1e-12)
    p = Engine("maneuver").scenario.reset(np.random.default_rng(0), 1)
    np.testing.assert_allclose(p["angle"], [1.2618487875361777], rtol=1e-12)
    np.testing.assert_allclose(p["start"][0, 4], [0.9591082971919788, 1.090006602307127], rtol=1e-12)
    p = Engine("obstacle_field").scenario.reset(np.random.default_rng(0), 1)
    np.testing.assert_allclose(p["circles"][0, 0], [0.09240421830363577, 0.8530862061374389, 0.5572212829762708])
    np.testing.assert_allclose(p["start"][0, 4], [-6.3283046295798435, -1.2684581053957646], rtol=1e-12)


def test_draw_plan_each_equals_batched_draw_of_one():
    from formation_env.env.scenarios._base import Draw, DrawPlan

    plan = DrawPlan(
        [
            Draw("a", (2,), bounds=(-1.0, 3.0)),
            Draw("const", (3,), bounds=(0.5, 0.5)),
            Draw("b", bounds=(0.0, 2.0)),
            Draw("n", (2, 2), "normal"),
            Draw("m", (3,), "normal"),
            Draw("s", (4,), "sign"),
            Draw("t", (1,), "sign"),
            Draw("empty", (0, 2)),
            Draw("c", bounds=(2.0, 5.0)),
        ]
    )
    rngs = [np.random.default_rng(s) for s in range(6)]
    got = plan.draw_each(rngs)
    for b in range(6):
        g = np.random.default_rng(b)
        want = plan.draw(g, 1)
        for key, arr in want.items():
            np.testing.assert_array_equal(got[key][b], arr[0], err_msg=key)
        assert rngs[b].random() == g.random()
    assert set(np.unique(got["s"])) <= {-1.0, 1.0} and np.all(got["const"] == 0.5)


def test_draw_plan_errors():
    from formation_env.env.scenarios._base import Draw, DrawPlan

    with pytest.raises(FormationError, match="draw names must be unique"):
        DrawPlan([Draw("a"), Draw("a")])
    with pytest.raises(FormationError, match="kind must be uniform, normal or sign"):
        DrawPlan([Draw("a", kind="gamma")])


#: Hold with a wide success test (1.5 m, one sample): episodes end at different steps.
_EARLY_ENDS = {"max_cycles": 9, "goal_tol": 1.5, "formation_tol": 0.3, "hold_steps": 1}


@pytest.mark.parametrize(
    ("scenario", "kwargs", "scale"),
    [
        ("hold", {"framework": "many", "follower_noise": 0.5, "max_cycles": 4}, 0.3),
        ("hold", _EARLY_ENDS, 1.0),
        ("moving_obstacles", {"max_cycles": 6}, 1.0),
    ],
)
def test_vec_env_replays_engine_resets_with_many_redraws(scenario, kwargs, scale):
    """Env b equals an engine stepped alone and reset from the generator of seed + b, episode after episode, also
    through a ``reset()`` without a new seed, which starts every env's next episode. Hold with 7 crowded
    followers: most start draws are redrawn, every episode is cut at 4 steps; hold with a wide success test:
    episodes end at different steps."""
    B, seed = 5, 3
    eng = _engine(scenario, kwargs)
    venv = FormationVecEnv(num_envs=B, engine=eng, seed=seed)
    obs = venv.reset()
    rngs = [np.random.default_rng(seed + b) for b in range(B)]
    singles = [eng.reset(g, 1) for g in rngs]
    nl = venv.n_l
    rng = np.random.default_rng(0)
    n_done = 0
    for t in range(20):
        if t == 5:  # a reset mid-way: every env starts its next episode
            obs = venv.reset()
            singles = [eng.reset(g, 1) for g in rngs]
        for b in range(B):
            np.testing.assert_allclose(obs[b * nl : (b + 1) * nl], eng.observe(singles[b])[0], **TOL)
            np.testing.assert_allclose(venv.state.pos[b], singles[b].pos[0], rtol=0, atol=1e-12)
        act = _actions(rng, (B * nl, venv.p), scale)
        obs, _, done, infos = venv.step(act)
        for b in range(B):
            singles[b], o, _, te, tr, _ = eng.step(singles[b], act[b * nl : (b + 1) * nl][None])
            assert done[b * nl] == bool(te[0] or tr[0])
            if te[0] or tr[0]:
                n_done += 1
                np.testing.assert_allclose(infos[b * nl]["terminal_observation"], o[0, 0], **TOL)
                singles[b] = eng.reset(rngs[b], 1)
    assert n_done >= B + 2


def test_infos_are_fresh_dicts_with_keys_only_where_done():
    venv = FormationVecEnv("hold", num_envs=3, mode="shared", seed=0, max_cycles=2)
    venv.reset()
    _, _, done, infos = venv.step(np.zeros((venv.num_envs, venv.p)))
    assert not done.any() and infos == [{}] * venv.num_envs
    assert len({id(i) for i in infos}) == venv.num_envs  # no shared dict
    _, _, done, infos = venv.step(np.zeros((venv.num_envs, venv.p)))
    assert done.all()
    keys = {"terminal_observation", "TimeLimit.truncated", "success", "collision", "out_of_bounds"}
    assert all(keys <= set(i) for i in infos)
    assert all(i["TimeLimit.truncated"] is True and type(i["success"]) is bool for i in infos)
    assert len({id(i["terminal_observation"]) for i in infos}) == venv.num_envs
