"""PettingZoo's checkers on every offered scenario x dynamics x law (MPE2 ``all_parameter_combs_test`` style),
plus determinism over many steps, pickling, NaN actions, refused arguments."""

from __future__ import annotations

import functools
import itertools
import os
import pickle
import types

os.environ.setdefault("SDL_VIDEODRIVER", "dummy")

import numpy as np
import pytest
from pettingzoo.test import api_test, max_cycles_test, parallel_api_test, render_test, seed_test, state_test

from formation_env import formation_v0
from formation_env.core.errors import FormationError
from formation_env.env.engine import DYNAMICS, FOLLOWER_LAWS, offered_combinations
from formation_env.env.scenarios import REGISTRY

COMBOS = offered_combinations()
IDS = [f"{s}-{d}-{law}" for s, d, law in COMBOS]


def _kwargs(combo: tuple[str, str, str]) -> dict[str, str]:
    scenario, dynamics, law = combo
    return {"scenario": scenario, "dynamics": dynamics, "follower_law": law}


def test_offered_combinations_cover_every_scenario_and_law():
    assert {s for s, _, _ in COMBOS} == set(REGISTRY)
    assert {law for _, _, law in COMBOS} == set(FOLLOWER_LAWS)
    assert all(d == "single_integrator" for _, d, law in COMBOS if law == "stationary")
    per_scenario = len(DYNAMICS) * len(FOLLOWER_LAWS) - (len(DYNAMICS) - 1)  # stationary: single integrators
    assert len(COMBOS) == len(REGISTRY) * per_scenario


@pytest.mark.parametrize("combo", COMBOS, ids=IDS)
def test_pettingzoo_checkers(combo):
    kw = _kwargs(combo)
    parallel_api_test(formation_v0.parallel_env(**kw), num_cycles=200)
    api_test(formation_v0.env(**kw), num_cycles=100)
    seed_test(functools.partial(formation_v0.env, **kw), num_cycles=100)
    state_test(formation_v0.env(**kw), formation_v0.parallel_env(**kw), num_cycles=20)
    # max_cycles_test steps unseeded random actions and needs every episode to last its 4 cycles; random
    # actions end about 1 run in 150 early (a collision, or a follower pushed out of the world box), so there
    # the agents are points (no contacts) and the actions small (u_max 0.01)
    still = {**kw, "agent_radius": 0.0, "u_max": 0.01}
    mod = types.SimpleNamespace(
        env=functools.partial(formation_v0.env, **still),
        parallel_env=functools.partial(formation_v0.parallel_env, **still),
    )
    max_cycles_test(mod)


#: A network with every model on, for the checkers (its draws come from the env's generator, seeded at the reset).
NETWORK = {"delay": 1, "loss": 0.25, "jitter": (0.08, 0.12), "quantise": ("uniform", 0.01)}
NET_LAWS = [("double_integrator", "linear"), ("single_integrator", "stationary")]


@pytest.mark.parametrize(("dynamics", "law"), NET_LAWS)
@pytest.mark.parametrize("scenario", sorted(REGISTRY))
def test_pettingzoo_checkers_with_a_network(scenario, dynamics, law):
    kw = {"scenario": scenario, "dynamics": dynamics, "follower_law": law, "network": NETWORK}
    parallel_api_test(formation_v0.parallel_env(**kw), num_cycles=100)
    api_test(formation_v0.env(**kw), num_cycles=50)
    seed_test(functools.partial(formation_v0.env, **kw), num_cycles=50)


@pytest.mark.parametrize("combo", COMBOS, ids=IDS)
def test_render(combo):
    render_test(functools.partial(formation_v0.env, **_kwargs(combo)))


@pytest.mark.parametrize("combo", COMBOS[::3], ids=IDS[::3])
def test_many_step_determinism(combo):
    """Same seed and actions give identical observations, rewards and infos over 120 steps (resets included)."""

    def rollout() -> list:
        env = formation_v0.parallel_env(**_kwargs(combo), max_cycles=50)
        rng = np.random.default_rng(7)
        out = []
        obs, _ = env.reset(seed=11)
        out.append(obs)
        for _ in range(120):
            if not env.agents:
                obs, _ = env.reset(seed=int(rng.integers(1000)))
                out.append(obs)
            acts = {a: rng.uniform(-1, 1, env.action_space(a).shape).astype(np.float32) for a in env.agents}
            out.append(env.step(acts))
        return out

    a, b = rollout(), rollout()
    for x, y in zip(a, b, strict=True):
        if isinstance(x, dict):
            x, y = (x,), (y,)
        for dx, dy in zip(x, y, strict=True):
            assert dx.keys() == dy.keys()
            for k in dx:
                if isinstance(dx[k], np.ndarray):
                    np.testing.assert_array_equal(dx[k], dy[k])
                else:
                    assert dx[k] == dy[k]


def test_different_seeds_differ_and_reset_reseeds():
    env = formation_v0.parallel_env()
    o1, _ = env.reset(seed=1)
    o2, _ = env.reset(seed=2)
    o3, _ = env.reset(seed=1)
    assert not np.array_equal(o1["leader_0"], o2["leader_0"])
    np.testing.assert_array_equal(o1["leader_0"], o3["leader_0"])


def test_contract_example():
    env = formation_v0.parallel_env(
        scenario="narrow_passage",
        dynamics="double_integrator",
        follower_law="dynamic",
        dt=0.1,
        max_cycles=400,
        render_mode="rgb_array",
    )
    obs, infos = env.reset(seed=0)
    assert env.agents == ["leader_0", "leader_1", "leader_2"]
    assert env.observation_space("leader_0") is env.observation_space("leader_0")
    assert env.observation_space("leader_0") is env.observation_space("leader_2")
    obs, rewards, terminations, truncations, infos = env.step({a: env.action_space(a).sample() for a in env.agents})
    assert all(type(r) is float for r in rewards.values())
    assert all(type(t) is bool for t in terminations.values()) and all(type(t) is bool for t in truncations.values())
    info = infos["leader_0"]
    assert set(info) == {
        "success",
        "collision",
        "out_of_bounds",
        "formation_error",
        "min_clearance",
        "goal_distance",
        "control_effort",
        "time",
        "lost_fraction",
    }
    assert info["lost_fraction"] == 0.0  # no network
    assert infos["leader_0"] is not infos["leader_1"]
    assert all(o.dtype == np.float32 and env.observation_space(a).contains(o) for a, o in obs.items())
    img = env.render()
    assert img.shape[2] == 3 and img.dtype == np.uint8
    assert env.metadata["name"] == "formation_v0" and env.metadata["is_parallelizable"] is True
    env.close()


def test_observation_blocks_tile_the_observation():
    env = formation_v0.parallel_env()
    blocks = sorted(env.obs_blocks.values(), key=lambda s: s.start)
    assert blocks[0].start == 0 and blocks[-1].stop == env.observation_space("leader_0").shape[0] == 34
    assert all(a.stop == b.start for a, b in itertools.pairwise(blocks))


def test_pickle_round_trip():
    env = formation_v0.parallel_env(scenario="obstacle_field", dynamics="single_integrator", follower_law="linear")
    clone = pickle.loads(pickle.dumps(env))
    o1, _ = env.reset(seed=5)
    o2, _ = clone.reset(seed=5)
    for a in env.agents:
        np.testing.assert_array_equal(o1[a], o2[a])
    acts = {a: np.full(2, 0.3, np.float32) for a in env.agents}
    assert env.step(acts)[1] == clone.step(acts)[1]
    aec = pickle.loads(pickle.dumps(formation_v0.env(scenario="hold")))
    aec.reset(seed=0)
    assert aec.agent_selection == "leader_0"


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_action_raises_and_changes_nothing(bad):
    env = formation_v0.parallel_env()
    ref = formation_v0.parallel_env()
    env.reset(seed=3)
    ref.reset(seed=3)
    before = env.engine_state
    acts = {a: np.zeros(2, np.float32) for a in env.agents}
    acts["leader_1"] = np.array([0.0, bad], np.float32)
    with pytest.raises(ValueError, match="leader_1"):
        env.step(acts)
    assert env.engine_state is before
    assert env.agents == ["leader_0", "leader_1", "leader_2"]
    good = {a: np.full(2, 0.5, np.float32) for a in env.agents}
    o1, r1, *_ = env.step(good)
    o2, r2, *_ = ref.step(good)
    assert r1 == r2
    np.testing.assert_array_equal(o1["leader_0"], o2["leader_0"])


def test_out_of_range_actions_are_clipped():
    a, b = formation_v0.parallel_env(), formation_v0.parallel_env()
    a.reset(seed=4)
    b.reset(seed=4)
    oa, ra, *_ = a.step({ag: np.array([5.0, -7.0], np.float32) for ag in a.agents})
    ob, rb, *_ = b.step({ag: np.array([1.0, -1.0], np.float32) for ag in b.agents})
    assert ra == rb
    np.testing.assert_array_equal(oa["leader_2"], ob["leader_2"])


def test_missing_action_is_refused():
    env = formation_v0.parallel_env()
    env.reset(seed=0)
    with pytest.raises(ValueError, match="leader_2"):
        env.step({"leader_0": np.zeros(2), "leader_1": np.zeros(2)})


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"foo": 1}, TypeError, "foo"),
        ({"scenario": "narrow_passage", "wall_height": 3}, TypeError, "wall_height"),
        ({"reward_weights": {"speed": 1.0}}, TypeError, "speed"),
        ({"dynamics": "double_integrator", "follower_law": "stationary"}, FormationError, "single_integrator"),
        ({"follower_law": "linear_paper"}, FormationError, "linear_paper"),
        ({"follower_law": "magic"}, FormationError, "magic"),
        ({"dynamics": "triple_integrator"}, FormationError, "triple_integrator"),
        ({"scenario": "maze"}, FormationError, "maze"),
        ({"scenario": "narrow_passage", "framework": "bipyramid_3d"}, FormationError, "supports d"),
        ({"framework": "no_such_framework"}, FormationError, "no_such_framework"),
        ({"render_mode": "ansi"}, FormationError, "render_mode"),
        ({"dt": 0.0}, FormationError, "dt"),
        ({"max_cycles": 0}, FormationError, "max_cycles"),
        ({"u_max": -1.0}, FormationError, "u_max"),
        ({"law_params": {"bogus": 1}}, TypeError, "bogus"),
    ],
)
def test_refused_arguments(kwargs, error, match):
    with pytest.raises(error, match=match):
        formation_v0.parallel_env(**kwargs)


def test_step_after_end_and_before_reset():
    env = formation_v0.parallel_env(max_cycles=2)
    with pytest.raises(FormationError, match="reset"):
        env.state()
    env.reset(seed=0)
    for _ in range(2):
        _, _, _, trunc, _ = env.step({a: np.zeros(2, np.float32) for a in env.agents})
    assert all(trunc.values()) and env.agents == []
    assert env.step({}) == ({}, {}, {}, {}, {})
    with pytest.raises(FormationError, match="reset"):
        env.step({"leader_0": np.zeros(2)})
    fresh = formation_v0.parallel_env()
    with pytest.raises(FormationError, match="reset"):
        fresh.step({})


def test_step_needs_exactly_the_live_agents():
    env = formation_v0.parallel_env()
    env.reset(seed=0)
    acts = {a: np.zeros(2, np.float32) for a in env.agents}
    with pytest.raises(ValueError, match="exactly the live agents"):
        env.step({**acts, "leader_9": np.zeros(2)})


def test_reset_infos_carry_every_step_key():
    env = formation_v0.parallel_env(scenario="narrow_passage")
    _, infos = env.reset(seed=0)
    _, _, _, _, step_infos = env.step({a: np.zeros(2, np.float32) for a in env.agents})
    for a in env.possible_agents:
        assert set(infos[a]) == set(step_infos[a])
        assert infos[a]["success"] is False and infos[a]["collision"] is False and infos[a]["time"] == 0.0


@pytest.mark.parametrize("how", ["pickle", "deepcopy"])
def test_copies_continue_the_episode_bit_identically(how):
    import copy

    from formation_env.env.commander import FormationCommanderEnv
    from formation_env.env.vector import FormationVecEnv

    clone = (lambda e: pickle.loads(pickle.dumps(e))) if how == "pickle" else copy.deepcopy
    env = formation_v0.parallel_env(scenario="moving_obstacles", obs_noise=0.01)
    env.reset(seed=3)
    acts = {a: np.full(2, 0.3, np.float32) for a in env.agents}
    for _ in range(5):
        env.step(acts)
    twin = clone(env)
    for _ in range(5):
        o1, r1, *_ = env.step(acts)
        o2, r2, *_ = twin.step(acts)
        assert r1 == r2 and all(np.array_equal(o1[a], o2[a]) for a in o1)
    venv = FormationVecEnv("hold", num_envs=3, seed=0, max_cycles=4)
    venv.reset()
    zero = np.zeros((venv.num_envs, venv.p))
    venv.step(zero)
    vtwin = clone(venv)
    for _ in range(7):  # across auto-resets
        a, b = venv.step(zero), vtwin.step(zero)
        np.testing.assert_array_equal(a[0], b[0])
        np.testing.assert_array_equal(a[1], b[1])
    cmd = FormationCommanderEnv("narrow_passage")
    cmd.reset(seed=1)
    cmd.step(np.zeros(6))
    ctwin = clone(cmd)
    np.testing.assert_array_equal(cmd.step(np.full(6, 0.2))[0], ctwin.step(np.full(6, 0.2))[0])


def test_commander_refuses_wrong_shapes_and_steps_after_the_end():
    from formation_env.env.commander import FormationCommanderEnv

    cmd = FormationCommanderEnv("hold", max_cycles=2)
    with pytest.raises(FormationError, match="reset"):
        cmd.step(np.zeros(6))
    cmd.reset(seed=0)
    with pytest.raises(ValueError, match="shape"):
        cmd.step(np.zeros((2, 3)))
    cmd.step(np.zeros(6))
    _, _, _, truncated, _ = cmd.step(np.zeros(6))
    assert truncated
    with pytest.raises(FormationError, match="over"):
        cmd.step(np.zeros(6))
