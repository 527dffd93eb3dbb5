"""The CLI: a user error prints one line and exits 2; ``--debug`` shows the traceback."""

from __future__ import annotations

import re

import pytest

from formation_env.cli import main


@pytest.mark.parametrize(
    ("argv", "match"),
    [
        (["evaluate", "--episodes", "0"], "--episodes must be a positive integer"),
        (["rollout", "--steps", "-1"], "--steps must be a positive integer"),
        (["evaluate", "--policy", "nope.zip", "--episodes", "2"], "no saved model"),
        (["evaluate", "--env-kwargs", "{bad", "--episodes", "2"], "--env-kwargs must be a JSON object"),
        (["evaluate", "--env-kwargs", '{"gap_width": [2, 1]}', "--episodes", "2"], "low <= high"),
        (["evaluate", "--scenario", "maze"], "invalid choice"),
        (["rollout", "--scenario", "maze"], "argument --scenario: invalid choice: 'maze'"),
        (["rollout", "--fps", "0"], "--fps must be a positive integer, got 0"),
        (["rollout", "--env-kwargs", "[1, 2]"], "--env-kwargs must be a JSON object (a dict of arguments)"),
        (["evaluate", "--env-kwargs", "[]", "--episodes", "2"], "--env-kwargs must be a JSON object"),
        (["leaderboard", "--policies", "no/such/folder"], "--policies must be a folder of learned policies"),
        (
            [
                "evaluate",
                "--policy",
                "agents/pretrained/maneuver_ppo_commander_seed0.zip",
                "--scenario",
                "obstacle_field",
            ],
            "the policy takes observations of shape (46,), the 'obstacle_field' engine gives (64,): evaluate it on its "
            "training scenario ('maneuver')",
        ),
    ],
)
def test_user_errors_exit_2_with_one_line(argv, match, capsys):
    try:
        rc = main(argv)
    except SystemExit as exc:  # argparse's own errors
        rc = exc.code
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and match in err[-1] and "Traceback" not in "\n".join(err)


def test_evaluate_runs_a_saved_policy_on_its_training_scenario(capsys) -> None:
    """Without ``--scenario`` a saved policy meets the suite of the scenario it was trained on."""
    import json

    assert main(["evaluate", "--policy", "agents/pretrained/maneuver_ppo_commander_seed0.zip", "--episodes", "2",
                 "--json"]) == 0  # fmt: skip
    out = json.loads(capsys.readouterr().out)
    assert out["scenario"] == "maneuver" and out["metrics"]["success_rate"] == 1.0


def test_debug_shows_the_traceback():
    with pytest.raises(FileNotFoundError):
        main(["--debug", "evaluate", "--policy", "nope.zip", "--episodes", "2"])


def test_train_takes_the_flags_of_train_leaders(capsys) -> None:
    """``formation-env train`` is ``python -m train.leaders`` under another name: same flags, same errors."""
    from train.leaders import main as leaders_main

    helps = []
    for run in (lambda: main(["train", "-h"]), lambda: leaders_main(["-h"])):
        with pytest.raises(SystemExit) as exc:
            run()
        assert exc.value.code == 0
        helps.append(capsys.readouterr().out)
    assert helps[0].startswith("usage: formation-env train") and "--curriculum" in helps[0]
    flags = [set(re.findall(r"--[a-z][a-z-]*", h)) for h in helps]
    assert flags[0] == flags[1] and len(flags[0]) > 10
    with pytest.raises(SystemExit) as exc:
        main(["train", "--algo", "nope"])
    assert exc.value.code == 2 and "argument --algo: invalid choice: 'nope'" in capsys.readouterr().err


def test_unknown_flags_of_other_commands_are_refused(capsys) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["evaluate", "--bogus"])
    assert exc.value.code == 2 and "unrecognized arguments: --bogus" in capsys.readouterr().err


@pytest.mark.slow
def test_train_smoke_run(tmp_path, capsys) -> None:
    import json

    assert main(["train", "--smoke", "--scenario", "hold", "--n-envs", "2", "--seed", "3", "--out", str(tmp_path)]) == 0
    cfg = json.loads((tmp_path / "hold_commander_config.json").read_text())
    assert cfg["scenario"] == "hold" and cfg["seed"] == 3 and (tmp_path / "hold_commander.zip").is_file()


def _json_and_bar(capsys, argv: list[str]) -> tuple[dict, str]:
    import json

    assert main(argv) == 0
    cap = capsys.readouterr()
    return json.loads(cap.out), cap.err  # stdout is the one JSON object, bar or not


def test_progress_bars_go_to_stderr_and_keep_json_whole(capsys, tmp_path) -> None:
    argv = ["evaluate", "--scenario", "hold", "--episodes", "2", "--json"]
    blob, err = _json_and_bar(capsys, [*argv, "--progress"])
    assert "metrics" in blob and "analytic on hold" in err and "step" in err
    blob_quiet, err = _json_and_bar(capsys, argv)  # stderr is not a terminal here: no bar by default
    assert blob_quiet == blob and "analytic on hold" not in err
    (tmp_path / "none").mkdir()
    lb = ["leaderboard", "--scenarios", "hold", "--episodes", "2", "--policies", str(tmp_path / "none")]
    board, err = _json_and_bar(capsys, [*lb, "--out", str(tmp_path / "lb"), "--json", "--progress"])
    assert set(board["scenarios"]["hold"]) >= {"random", "analytic"} and "/2 " in err and "suite/s" in err


def test_bench_out_is_a_folder(capsys, tmp_path) -> None:
    assert main(["bench", "--only", "core", "--quick", "--out", str(tmp_path / "b")]) == 0
    assert (tmp_path / "b" / "BENCHMARKS.md").read_text().startswith("# Benchmarks")
    with pytest.raises(SystemExit) as exc:
        main(["bench", "--out", str(tmp_path / "BENCHMARKS.md")])
    assert exc.value.code == 2 and "--out is a folder" in capsys.readouterr().err


def test_progress_bar_shows_on_a_terminal_or_when_asked(capsys) -> None:
    from formation_env._progress import progress_bar

    for show in (None, False, True):  # pytest's stderr is not a terminal: None shows nothing
        with progress_bar(3, f"bar-{show}", show) as bar:
            bar.update(3)
    err = capsys.readouterr().err
    assert "bar-True" in err and "bar-None" not in err and "bar-False" not in err


def test_leaderboard_writes_into_an_out_folder_and_the_projects_table_is_one_flag_away(
    tmp_path, monkeypatch, capsys
) -> None:
    """By default ``out/leaderboard.md`` under the working folder (no stray ``docs/``); ``--out`` is a folder as
    everywhere; ``--project`` rewrites the checkout's docs/leaderboard.md and the README's results table."""
    import json

    from train.leaderboard import leaderboard, summary_table, write_project

    monkeypatch.chdir(tmp_path)
    (tmp_path / "none").mkdir()
    lb = ["leaderboard", "--scenarios", "hold", "--episodes", "2", "--policies", str(tmp_path / "none")]
    assert main([*lb, "--json"]) == 0
    assert set(json.loads(capsys.readouterr().out)["scenarios"]) == {"hold"}
    assert (tmp_path / "out" / "leaderboard.md").read_text().startswith("# Leaderboard")
    assert not (tmp_path / "docs").exists()
    assert main([*lb, "--out", "lb.md"]) == 2
    assert "--out is a folder (leaderboard.md is written inside it)" in capsys.readouterr().err
    assert main([*lb, "--project"]) == 2
    assert "--project writes the whole table" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        main(["leaderboard", "--project", "--out", "x"])
    assert exc.value.code == 2 and "not allowed with argument" in capsys.readouterr().err

    board = leaderboard(2, 0, tmp_path / "none", ["hold"])
    proj = tmp_path / "proj"
    (proj / "docs").mkdir(parents=True)
    head = summary_table(board).splitlines()[0]
    (proj / "README.md").write_text(f"intro\n\n{head}\n|---|\n| hold | stale |\n\nafter\n")
    written = write_project(board, "# Leaderboard\n", proj)
    assert written == [proj / "docs" / "leaderboard.md", proj / "README.md"]
    assert (proj / "docs" / "leaderboard.md").read_text() == "# Leaderboard\n"
    assert (proj / "README.md").read_text() == f"intro\n\n{summary_table(board)}\n\nafter\n"
    with pytest.raises(FileNotFoundError, match=r"is not one \(no README.md or docs/ in it\): run from a clone"):
        write_project(board, "", tmp_path / "none")


def test_bench_train_refuses_only(capsys, tmp_path) -> None:
    """``bench --train`` runs benchmarks.train_bench alone (tests/test_train_bench.py runs its quick mode)."""
    assert main(["bench", "--train", "--only", "core", "--out", str(tmp_path)]) == 2
    assert "drop --only" in capsys.readouterr().err
