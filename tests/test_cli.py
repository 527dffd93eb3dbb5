"""The CLI: a user error prints one line and exits 2; ``--debug`` shows the traceback."""

from __future__ import annotations

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
        (["rollout", "--env-kwargs", "[1, 2]"], "--env-kwargs must be a JSON object (a dict of env arguments)"),
        (["evaluate", "--env-kwargs", "[]", "--episodes", "2"], "--env-kwargs must be a JSON object"),
        (["leaderboard", "--policies", "no/such/folder"], "--policies must be a folder of learned policies"),
    ],
)
def test_user_errors_exit_2_with_one_line(argv, match, capsys):
    try:
        rc = main(argv)
    except SystemExit as exc:  # argparse's own errors
        rc = exc.code
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and match in err[-1] and "Traceback" not in "\n".join(err)


def test_debug_shows_the_traceback():
    with pytest.raises(FileNotFoundError):
        main(["--debug", "evaluate", "--policy", "nope.zip", "--episodes", "2"])
