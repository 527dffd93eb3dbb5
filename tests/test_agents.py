"""Analytic planners, the policy interface and the evaluation harness (agents/, train/evaluate.py)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from agents.planner import PassagePlanner, make_planner
from agents.policy import AnalyticPolicy, LearnedPolicy, decode_state, load_policy
from formation_env.env.engine import Engine
from formation_env.env.scenarios import REGISTRY
from train.evaluate import METRIC_KEYS, evaluate, reset_paired, run_batch, wilson

SEEDS = [0, 1, 2, 3, 4, 5, 6, 7]


@pytest.fixture(scope="module")
def passage() -> Engine:
    return Engine("narrow_passage")


def test_planner_solves_narrow_passage_without_collisions(passage: Engine) -> None:
    res = run_batch(passage, lambda e, s, o: PassagePlanner()(e, s), SEEDS)
    assert res["success"].all()
    assert not res["collision"].any()
    assert (res["min_clearance"] > 0).all()
    assert np.all(res["time_to_goal"] < 12.0)


@pytest.mark.parametrize("scenario", sorted(REGISTRY))
def test_every_scenario_has_a_planner_that_solves_it(scenario: str) -> None:
    eng = Engine(scenario)
    planner = make_planner(scenario)
    assert type(planner).__name__ == REGISTRY[scenario].planner.split(":")[1]
    res = run_batch(eng, lambda e, s, o: planner(e, s), SEEDS)
    assert not res["collision"].any()
    assert res["success"].mean() >= 0.9


def test_planner_decodes_moving_obstacles_from_the_global_state() -> None:
    eng = Engine("moving_obstacles")
    state = reset_paired(eng, [5, 6])
    for _ in range(30):
        state = eng.step(state, make_planner("moving_obstacles")(eng, state))[0]
    dec = decode_state(eng, eng.global_state(state))
    now = eng.capsules(state.params, state.k)
    again = eng.capsules({**state.params, "moving_circles": dec.params["moving_circles"]}, state.k + 7)
    later = eng.capsules(state.params, state.k + 7)
    np.testing.assert_allclose(again.a, later.a, atol=1e-5)
    assert now.a.shape == again.a.shape


def test_make_planner_refuses_unknown_scenario() -> None:
    with pytest.raises(KeyError, match="nope"):
        make_planner("nope")


def test_analytic_policy_shapes_and_bounds(passage: Engine) -> None:
    pol = load_policy("analytic", passage)
    assert isinstance(pol, AnalyticPolicy)
    state = reset_paired(passage, [0, 1, 2])
    a = pol.act_engine(passage, state)
    assert a.shape == (3, passage.n_l, passage.p)
    assert np.all(np.abs(a) <= 1.0)
    # commander interface: global state in, (B, n_l p) out, equal to the engine-state path
    gs = passage.global_state(state)
    ac = pol.act(gs)
    assert ac.shape == (3, passage.n_l * passage.p) and ac.dtype == np.float32
    assert np.all(np.abs(ac) <= 1.0)
    np.testing.assert_allclose(ac, a.reshape(3, -1), atol=1e-3)


def test_decode_state_round_trip(passage: Engine) -> None:
    state = reset_paired(passage, [3, 4])
    dec = decode_state(passage, passage.global_state(state))
    np.testing.assert_allclose(dec.pos, state.pos, atol=1e-5)
    for key in ("wall_x", "gap_center", "gap_width"):
        np.testing.assert_allclose(dec.params[key], state.params[key], atol=1e-5)


def test_act_parallel_on_pettingzoo_env() -> None:
    from formation_env import formation_v0

    env = formation_v0.parallel_env(scenario="narrow_passage")
    obs, _ = env.reset(seed=0)
    pol = load_policy("analytic", env)
    acts = pol.act_parallel(obs, env)
    assert set(acts) == set(env.agents)
    for a in acts.values():
        assert a.shape == (env.engine.p,) and np.all(np.abs(a) <= 1.0)
    for _ in range(5):
        obs, *_ = env.step(pol.act_parallel(obs, env))


def test_learned_policy_missing_file_raises(tmp_path) -> None:
    with pytest.raises(FileNotFoundError, match="no saved model"):
        LearnedPolicy.load(tmp_path / "none.zip")


def test_a_zip_without_a_model_is_refused_naming_what_it_misses(tmp_path, capsys) -> None:
    """A zip holding no SB3 model (or not a zip at all) is refused naming the missing entries, not with SB3's
    bare ``AssertionError: No data found in the saved file``; through the CLI: one line, exit 2."""
    import zipfile

    from formation_env.cli import main

    empty = tmp_path / "notes.zip"
    with zipfile.ZipFile(empty, "w") as zf:
        zf.writestr("readme.txt", "not a model")
    weights_only = tmp_path / "weights.zip"
    with zipfile.ZipFile(weights_only, "w") as zf:
        zf.writestr("policy.pth", b"")
    text = tmp_path / "text.zip"
    text.write_text("hello")
    with pytest.raises(ValueError, match=r"holds no SB3 model: it lacks 'data' \(.*\) and 'policy.pth' \(.*readme.txt"):
        load_policy(empty, Engine("hold"))
    with pytest.raises(ValueError, match=r"lacks 'data' \(the model's class, spaces and hyperparameters\); it holds"):
        LearnedPolicy.load(weights_only)
    with pytest.raises(ValueError, match="is not a saved SB3 model: not a zip archive"):
        LearnedPolicy.load(text)
    assert main(["evaluate", "--policy", str(empty), "--scenario", "hold", "--episodes", "2"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "holds no SB3 model: it lacks 'data'" in err[0] and "AssertionError" not in err[0]


def test_load_policy_resolves_a_spec_once_into_a_policy_knowing_its_scenario_and_env_arguments() -> None:
    """``load_policy(spec)`` needs no env: a saved policy gets its training scenario and the training values of the
    arguments that shape what it observes; the planner and the random policy the default scenario or the given one.
    ``evaluate`` takes the policy's scenario and arguments when given a policy without them."""
    from agents.policy import DEFAULT_SCENARIO, POLICY_ENV_KWARGS, saved_config

    spec = "agents/pretrained/narrow_passage_ppo_commander_seed0.zip"
    pol = load_policy(spec)
    config = saved_config(spec)
    assert isinstance(pol, LearnedPolicy) and pol.scenario == config["scenario"] == "narrow_passage"
    assert pol.env_kwargs == {k: v for k, v in config["env_kwargs"].items() if k in POLICY_ENV_KWARGS}
    assert "reward_weights" in config["env_kwargs"] and "reward_weights" not in pol.env_kwargs  # training only
    planner = load_policy("analytic")
    assert planner.scenario == DEFAULT_SCENARIO and planner.env_kwargs == {}
    held = load_policy("random", scenario="hold", env_kwargs={"framework": "bipyramid_3d"})
    assert held.scenario == "hold" and held.engine.d == 3 and held.env_kwargs == {"framework": "bipyramid_3d"}
    given = load_policy("analytic", Engine("hold"))
    assert given.scenario == "hold" and given.env_kwargs == {}
    with pytest.raises(ValueError, match="an env to act in, or scenario and env_kwargs to build one, not both"):
        load_policy("analytic", Engine("hold"), scenario="hold")
    res = evaluate(held, None, 2, seed=0, generalisation=False)
    assert res["scenario"] == "hold" and res["policy"] == "random"


def test_wilson_interval() -> None:
    lo, hi = wilson(10, 10)
    assert hi == 1.0 and 0.69 < lo < 0.73
    lo, hi = wilson(0, 10)
    assert lo == 0.0 and 0.27 < hi < 0.31


def test_evaluate_pairs_seeds_and_json_contract(tmp_path) -> None:
    a = evaluate("analytic", "narrow_passage", 4, seed=5, generalisation=False)
    b = evaluate(AnalyticPolicy(Engine("narrow_passage")), "narrow_passage", 4, seed=5, generalisation=False)
    assert a["seeds"] == [5, 8]
    assert a["per_episode"]["time_to_goal"] == b["per_episode"]["time_to_goal"]  # paired, deterministic
    c = evaluate("analytic", "narrow_passage", 4, seed=6, generalisation=False)
    assert c["per_episode"]["time_to_goal"][:3] == a["per_episode"]["time_to_goal"][1:]  # episode = seed
    assert set(a["metrics"]) == set(METRIC_KEYS)


def test_cli_evaluate_json(tmp_path, capsys) -> None:
    from formation_env.cli import main

    rc = main(["evaluate", "--policy", "analytic", "--episodes", "3", "--seed", "0", "--json", "--out", str(tmp_path)])
    assert rc == 0
    blob = json.loads(capsys.readouterr().out)
    m = blob["metrics"]
    for key in ("success_rate", "collision_rate", "time_to_goal"):
        assert key in m
    assert set(m) == set(METRIC_KEYS)
    assert m["success_rate"] == 1.0 and m["collision_rate"] == 0.0
    assert math.isfinite(m["time_to_goal"])
    assert (tmp_path / "metrics_analytic.md").exists() and (tmp_path / "episodes_analytic.csv").exists()
    assert (tmp_path / "episode_analytic.gif").exists()


def test_report_section(tmp_path, monkeypatch) -> None:
    import train.report_section as rs

    monkeypatch.setitem(rs.STANDARD_SUITE, "quick_episodes", 3)
    lines = rs.evaluation_section(tmp_path, quick=True)
    text = "\n".join(lines)
    assert "| analytic |" in text and "narrow_0.8-1.0" in text
    assert (tmp_path / "evaluation" / "comparison.png").exists()


def test_paired_difference() -> None:
    from train.evaluate import paired_difference

    a = evaluate("analytic", "narrow_passage", 3, seed=0, generalisation=False)
    m, lo, hi, k = paired_difference(a, a)
    assert (m, lo, hi, k) == (0.0, 0.0, 0.0, 3)
    b = evaluate("analytic", "narrow_passage", 3, seed=1, generalisation=False)
    with pytest.raises(ValueError, match="not paired"):
        paired_difference(a, b)


def test_planner_tuning_runs_in_the_engine_and_grid_given(capsys: pytest.CaptureFixture[str]) -> None:
    """``python -m agents.planner --tune``: the grid search runs in ``Engine(scenario, **env_kwargs)`` over the grid
    given, best first, and ``--suite N`` runs the best on the suite in the same engine; bad JSON is a usage error."""
    from agents.planner import main, rollout_stats, tune

    grid = {"kp": [2.0, 6.0], "lookahead": [1.5]}
    kw = {"follower_law": "linear", "network": {"loss": 0.2}}
    best, rows = tune("hold", 4, env_kwargs=kw, grid=grid)
    assert [r[0] for r in rows] in ([{"kp": 2.0, "lookahead": 1.5}, {"kp": 6.0, "lookahead": 1.5}],
                                    [{"kp": 6.0, "lookahead": 1.5}, {"kp": 2.0, "lookahead": 1.5}])  # fmt: skip
    assert best == rows[0][0]
    key = [(-s["success_rate"], s["collision_rate"], s["time_to_goal"]) for _, s in rows]
    assert key == sorted(key)
    engine = Engine("hold", **kw)
    assert rows[0][1] == rollout_stats(engine, make_planner("hold", **best), list(range(10_000, 10_004)))
    argv = [
        "--tune",
        "hold",
        "--seeds",
        "4",
        "--grid",
        json.dumps(grid),
        "--env-kwargs",
        json.dumps(kw),
        "--suite",
        "3",
    ]
    assert main(argv) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[-2] == "best: " + json.dumps(best)
    suite = rollout_stats(engine, make_planner("hold", **best), [0, 1, 2])
    assert out[-1] == "suite 0..2: " + json.dumps(suite)
    with pytest.raises(SystemExit):
        main(["--tune", "hold", "--grid", "[1, 2]"])
    assert "--grid must be a JSON object" in capsys.readouterr().err
