"""Gymnasium ids (one per scenario) and a light ``import formation_env``, each checked in a fresh process."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

import formation_env
from formation_env import COMMANDER_ID, MAX_EPISODE_STEPS, SCENARIO_IDS

ROOT = Path(__file__).resolve().parents[1]


def run_fresh(code: str) -> str:
    """Run ``code`` in a fresh interpreter (the repository importable, no display); return its last stdout line."""
    env = dict(
        os.environ, SDL_VIDEODRIVER="dummy", PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])
    )
    proc = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)],
        capture_output=True,
        text=True,
        cwd=ROOT,
        env=env,
        timeout=300,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr
    return proc.stdout.strip().splitlines()[-1]


def known_scenarios() -> set[str]:
    pytest.importorskip("gymnasium")
    from formation_env.env.scenarios import REGISTRY

    return set(REGISTRY)


def test_scenario_ids_are_documented_and_cover_the_scenarios() -> None:
    assert SCENARIO_IDS["narrow_passage"] == "formation_env/NarrowPassage-v0"
    assert all(i.startswith("formation_env/") and i.endswith("-v0") for i in SCENARIO_IDS.values())
    assert len(set(SCENARIO_IDS.values())) == len(SCENARIO_IDS)
    assert COMMANDER_ID not in SCENARIO_IDS.values()
    assert MAX_EPISODE_STEPS == 400
    assert formation_env.__doc__ is not None and "SCENARIO_IDS" in formation_env.__doc__
    # every scenario the env offers has an id ("moving_obstacles" may have its id before the env has it)
    assert known_scenarios() <= set(SCENARIO_IDS)


def test_import_is_light() -> None:
    """``import formation_env`` pulls in none of the optional stacks (nor the maths core's scipy)."""
    heavy = ["gymnasium", "pettingzoo", "torch", "cvxpy", "pygame", "numba", "stable_baselines3", "scipy", "matplotlib"]
    out = run_fresh(
        f"""
        import json, sys
        import formation_env
        assert formation_env.SCENARIO_IDS
        print(json.dumps([m for m in {heavy!r} if m in sys.modules]))
        """
    )
    assert json.loads(out) == []


def test_make_with_module_prefix_in_a_fresh_process() -> None:
    """``gym.make("formation_env:formation_env/NarrowPassage-v0")`` imports the package itself."""
    pytest.importorskip("gymnasium")
    out = run_fresh(
        """
        import json, sys
        import gymnasium as gym
        assert "formation_env" not in sys.modules
        env = gym.make("formation_env:formation_env/NarrowPassage-v0")
        obs, info = env.reset(seed=0)
        obs, r, term, trunc, info = env.step(env.action_space.sample())
        print(json.dumps({"max": env.spec.max_episode_steps, "kwargs": env.spec.kwargs,
                          "scenario": env.unwrapped.engine.scenario.name}))
        env.close()
        """
    )
    got = json.loads(out)
    assert got == {"max": 400, "kwargs": {"scenario": "narrow_passage"}, "scenario": "narrow_passage"}


@pytest.mark.parametrize("gym_first", [False, True], ids=["formation_env-first", "gymnasium-first"])
def test_every_id_after_import(gym_first: bool) -> None:
    """After ``import formation_env`` (before or after gymnasium) every id makes its scenario with 400 steps."""
    scenarios = known_scenarios()
    if "moving_obstacles" not in scenarios:  # added by the env's owner; its id is registered already
        ids = {s: i for s, i in SCENARIO_IDS.items() if s != "moving_obstacles"}
    else:
        ids = dict(SCENARIO_IDS)
    imports = (
        "import gymnasium as gym; import formation_env"
        if gym_first
        else "import formation_env; import gymnasium as gym"
    )
    out = run_fresh(
        f"""
        import json
        {imports}
        got = {{}}
        for scenario, env_id in {ids!r}.items():
            env = gym.make(env_id)
            env.reset(seed=0)
            got[scenario] = [env.spec.id, env.spec.max_episode_steps, env.unwrapped.engine.scenario.name]
            env.close()
        cmd = gym.make({COMMANDER_ID!r}, scenario="hold")
        got["commander"] = [cmd.spec.id, cmd.spec.max_episode_steps, cmd.unwrapped.engine.scenario.name]
        print(json.dumps(got))
        """
    )
    got = json.loads(out)
    for scenario, env_id in ids.items():
        assert got[scenario] == [env_id, 400, scenario]
    assert got["commander"] == [COMMANDER_ID, None, "hold"]


def test_moving_obstacles_id() -> None:
    """Its own test, so that it shows as skipped until the env's owner adds the scenario."""
    if "moving_obstacles" not in known_scenarios():
        pytest.skip("formation_env.env.scenarios has no 'moving_obstacles' yet")
    gym = pytest.importorskip("gymnasium")
    env = gym.make(SCENARIO_IDS["moving_obstacles"])
    env.reset(seed=0)
    assert env.spec.max_episode_steps == 400
    assert env.unwrapped.engine.scenario.name == "moving_obstacles"
    env.close()


def test_require_names_the_extra() -> None:
    from formation_env._extras import EXTRAS, MissingExtra, require

    assert require("json", "design", "x") is json
    with pytest.raises(ImportError) as err:
        require("formation_env_no_such_module.sub", "design", "design_stress(method='sdp')")
    assert isinstance(err.value, MissingExtra) and err.value.extra == "design"
    msg = str(err.value)
    assert msg == "design_stress(method='sdp') needs formation_env_no_such_module: pip install 'formation-env[design]'"
    assert "\n" not in msg
    assert set(EXTRAS) == {"design", "env", "train", "video", "plots", "rllib", "torchrl", "benchmarl", "bench"}


def test_require_does_not_hide_a_broken_install(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """An installed module whose own import fails on something else re-raises that error, not the extra."""
    from formation_env._extras import MissingExtra, require

    (tmp_path / "fe_broken_pkg.py").write_text("import fe_missing_dependency_xyz\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(ModuleNotFoundError) as err:
        require("fe_broken_pkg", "design", "x")
    assert not isinstance(err.value, MissingExtra)
    assert err.value.name == "fe_missing_dependency_xyz"


def test_version_1_ids_and_module_carry_the_learnable_rewards() -> None:
    import gymnasium as gym

    from formation_env import COMMANDER_ID_V1, SCENARIO_IDS_V1, formation_v1
    from formation_env.env.versions import ENV_VERSIONS, with_version

    assert set(SCENARIO_IDS_V1) == set(SCENARIO_IDS)
    assert all(i.endswith("-v1") for i in SCENARIO_IDS_V1.values())
    v1 = ENV_VERSIONS[1]["reward_weights"]
    for env in (
        gym.make(SCENARIO_IDS_V1["narrow_passage"]).unwrapped,
        gym.make(COMMANDER_ID_V1, scenario="narrow_passage").unwrapped,
        formation_v1.parallel_env(scenario="narrow_passage"),
    ):
        assert {k: env.engine.reward_weights[k] for k in v1} == v1
    v0 = gym.make(COMMANDER_ID, scenario="narrow_passage").unwrapped.engine.reward_weights
    assert v0["approach"] == 0.0 and v0["progress"] == 1.0  # version 0 keeps its defaults
    mixed = formation_v1.parallel_env(scenario="hold", reward_weights={"approach": 1.0}).engine.reward_weights
    assert mixed["approach"] == 1.0 and mixed["proximity"] == v1["proximity"]  # merged term by term
    assert with_version(0, {"dt": 0.05}) == {"dt": 0.05}
    with pytest.raises(ValueError, match="env version"):
        with_version(7, {})


def test_formation_v1_passes_the_pettingzoo_checkers() -> None:
    import functools

    from pettingzoo.test import api_test, parallel_api_test, seed_test

    from formation_env import formation_v1

    parallel_api_test(formation_v1.parallel_env(scenario="narrow_passage"), num_cycles=100)
    api_test(formation_v1.env(scenario="hold"), num_cycles=50)
    seed_test(functools.partial(formation_v1.env, scenario="moving_obstacles"), num_cycles=50)
