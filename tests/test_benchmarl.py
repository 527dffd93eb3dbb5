"""BenchMARL: the formation env as a task (``formation_env.integrations.benchmarl``); its env passes TorchRL's
``check_env_specs``, its episode metrics are logged, and a MAPPO experiment runs on it."""

from __future__ import annotations

from pathlib import Path

import pytest

pytest.importorskip("benchmarl", reason="BenchMARL is not installed: pip install 'formation-env[benchmarl]'")

from torchrl.envs.utils import check_env_specs

from formation_env.integrations.benchmarl import DEFAULT_CONFIG, FormationTask, FormationTaskClass

# TorchRL names the PettingZoo release it tests with (1.24.3); this env is checked here on the installed one.
pytestmark = pytest.mark.filterwarnings("ignore:PettingZoo in TorchRL is tested:UserWarning")

#: Short episodes, so that some end within a smoke run.
SHORT = {"env_version": 1, "max_cycles": 20}


def test_every_scenario_task_and_the_shipped_config() -> None:
    from formation_env.env.scenarios import REGISTRY

    assert {t.name.lower() for t in FormationTask} <= set(REGISTRY)
    task = FormationTask.NARROW_PASSAGE.get_from_yaml()
    assert isinstance(task, FormationTaskClass) and DEFAULT_CONFIG.is_file()
    assert task.config["env_version"] == 1 and task.max_steps(None) == task.config["max_cycles"]


def test_env_specs_and_logged_episode_metrics() -> None:
    task = FormationTask.HOLD.get_task(config=dict(SHORT))
    env = task.get_env_fun(num_envs=1, continuous_actions=True, seed=0, device="cpu")()
    check_env_specs(env, seed=0)
    assert task.group_map(env) == {"leader": ["leader_0", "leader_1", "leader_2"]}
    assert task.state_spec(env) is not None and "success" in task.info_spec(env)["leader", "info"].keys()
    td = env.rollout(50, break_when_any_done=False)  # random actions; episodes end by step 20 at the latest
    logged = FormationTaskClass.log_info(td)
    assert set(logged) == {"collection/formation/success_rate", "collection/formation/collision_rate"}
    ended = td["next", "done"].reshape(td.shape[0], -1).any(-1)
    collided = td["next", "leader", "info", "collision"].reshape(td.shape[0], -1)[:, 0]
    assert logged["collection/formation/collision_rate"] == pytest.approx(collided[ended].float().mean().item())
    assert FormationTaskClass.log_info(td[:1]) == {}  # no episode ended: nothing to log


@pytest.mark.slow
def test_mappo_smoke_run(tmp_path: Path) -> None:
    from benchmarl.algorithms import MappoConfig
    from benchmarl.experiment import Experiment, ExperimentConfig
    from benchmarl.models.mlp import MlpConfig

    cfg = ExperimentConfig.get_from_yaml()
    cfg.max_n_iters, cfg.max_n_frames = 2, None
    cfg.on_policy_collected_frames_per_batch, cfg.on_policy_n_envs_per_worker = 80, 2
    cfg.on_policy_minibatch_size, cfg.on_policy_n_minibatch_iters = 40, 1
    cfg.evaluation, cfg.render, cfg.loggers, cfg.save_folder = False, False, ["csv"], str(tmp_path)
    model = MlpConfig.get_from_yaml()
    exp = Experiment(task=FormationTask.HOLD.get_task(config=dict(SHORT)), algorithm_config=MappoConfig.get_from_yaml(),
                     model_config=model, critic_model_config=model, seed=0, config=cfg)  # fmt: skip
    exp.run()
    assert exp.n_iters_performed == 2 and exp.total_frames == 160
    logged = {p.stem for p in tmp_path.rglob("*.csv")}
    assert {"collection_formation_success_rate", "collection_formation_collision_rate"} <= logged, sorted(logged)
