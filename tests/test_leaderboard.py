"""The leaderboard, the time lower bound, the random baseline, training recipes and honest metrics."""

from __future__ import annotations

import json
import re
import warnings
from pathlib import Path

import numpy as np
import pytest

from agents.bounds import time_lower_bound, time_lower_bound_seeds
from agents.policy import AnalyticPolicy, RandomPolicy, load_policy
from agents.rollout import reset_paired, run_batch
from formation_env.env.engine import Engine
from formation_env.env.scenarios import REGISTRY
from train.evaluate import evaluate, summarise
from train.leaders import load_config
from train.leaders import main as leaders_main


@pytest.mark.parametrize("scenario", sorted(REGISTRY))
def test_time_lower_bound_is_below_the_planners_time_on_every_solved_episode(scenario: str) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        eng = Engine(scenario)
    seeds = list(range(12))
    bound = time_lower_bound_seeds(eng, seeds)
    t = run_batch(eng, AnalyticPolicy(eng).act_engine, seeds)["time_to_goal"]
    solved = np.isfinite(t)
    assert solved.any() and np.all(np.isfinite(bound))
    assert np.all(t[solved] >= bound[solved] - 1e-9)


def test_time_lower_bound_is_the_exact_bang_bang_time_for_one_axis() -> None:
    """A leader D m from its goal along x reaches the tolerance ball in sqrt(2 (D - tol) / u_max) at the
    earliest (full acceleration, arrival at speed): the bound's first sample is that time rounded up."""
    eng = Engine("narrow_passage")
    s = reset_paired(eng, [0])
    D = 3.0
    goal = s.pos.copy()
    goal[:, :, 0] += D  # every agent's goal D m ahead along x
    state = s._replace(goal=goal, vel=np.zeros_like(s.vel), params={**s.params, "goal_b": s.params["goal_b"]})
    th, b = eng.affine.fit(goal)
    state = state._replace(params={**state.params, "goal_theta": th, "goal_b": b})
    t = float(time_lower_bound(eng, state)[0])
    exact = np.sqrt(2 * (D - eng.scenario.goal_tol) / eng.u_max)
    assert exact <= t < exact + eng.dt + 1e-9


def test_random_policy_is_seeded_and_bounded() -> None:
    eng = Engine("hold")
    s = reset_paired(eng, [0, 1, 2])
    a, b = RandomPolicy(eng, seed=3).act_engine(eng, s), RandomPolicy(eng, seed=3).act_engine(eng, s)
    np.testing.assert_array_equal(a, b)
    assert a.shape == (3, eng.n_l, eng.p) and np.all(np.abs(a) <= 1.0)
    res = evaluate("random", "hold", 4, seed=0, generalisation=False)
    assert res["policy"] == "random" and res["metrics"]["success_rate"] == 0.0


def test_episode_endings_name_what_ended_each_episode() -> None:
    """Every episode has one ending, consistent with success and collision; driving every leader left ends in the
    world box, the planner on hold in success, a random policy among the discs mostly in contacts."""
    from agents.rollout import ENDINGS

    left = Engine("hold")
    push = lambda e, s, o: np.tile([-1.0, 0.0], (s.batch_size, e.n_l, 1))  # noqa: E731
    assert set(run_batch(left, push, [0, 1, 2])["ending"]) == {"world_box"}
    assert set(run_batch(left, AnalyticPolicy(left).act_engine, [0, 1, 2])["ending"]) == {"success"}
    field = Engine("obstacle_field")
    res = run_batch(field, RandomPolicy(field, seed=0).act_engine, list(range(16)))
    ends = res["ending"]
    assert set(ends) <= set(ENDINGS) and (ends == "success").tolist() == res["success"].tolist()
    assert np.isin(ends, ["agents", "obstacle", "world_box"]).tolist() == res["collision"].tolist()
    assert evaluate("random", "obstacle_field", 16, seed=0, generalisation=False)["endings"] == {
        e: int(np.sum(ends == e)) for e in ENDINGS
    }


def test_metrics_are_means_and_worst_values_are_apart() -> None:
    res = {
        "success": np.array([True, True, False, False]),
        "collision": np.array([False, False, True, False]),
        "time_to_goal": np.array([2.0, 4.0, np.nan, np.nan]),
        "mean_formation_err": np.array([0.01, 0.02, 0.03, 0.04]),
        "max_formation_err": np.array([0.1, 0.2, 0.6, np.nan]),  # the last episode never formed
        "tracking_err": np.array([0.5, 0.1, 0.2, 0.2]),
        "min_clearance": np.array([0.5, 0.4, -0.1, 0.2]),
        "control_effort": np.ones(4),
    }
    metrics, cis, worst = summarise(res)
    assert metrics["max_formation_err"] == pytest.approx(0.3) and worst["max_formation_err"] == 0.6
    assert metrics["tracking_err"] == pytest.approx(0.25) and worst["tracking_err"] == 0.5
    assert metrics["min_clearance"] == pytest.approx(0.25) and worst["min_clearance"] == -0.1
    assert metrics["time_to_goal"] == 3.0 and worst["time_to_goal"] == 4.0
    lo, hi = cis["max_formation_err"]
    assert lo < metrics["max_formation_err"] < hi
    from scipy import stats

    ci = stats.binomtest(2, 4).proportion_ci(method="wilson")
    assert cis["success_rate"] == pytest.approx([ci.low, ci.high])


def test_recipe_file_sets_the_arguments_and_refuses_unknown_keys(tmp_path: Path) -> None:
    good = tmp_path / "r.yaml"
    good.write_text(
        "scenario: hold\nalgo_kwargs: {gamma: 0.98}\npolicy_kwargs: {net_arch: [8, 8]}\ncurriculum: [2, 0.5]\n"
    )
    cfg = load_config(good)
    assert cfg["scenario"] == "hold" and cfg["algo_kwargs"] == {"gamma": 0.98} and cfg["curriculum"] == (2.0, 0.5)
    bad = tmp_path / "bad.yaml"
    bad.write_text("scenaro: hold\n")
    with pytest.raises(ValueError, match="scenaro"):
        load_config(bad)
    with pytest.raises(SystemExit):
        leaders_main(["--config", str(bad), "--smoke"])


@pytest.mark.parametrize(
    "recipe", sorted(Path(__file__).resolve().parent.parent.joinpath("train", "configs").glob("*.yaml"))
)
def test_shipped_recipes_load(recipe: Path) -> None:
    cfg = load_config(recipe)
    assert cfg["algo"] in ("ppo", "sac") and cfg["scenario"] in REGISTRY


@pytest.mark.slow
def test_recipe_run_is_reproducible_and_the_leaderboard_reads_it(tmp_path: Path, capsys) -> None:
    recipe = tmp_path / "tiny.yaml"
    recipe.write_text(
        "algo: ppo\nmode: commander\nscenario: hold\ntimesteps: 256\nn_envs: 2\neval_episodes: 1\n"
        "policy_kwargs: {net_arch: [8, 8]}\nalgo_kwargs: {n_steps: 32}\n"
    )
    weights = []
    for k in ("a", "b"):
        leaders_main(["--config", str(recipe), "--smoke", "--seed", "3", "--out", str(tmp_path / k)])
        pol = load_policy(tmp_path / k / "hold_commander.zip", Engine("hold"))
        weights.append([p.detach().numpy().copy() for p in pol.model.policy.parameters()])
    for x, y in zip(*weights, strict=True):
        np.testing.assert_array_equal(x, y)
    pol = load_policy(tmp_path / "a" / "hold_commander.zip", Engine("hold"))
    assert pol.config["sb3_policy_kwargs"]["net_arch"] == [8, 8]  # the recipe's network
    assert pol.model.policy.mlp_extractor.policy_net[0].out_features == 8
    capsys.readouterr()
    folder = tmp_path / "pretrained"
    folder.mkdir()
    for suffix in (".zip", "_vecnormalize.pkl", "_config.json"):
        (folder / f"hold_ppo_commander_seed3{suffix}").write_bytes(
            (tmp_path / "a" / f"hold_commander{suffix}").read_bytes()
        )
    from formation_env.cli import main as cli

    md = tmp_path / "lb"
    assert (
        cli(
            [
                "leaderboard",
                "--episodes",
                "2",
                "--scenarios",
                "hold",
                "--policies",
                str(folder),
                "--out",
                str(md),
                "--json",
            ]
        )
        == 0
    )
    board = json.loads(capsys.readouterr().out)
    rows = board["scenarios"]["hold"]
    assert rows["random"]["kind"] == "random" and rows["analytic"]["kind"] == "analytic"
    assert rows["ppo_commander"]["kind"] == "learned" and rows["ppo_commander"]["policies"] == [
        "hold_ppo_commander_seed3.zip"
    ]
    for key in ("success_rate", "collision_rate", "time_to_goal", "time_lower_bound", "time_vs_analytic"):
        assert key in rows["analytic"]["metrics"] and key in rows["ppo_commander"]["metrics"]
    assert rows["analytic"]["metrics"]["time_vs_analytic"] == 0.0  # paired with itself
    assert len(rows["ppo_commander"]["time_vs_analytic_ci95"]) == 1  # one interval per seed
    assert rows["ppo_shared"]["metrics"] is None and rows["ppo_residual"]["metrics"] is None
    assert rows["analytic"]["metrics"]["success_rate"] == 1.0
    assert "## hold" in (md / "leaderboard.md").read_text()


def test_readme_shows_the_leaderboards_table() -> None:
    """The README holds docs/leaderboard.md's summary table and, once the robustness view has run, its table."""
    from train.leaderboard import ROBUSTNESS_HEADING

    root = Path(__file__).resolve().parent.parent
    doc = (root / "docs" / "leaderboard.md").read_text()
    table = doc.split("## Summary", 1)[1].split("\n## ", 1)[0].strip().splitlines()
    assert table[0].startswith("| scenario |") and len(table) == 2 + len(REGISTRY)
    readme = (root / "README.md").read_text()
    assert "\n".join(table) in readme
    robust = doc.split(ROBUSTNESS_HEADING, 1)[1] if ROBUSTNESS_HEADING in doc else ""
    for line in robust.splitlines():  # every planner row of the section stands in the README's table
        if line.startswith("| analytic |"):
            cells = line.split("|")[2:-1]
            assert any(row.split("|")[3:-1] == cells for row in readme.splitlines()), line


SHIPPED = sorted(Path("agents/pretrained").glob("*_config.json"))


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.name[: -len("_config.json")])
def test_shipped_policy_is_what_its_recorded_command_trains(path: Path) -> None:
    """Every shipped policy's config is what its recorded command (its recipe and flags, read as they are today)
    asks for: a recipe edited after a policy was shipped fails here until the policy is retrained."""
    import json
    import shlex

    from formation_env.env.versions import with_version
    from train.leaders import parse_run

    shipped = json.loads(path.read_text())
    argv = shlex.split(shipped["command"])
    assert argv[:3] == ["python", "-m", "train.leaders"], shipped["command"]
    recorded = shipped.get("config_file")
    if recorded and Path(recorded).is_absolute():
        # trained from a copy of the recipe outside the repo (the policy's README row says so): the repo's recipe of
        # the policy's name must ask for what the copy did
        recipe = f"train/configs/{re.sub(r'_seed[0-9]+$', '', path.name[: -len('_config.json')])}.yaml"
        assert Path(recipe).exists(), (recorded, recipe)
        argv, recorded = [recipe if a == shipped["config_file"] else a for a in argv], recipe
    run = parse_run(argv[3:])
    assert run["config_file"] == recorded
    defaults = {"algo": "ppo", "mode": "commander", "scenario": "narrow_passage", "timesteps": 100_000, "seed": 0,
                "n_envs": 16, "residual": 0.0, "action_mode": "leaders", "range_curriculum": None,
                "central_critic": False, "checkpoints": 4, "obs_norm": "running"}  # fmt: skip
    for key, default in defaults.items():
        assert json.loads(json.dumps(run.get(key, default))) == shipped.get(key, default), key
    assert with_version(run.get("env_version", 0), run.get("env_kwargs", {})) == shipped["env_kwargs"]
    assert run.get("algo_kwargs", {}).items() <= shipped.get("algo_kwargs", {}).items()
    assert run.get("policy_kwargs", {}).items() <= shipped.get("sb3_policy_kwargs", {}).items()


#: (scenario, engine arguments, whether the team forms): the stationary law lags moving leaders by more than 5 mm.
FORMING = [("maneuver", {}, True), ("hold", {"dynamics": "single_integrator", "follower_law": "stationary"}, False)]


@pytest.mark.parametrize(("scenario", "kwargs", "forms"), FORMING)
def test_formed_error_and_tracking_error_follow_their_definitions(scenario: str, kwargs: dict, forms: bool) -> None:
    """``max_formation_err`` is the largest error from the first sample at or below FORMED_FRACTION x formation_tol
    (the reset counts), ``tracking_err`` the mean over the episode's samples of the largest distance to the
    reference, both recomputed here from the engine's own step by step."""
    from agents.rollout import FORMED_FRACTION

    eng = Engine(scenario, max_cycles=60, **kwargs)
    pol = AnalyticPolicy(eng)
    seeds = list(range(5))
    res = run_batch(eng, pol.act_engine, seeds)
    tol = FORMED_FRACTION * eng.scenario.formation_tol
    for b, s in enumerate(seeds):
        state = reset_paired(eng, [s])
        obs = eng.observe(state)
        errs, times, far = [float(state.err[0])], [0.0], []
        for _ in range(int(res["steps"][b])):
            state, obs, _, _, _, info = eng.step(state, pol.act_engine(eng, state, obs))
            errs.append(float(info["formation_error"][0]))
            times.append(float(info["time"][0]))
            far.append(float(info["goal_distance"][0]))
        below = [i for i, e in enumerate(errs) if e <= tol]
        if below:
            assert res["formed_time"][b] == pytest.approx(times[below[0]])
            assert res["max_formation_err"][b] == pytest.approx(max(errs[below[0] :]))
        else:
            assert np.isnan(res["formed_time"][b]) and np.isnan(res["max_formation_err"][b])
        assert res["tracking_err"][b] == pytest.approx(np.mean(far))
    assert np.isfinite(res["formed_time"]).all() if forms else np.isnan(res["formed_time"]).all()


def test_tracking_scenarios_show_the_tracking_error_on_the_board() -> None:
    from train.leaderboard import ENTRIES, SHOWN, SHOWN_TRACKING, markdown, summary_table

    def row(success: float, track: float) -> dict:
        m = dict.fromkeys({*SHOWN, *SHOWN_TRACKING}, 0.01)
        m.update(success_rate=success, tracking_err=track, time_to_goal=0.1)
        return {"kind": "analytic", "metrics": m}

    rows = {e: row(1.0, 0.02 * (i + 1)) for i, e in enumerate(ENTRIES)}
    board = {"scenarios": {"maneuver": rows, "hold": rows}, "episodes": 2, "seed": 0}
    md = markdown(board, "formation-env leaderboard")
    man, hold = md.split("## maneuver", 1)[1].split("## hold")
    assert "| tracking_err |" in man and "time_to_goal" not in man.split("\n\n")[1]
    assert "| time_to_goal |" in hold and "tracking_err" not in hold
    assert "from the first sample whose error is at most a tenth" in md  # the definition of "formed"
    table = summary_table(board)
    assert "| maneuver | 1.00 / 0.020 m | 1.00 / 0.040 m |" in table and "| hold | 1.00 / 0.1 s |" in table


def _fake_board(network: str, success: float) -> dict:
    """A board of two scenarios (one timed, one tracking) with the planner and one learned entry."""

    def row(s: float) -> dict:
        m = {"success_rate": s, "collision_rate": 1.0 - s, "time_to_goal": 5.0, "tracking_err": 0.02}
        return {"kind": "learned", "metrics": m, "per_seed": [m]}

    rows = {"random": {"kind": "random", "metrics": None}, "analytic": row(1.0), "ppo_commander": row(success)}
    return {"scenarios": {"hold": rows, "maneuver": rows}, "episodes": 2, "seed": 0, "network": network}


def test_robustness_section_and_table_are_written_beside_the_board(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``--network``'s page and README table: one column per condition, success / collisions (/ time), entries with
    no result under any condition left out; the project's standard board keeps the section and vice versa."""
    from train.leaderboard import ROBUSTNESS_HEADING, robustness_markdown, robustness_table, write_project

    boards = {"ideal": _fake_board("ideal", 0.9), "loss20": _fake_board("loss20", 0.5)}
    page = robustness_markdown(boards, "formation-env leaderboard --network all --project")
    assert page.startswith(ROBUSTNESS_HEADING) and "| entry | ideal | loss20 |" in page
    assert "| ppo_commander | 0.90 / 0.10 / 5 s | 0.50 / 0.50 / 5 s |" in page  # timed: the time to goal
    assert "| ppo_commander | 0.90 / 0.10 / 0.02 m | 0.50 / 0.50 / 0.02 m |" in page  # tracking: the error
    assert "| random |" not in page
    table = robustness_table(boards)
    assert table.splitlines()[0] == "| scenario | entry | ideal | loss20 |"
    assert "| hold | analytic | 1.00 / 0.00 / 5 s | 1.00 / 0.00 / 5 s |" in table
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "leaderboard.md").write_text("# Leaderboard\n\nold board\n")
    readme = "# x\n\n| scenario | random |\n|---|---|\n| hold | 0 |\n\n" + table.replace("0.50", "0.10") + "\n\nend\n"
    (tmp_path / "README.md").write_text(readme)
    write_project({"robustness": boards}, page, tmp_path)
    doc = (tmp_path / "docs" / "leaderboard.md").read_text()
    assert doc.startswith("# Leaderboard\n\nold board\n\n" + ROBUSTNESS_HEADING)
    text = (tmp_path / "README.md").read_text()
    assert table in text and "| hold | 0 |" in text and text.endswith("\n\nend\n")
    board = _fake_board("ideal", 0.9)
    board["scenarios"] = {"hold": board["scenarios"]["hold"]}
    new_page = "# Leaderboard\n\nnew board\n\n## Summary\n\n| scenario | random |\n|---|---|\n| hold | 1 |\n"
    from train import leaderboard as lb

    monkeypatch.setattr(lb, "summary_table", lambda b: "| scenario | random |\n|---|---|\n| hold | 1 |")
    write_project(board, new_page, tmp_path)
    doc = (tmp_path / "docs" / "leaderboard.md").read_text()
    assert doc.startswith(new_page) and doc.count(ROBUSTNESS_HEADING) == 1 and "| ppo_commander | 0.90" in doc
    assert "| hold | 1 |" in (tmp_path / "README.md").read_text()


def test_network_view_runs_every_entry_over_the_network_with_the_distributed_law(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``leaderboard(network=...)``: each entry's suite runs with the condition's network and ``NETWORK_LAW`` over
    the policy's own arguments; the entries trained under a network join; a bad name is refused."""
    from train import leaderboard as lb

    seen: list[dict] = []
    real = lb.evaluate_suite

    def spy(spec, scenario, *args, **kw):  # type: ignore[no-untyped-def]
        seen.append(kw.get("env_kwargs"))
        return real(spec, scenario, *args, **kw)

    monkeypatch.setattr(lb, "evaluate_suite", spy)
    board = lb.leaderboard(2, 0, tmp_path, ["hold"], network="loss20")
    assert board["network"] == "loss20" and set(lb.NETWORK_TRAINED) <= set(board["scenarios"]["hold"])
    assert seen == [{"follower_law": "linear", "network": {"loss": 0.2}}] * 2  # random and analytic
    assert board["scenarios"]["hold"]["analytic"]["metrics"]["success_rate"] == 1.0
    with pytest.raises(ValueError, match="network must be one of"):
        lb.leaderboard(2, 0, tmp_path, ["hold"], network="lossy")
