"""Issue 21 (env): bad input to the envs is refused with an error naming the argument; nothing silently wrong."""

from __future__ import annotations

import copy
import pickle
import re

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from formation_env import formation_v0, formation_v1
from formation_env.core import ControlDimension, FormationError
from formation_env.env.commander import FormationCommanderEnv
from formation_env.env.engine import Engine
from formation_env.env.vector import FormationVecEnv, GymnasiumFormationVecEnv

NAN, INF = float("nan"), float("inf")


def pz(**kwargs):
    env = formation_v0.parallel_env(scenario="hold", **kwargs)
    env.reset(seed=0)
    return env


# ------------------------------------------------------------------ Engine arguments (the cases first)
@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"reward_weights": {"progress": NAN}}, FormationError, r"reward_weights\['progress'\] must be finite"),
        ({"dynamics": "double_integrator", "law_params": {"gain": -1}}, FormationError, "gain must be positive"),
        ({"dynamics": "double_integrator", "law_params": {"gain": NAN}}, FormationError, "gain must be positive"),
        ({"scenario": "narrow_passage", "gap_width": (-1, -0.5)}, FormationError, r"gap_width must lie in \[1e-09"),
        ({"scenario": "narrow_passage", "gap_width": NAN}, TypeError, r"gap_width must be a \(low, high\) pair"),
        ({"scenario": "narrow_passage", "gap_width": (2, 1)}, FormationError, "gap_width must have low <= high"),
        ({"dt": "0.1"}, TypeError, r"dt must be a real number, got '0.1' \(str\)"),
        ({"max_cycles": None}, TypeError, "max_cycles must be a positive integer, got None"),
        ({"max_cycles": 1.5}, FormationError, "max_cycles must be a positive integer, got the float 1.5"),
        ({"scenario": "obstacle_field", "n_obstacles": -1}, FormationError, "n_obstacles must be an integer >= 0"),
        ({"follower_noise": -1.0}, FormationError, "follower_noise must be >= 0 and finite, got -1"),
        ({"follower_noise": NAN}, FormationError, "follower_noise must be >= 0 and finite, got nan"),
        ({"follower_noise": "x"}, TypeError, "follower_noise must be a real number"),
        ({"goal_scale": (-1.0, 0.5)}, FormationError, r"goal_scale must lie in \[1e-09"),
        ({"scenario": "maneuver", "scale": (0.0, 1.0)}, FormationError, r"scale must lie in \[1e-09"),
        ({"law_params": "gain"}, TypeError, "law_params must be a dict or None, got 'gain'"),
        ({"reward_weights": "x"}, TypeError, "reward_weights must be a dict or None"),
        ({"observation": 5}, TypeError, "observation must be a sequence of block names"),
        ({"observation": "position"}, TypeError, "observation must be a sequence of block names"),
        ({"hold_steps": 0}, FormationError, "hold_steps must be a positive integer, got 0"),
        ({"obs_noise": -0.1}, FormationError, "obs_noise must be >= 0 and finite"),
    ],
)
def test_engine_arguments_refused(kwargs, error, match):
    kwargs = {"scenario": "hold", **kwargs}
    with pytest.raises(error, match=match):
        Engine(**kwargs)


def test_engine_reset_and_step_check_their_arguments():
    eng = Engine("hold")
    with pytest.raises(TypeError, match=r"rng must be a np\.random\.Generator, got int"):
        eng.reset(0)
    state = eng.reset(np.random.default_rng(0), 2)
    with pytest.raises(TypeError, match="state must be an EngineState"):
        eng.step(None, np.zeros((2, 3, 2)))
    with pytest.raises(TypeError, match="actions must be real, got a complex array"):
        eng.step(state, np.zeros((2, 3, 2)) * 1j)


def test_version_1_refuses_reward_weights_that_are_not_a_dict():
    with pytest.raises(TypeError, match="reward_weights must be a dict or None, got 5"):
        formation_v1.parallel_env(reward_weights=5)


# ------------------------------------------------------------------ resets: seeds and options
def _resets():
    def vec(seed=None, options=None):
        return GymnasiumFormationVecEnv(FormationVecEnv("hold", num_envs=2)).reset(seed=seed, options=options)

    return {
        "parallel": lambda seed=None, options=None: pz().reset(seed=seed, options=options),
        "aec": lambda seed=None, options=None: formation_v0.env(scenario="hold").reset(seed=seed, options=options),
        "commander": lambda seed=None, options=None: FormationCommanderEnv("hold").reset(seed=seed, options=options),
        "gymnasium_vec": vec,
    }


@pytest.mark.parametrize("which", sorted(_resets()))
@pytest.mark.parametrize(
    ("seed", "error", "match"),
    [
        (-1, FormationError, "seed must be an integer >= 0, got -1"),
        (1.5, FormationError, "seed must be an integer >= 0, got the float 1.5"),
        ("x", TypeError, "seed must be an integer >= 0, got 'x'"),
        (True, TypeError, "seed must be an integer >= 0, got True"),
        ([1, 2], TypeError, r"seed must be an integer >= 0, got \[1, 2\]"),
    ],
)
def test_bad_seeds_refused_at_reset(which, seed, error, match):
    if which == "gymnasium_vec" and isinstance(seed, list):  # one seed per env (as SyncVectorEnv): B = 2 is right
        _resets()[which](seed=seed)
        error, seed = FormationError, [1, 2, 3]
        match = "seed must be an int, None or a list of 2 seeds, got a list of 3"
    with pytest.raises(error, match=match):
        _resets()[which](seed=seed)


@pytest.mark.parametrize("which", sorted(_resets()))
def test_options_must_be_a_dict(which):
    reset = _resets()[which]
    with pytest.raises(TypeError, match="options must be a dict or None, got 'x'"):
        reset(seed=0, options="x")
    reset(seed=0, options={"options": 1})  # PettingZoo's checkers pass arbitrary keys: accepted, unused


def test_vec_env_seeds_refused_at_construction_and_seed():
    with pytest.raises(FormationError, match="seed must be an integer >= 0, got -1"):
        FormationVecEnv("hold", num_envs=2, seed=-1)
    venv = FormationVecEnv("hold", num_envs=2)
    with pytest.raises(FormationError, match=r"seed must be an integer >= 0, got the float 1\.5"):
        venv.seed(1.5)
    with pytest.raises(TypeError, match="num_envs must be a positive integer, got None"):
        FormationVecEnv("hold", num_envs=None)


# ------------------------------------------------------------------ actions
def test_parallel_step_refuses_a_list_and_complex_actions():
    env = pz()
    with pytest.raises(ValueError, match=r"actions must be a dict .*exactly the live agents.*got list"):
        env.step([np.zeros(2)] * 3)
    with pytest.raises(TypeError, match="actions must be real, got a complex array"):
        env.step({a: np.ones(2) * 1j for a in env.agents})


def test_aec_checks_each_action_as_it_is_given():
    env = formation_v0.env(scenario="hold")
    env.reset(seed=0)
    before = env.unwrapped.engine_state
    with pytest.raises(ValueError, match=r"action of leader_0 holds NaN or inf"):
        env.step(np.full(2, NAN))
    with pytest.raises(ControlDimension, match=r"action of leader_0 must have shape \(2,\), got \(5,\)"):
        env.step(np.zeros(5))
    assert env.agent_selection == "leader_0" and env.unwrapped.engine_state is before
    for _ in range(3):
        env.step(np.zeros(2, np.float32))
    assert env.unwrapped.engine_state is not before


def test_aec_done_agent_takes_none_only():
    env = formation_v0.env(scenario="hold", max_cycles=1)
    env.reset(seed=0)
    for _ in range(3):
        env.step(np.zeros(2, np.float32))
    agent = env.agent_selection
    assert env.truncations[agent]
    with pytest.raises(ValueError, match=f"action of {agent} must be None: the agent is done"):
        env.step(np.zeros(2, np.float32))
    env.step(None)  # PettingZoo's dead step


def test_commander_refuses_complex_actions_and_pose_rates_outside_maneuver_mode():
    env = FormationCommanderEnv("hold")
    env.reset(seed=0)
    with pytest.raises(TypeError, match="action must be real, got a complex array"):
        env.step(np.zeros(6) * 1j)
    with pytest.raises(TypeError, match="pose_speed apply to action_mode='maneuver' only"):
        FormationCommanderEnv("hold", pose_speed=2.0)
    with pytest.raises(FormationError, match="pose_speed must be a finite number > 0, got 0"):
        FormationCommanderEnv("hold", action_mode="maneuver", pose_speed=0.0)
    with pytest.raises(TypeError, match="scale_range must be a real numeric array"):
        FormationCommanderEnv("hold", action_mode="maneuver", scale_range="wide")


def test_vec_env_refuses_complex_actions_and_foreign_objects():
    venv = FormationVecEnv("hold", num_envs=2, seed=0)
    venv.reset()
    with pytest.raises(TypeError, match="actions must be real, got a complex array"):
        venv.step(np.zeros((venv.num_envs, venv.p)) * 1j)
    with pytest.raises(TypeError, match="engine must be an Engine"):
        FormationVecEnv(engine=5)
    with pytest.raises(TypeError, match="venv must be a FormationVecEnv or FormationBatch, got NoneType"):
        GymnasiumFormationVecEnv(None)
    with pytest.raises(AttributeError, match="attr_name 'nope' is an attribute of neither"):
        venv.get_attr("nope")
    assert not venv.has_attr("nope")  # SB3's has_attr relies on the AttributeError


@pytest.mark.parametrize("make", [formation_v0.parallel_env, formation_v0.env])
def test_max_cycles_set_on_the_pettingzoo_envs_is_checked_and_reaches_the_engine(make) -> None:
    """``env.max_cycles = 0`` is refused naming the argument (the AEC wrapper does not keep it to itself); a positive
    integer set on either view is the episode length the engine truncates at."""
    env = make(scenario="hold", max_cycles=40)
    for bad, error in ((0, FormationError), (-3, FormationError), (2.5, FormationError), ("7", TypeError)):
        with pytest.raises(error, match=r"max_cycles must be a positive integer number of steps"):
            env.max_cycles = bad
    assert env.max_cycles == env.unwrapped.engine.max_cycles == 40
    env.max_cycles = 7
    assert env.max_cycles == env.unwrapped.max_cycles == env.unwrapped.engine.max_cycles == 7
    env.reset(seed=0)
    while env.agents:
        if hasattr(env, "agent_iter"):
            env.step(None if env.terminations[env.agent_selection] or env.truncations[env.agent_selection]
                     else np.zeros(2, np.float32))  # fmt: skip
        else:
            env.step({a: np.zeros(2, np.float32) for a in env.agents})
    assert int(env.unwrapped.engine_state.k[0]) == 7  # truncated after the length set


def test_space_lookups_name_the_agent():
    env = formation_v0.parallel_env(scenario="hold")
    with pytest.raises(
        ValueError, match=r"agent must be one of \['leader_0', 'leader_1', 'leader_2'\], got 'leader_9'"
    ):
        env.observation_space("leader_9")
    with pytest.raises(ValueError, match="agent must be one of"):
        env.action_space(None)


# ------------------------------------------------------------------ copies: the AEC view and the Gymnasium vec view
@pytest.mark.parametrize("how", ["pickle", "deepcopy"])
def test_aec_and_gymnasium_vec_copies_continue_bit_identically(how):
    clone = (lambda e: pickle.loads(pickle.dumps(e))) if how == "pickle" else copy.deepcopy
    aec = formation_v0.env(scenario="hold", obs_noise=0.01)
    aec.reset(seed=1)
    for _ in range(4):  # mid-step: leader_1 has acted, leader_2 has not
        aec.step(np.full(2, 0.2, np.float32))
    twin = clone(aec)
    for _ in range(6):
        aec.step(np.full(2, 0.2, np.float32))
        twin.step(np.full(2, 0.2, np.float32))
        assert aec.agent_selection == twin.agent_selection
        np.testing.assert_array_equal(aec.observe(aec.agent_selection), twin.observe(twin.agent_selection))
    gv = FormationVecEnv("narrow_passage", num_envs=3, max_cycles=4).to_gymnasium()
    gv.reset(seed=0)
    zero = np.zeros((gv.num_envs, gv.venv.p))
    gv.step(zero)
    gtwin = clone(gv)
    for _ in range(7):  # across auto-resets
        a, b = gv.step(zero), gtwin.step(zero)
        np.testing.assert_array_equal(a[0], b[0])
        np.testing.assert_array_equal(a[1], b[1])


# ------------------------------------------------------------------ hypothesis: malformed inputs at the env
BAD = st.sampled_from(
    [None, "x", NAN, INF, -1, 0, 1.5, 1 + 2j, True, [1.0, NAN], np.zeros((2, 3)), [[1, 2], [3]], {"a": 1}]
)

#: Engine arguments (and scenario keywords) with the values of BAD that are legitimate for them.
ENGINE_ARGS: dict[str, set[str]] = {
    "scenario": set(),
    "dynamics": set(),
    "follower_law": set(),
    "dt": {"1.5"},
    "max_cycles": set(),
    "framework": {"None"},
    "omega": {"None"},
    "law_params": {"None"},
    "u_max": {"1.5"},
    "agent_radius": {"0", "1.5"},
    "n_rays": set(),
    "n_nearest": set(),
    "sensor_range": {"1.5"},
    "max_speed": {"1.5"},
    "reward_weights": {"None"},
    "observation": {"None"},
    "k_nearest": {"0"},
    "sense_radius": {"None", "1.5"},
    "obs_noise": {"0", "1.5"},
    "goal_tol": {"1.5"},
    "formation_tol": {"1.5"},
    "hold_steps": set(),
    "follower_noise": {"0", "1.5"},
    "goal_scale": set(),
}


def _reset_calls():
    return {
        ("parallel_env.reset", "seed"): lambda bad: formation_v0.parallel_env(scenario="hold").reset(seed=bad),
        ("parallel_env.reset", "options"): lambda bad: formation_v0.parallel_env(scenario="hold").reset(options=bad),
        ("commander.reset", "seed"): lambda bad: FormationCommanderEnv("hold").reset(seed=bad),
        ("commander.reset", "options"): lambda bad: FormationCommanderEnv("hold").reset(options=bad),
        ("FormationVecEnv", "seed"): lambda bad: FormationVecEnv("hold", num_envs=2, seed=bad),
        ("FormationVecEnv", "num_envs"): lambda bad: FormationVecEnv("hold", num_envs=bad),
        ("GymnasiumFormationVecEnv.reset", "seed"): lambda bad: (
            FormationVecEnv("hold", num_envs=2).to_gymnasium().reset(seed=bad)
        ),
    }


#: reset arguments: the values of BAD that are legitimate for them
RESET_VALID = {"seed": {"None", "0"}, "options": {"None", "{'a': 1}"}, "num_envs": set()}


def _step_calls():
    def vec(bad):
        venv = FormationVecEnv("hold", num_envs=2, seed=0)
        venv.reset()
        return venv.step(bad)

    def aec(bad):
        env = formation_v0.env(scenario="hold")
        env.reset(seed=0)
        return env.step(bad)

    def commander(bad):
        env = FormationCommanderEnv("hold")
        env.reset(seed=0)
        return env.step(bad)

    return {
        "parallel_env.step(actions)": lambda bad: pz().step(bad),
        "parallel_env.step({agent: action})": lambda bad: (lambda e: e.step(dict.fromkeys(e.agents, bad)))(pz()),
        "env().step(action)": aec,
        "commander.step(action)": commander,
        "FormationVecEnv.step(actions)": vec,
    }


def _named(exc: BaseException, name: str) -> bool:
    return name.lower() in str(exc).lower()


def _names_key_a(exc: BaseException) -> bool:
    """The message names the unknown key 'a' of the dict {"a": 1} (e.g. an unexpected law parameter)."""
    return re.search(r"'a'|: a$", str(exc)) is not None


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(bad=BAD, arg=st.sampled_from(sorted(ENGINE_ARGS)))
def test_malformed_engine_arguments_name_the_argument(bad, arg):
    if repr(bad) in ENGINE_ARGS[arg]:  # a legitimate value: it may pass, or fail on its consequences
        return
    try:
        Engine("hold", **{arg: bad})
    except (FormationError, ValueError, TypeError) as exc:
        assert _named(exc, arg) or (isinstance(bad, dict) and _names_key_a(exc)), f"{arg}={bad!r}: {exc}"
    else:
        raise AssertionError(f"Engine({arg}={bad!r}) silently accepted")


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(bad=BAD, key=st.sampled_from(sorted(_reset_calls())))
def test_malformed_reset_arguments_name_the_argument(bad, key):
    where, arg = key
    if repr(bad) in RESET_VALID[arg]:
        return
    try:
        _reset_calls()[key](bad)
    except (FormationError, ValueError, TypeError) as exc:
        assert _named(exc, arg), f"{where}({arg}={bad!r}): {exc}"
    else:
        raise AssertionError(f"{where}({arg}={bad!r}) silently accepted")


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(bad=BAD, where=st.sampled_from(sorted(_step_calls())))
def test_malformed_actions_name_the_argument(bad, where):
    try:
        _step_calls()[where](bad)
    except (FormationError, ValueError, TypeError) as exc:  # none of BAD is a valid action
        assert _named(exc, "action"), f"{where} with {bad!r}: {exc}"
    else:
        raise AssertionError(f"{where} with {bad!r} silently accepted")
