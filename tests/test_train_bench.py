"""``benchmarks.train_bench --quick``: the CI smoke of the training benchmark (fields and shares, never a timing)."""

from __future__ import annotations

import importlib.util
import json

import pytest

from benchmarks import train_bench

pytestmark = pytest.mark.slow


def test_quick_run_writes_rows_whose_shares_sum_to_one(tmp_path):
    out = tmp_path / "tb"
    assert train_bench.main(["--quick", "--recipes", "hold_ppo_commander", "hold_ppo_shared", "--out", str(out)]) == 0
    doc = json.loads((out / "train_bench.json").read_text())
    assert doc["quick"] is True and doc["machine"] and doc["command"].startswith("python -m benchmarks.train_bench")
    rows = doc["rows"]
    assert [r["run"] for r in rows[:2]] == ["hold_ppo_commander", "hold_ppo_shared"]
    peer = rows[2]
    if importlib.util.find_spec("supersuit") is None or importlib.util.find_spec("mpe2") is None:
        assert "skipped" in peer
        rows = rows[:2]
    else:
        assert peer["scenario"] == "simple_spread" and peer["settings_of"] == train_bench.PEER_RECIPE
    for r in rows:
        for key in ("algo", "mode", "scenario", "slots", "timesteps", "wall_s", "steps_per_s", "shares"):
            assert key in r, (r["run"], key)
        assert set(r["shares"]) == set(train_bench.SHARES)
        assert sum(r["shares"].values()) == pytest.approx(1.0, abs=1e-9)
        assert all(r["shares"][k] >= 0 for k in ("env_step", "policy_forward", "update")), r["shares"]
        assert r["shares"]["other"] > -1e-6, r["shares"]  # the timed parts never overlap
        assert r["timesteps"] >= 1024 and r["wall_s"] > 0  # whole rollouts: at least what was asked
    assert rows[1]["slots"] == 3 * rows[0]["slots"]  # shared mode: a slot per leader of each copy
    md = (out / "train_bench.md").read_text()
    assert "| hold_ppo_commander | ppo | commander | hold |" in md and "Measured" in md


def test_bad_arguments_are_usage_errors(tmp_path):
    with pytest.raises(SystemExit) as exc:
        train_bench.main(["--recipes", "no_such_recipe", "--out", str(tmp_path)])
    assert exc.value.code == 2
    with pytest.raises(SystemExit):
        train_bench.main(["--steps", "0", "--out", str(tmp_path)])
    with pytest.raises(SystemExit):
        train_bench.main(["--out", str(tmp_path / "x.md")])
