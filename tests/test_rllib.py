"""RLlib integration: fixed agent order, the env API, the smoke run's determinism across processes, and a
checkpoint evaluated through the policy interface."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("ray")


def test_multi_agent_env_order_and_api() -> None:
    from formation_env.integrations.rllib import FormationMultiAgentEnv

    env = FormationMultiAgentEnv({"scenario": "hold", "env_version": 1})
    assert env.possible_agents == ["leader_0", "leader_1", "leader_2"]
    obs, infos = env.reset(seed=0)
    assert list(obs) == env.possible_agents and set(infos["leader_0"]) >= {"success", "collision"}
    assert env.state().shape == env.engine.state_low.shape
    acts = {a: np.zeros(2, np.float32) for a in env.agents}
    _, rew, term, trunc, _ = env.step(acts)
    assert set(rew) == set(env.possible_agents) and "__all__" in term and "__all__" in trunc


@pytest.mark.slow
def test_smoke_same_seed_same_metrics_in_two_processes(tmp_path) -> None:
    lines = []
    for k in range(2):
        cmd = [sys.executable, "-m", "train.rllib", "--smoke", "--seed", "0", "--out", str(tmp_path / f"r{k}")]
        env = {k: v for k, v in os.environ.items() if k != "PYTHONHASHSEED"}  # the script fixes it itself
        out = subprocess.run(cmd, capture_output=True, text=True, timeout=600, check=True, env=env).stdout
        lines.append(json.loads(out.strip().splitlines()[-1]))
    assert lines[0] == lines[1]
    assert {"success_rate", "collision_rate", "env_steps"} <= set(lines[0]) and lines[0]["env_steps"] > 0


@pytest.fixture(scope="module")
def smoke_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A ``train.rllib --smoke`` output folder (checkpoint/, config.json) on ``hold``."""
    out = tmp_path_factory.mktemp("rllib") / "run"
    cmd = [sys.executable, "-m", "train.rllib", "--smoke", "--seed", "0", "--scenario", "hold", "--out", str(out)]
    subprocess.run(cmd, capture_output=True, text=True, timeout=600, check=True)
    return out


@pytest.mark.slow
def test_evaluate_an_rllib_checkpoint_on_the_suite(smoke_run: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from formation_env.cli import main
    from train.evaluate import METRIC_KEYS

    blobs = []
    for spec in (smoke_run, smoke_run / "checkpoint"):  # the run folder or its checkpoint
        assert main(["evaluate", "--policy", str(spec), "--scenario", "hold", "--episodes", "3", "--json"]) == 0
        blobs.append(json.loads(capsys.readouterr().out))
    assert blobs[0] == blobs[1] and set(blobs[0]["metrics"]) == set(METRIC_KEYS)
    assert 0.0 <= blobs[0]["metrics"]["collision_rate"] <= 1.0


@pytest.mark.slow
def test_rllib_policy_sees_what_the_rllib_env_gives(smoke_run: Path) -> None:
    """In the harness the policy reads ``Engine.observe``; the actions equal those on the RLlib env's own
    observations, and they are the mean of the module's action distribution, clipped to [-1, 1]."""
    import torch

    from agents.policy import RLlibPolicy, load_policy
    from formation_env.integrations.rllib import FormationMultiAgentEnv

    env = FormationMultiAgentEnv({"scenario": "hold", "env_version": 1})
    policy = load_policy(smoke_run, env.par_env)
    assert isinstance(policy, RLlibPolicy) and policy.name == "rllib_shared"
    assert policy.config["scenario"] == "hold"
    obs, _ = env.reset(seed=3)
    for _ in range(5):
        acts = policy.act_parallel(obs, env.par_env)  # from the engine's state
        stacked = np.stack([obs[a] for a in env.possible_agents])
        direct = policy.act(stacked)  # from the env's observations
        np.testing.assert_allclose(np.stack([acts[a] for a in env.possible_agents]), direct, atol=1e-6)
        with torch.no_grad():
            logits = policy.module.forward_inference({"obs": torch.as_tensor(stacked)})["action_dist_inputs"]
        np.testing.assert_allclose(direct, np.clip(logits[:, :2].numpy(), -1, 1), atol=1e-6)
        obs, *_ = env.step(acts)


def test_a_folder_that_is_no_checkpoint_is_refused(tmp_path: Path) -> None:
    from agents.policy import load_policy
    from formation_env.env.engine import Engine

    with pytest.raises(FileNotFoundError, match="not an RLlib checkpoint"):
        load_policy(tmp_path, Engine("hold"))


@pytest.mark.slow
def test_a_missing_module_id_is_named(smoke_run: Path) -> None:
    from agents.policy import RLlibPolicy

    with pytest.raises(ValueError, match=r"no module 'leader_0'; its modules: \['shared'\]"):
        RLlibPolicy.load(smoke_run, module_id="leader_0")


@pytest.mark.slow
def test_observations_of_another_shape_are_refused(smoke_run: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from formation_env.cli import main

    kw = '{"observation": ["position", "velocity", "goal"]}'
    argv = ["evaluate", "--policy", str(smoke_run), "--scenario", "hold", "--episodes", "2", "--env-kwargs", kw]
    assert main(argv) == 2
    assert "the RLlib policy takes observations of shape (34,)" in capsys.readouterr().err
