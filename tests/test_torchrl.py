"""TorchRL: the PettingZoo env through TorchRL's ``PettingZooWrapper`` passes ``check_env_specs``, its specs hold
every step info key (reset infos carry them), and a rollout's tensordict shows success and collision."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("torchrl", reason="TorchRL is not installed: pip install 'formation-env[torchrl]'")
import torch
from tensordict import TensorDictBase
from torchrl.envs.libs.pettingzoo import PettingZooWrapper
from torchrl.envs.utils import check_env_specs

from agents.policy import AnalyticPolicy
from formation_env import formation_v1
from formation_env.env.engine import INFO_KEYS

# TorchRL names the PettingZoo release it tests with (1.24.3); this env is checked here on the installed one.
pytestmark = pytest.mark.filterwarnings("ignore:PettingZoo in TorchRL is tested:UserWarning")


def wrap(scenario: str = "hold") -> PettingZooWrapper:
    """The parallel env in TorchRL, one group ``"leader"`` of all leaders, global state included."""
    return PettingZooWrapper(formation_v1.parallel_env(scenario=scenario), return_state=True, seed=0)


@pytest.mark.parametrize("scenario", ["hold", "narrow_passage"])
def test_check_env_specs_passes_with_the_info_keys(scenario: str) -> None:
    env = wrap(scenario)
    check_env_specs(env, seed=0)
    assert env.group_map == {"leader": ["leader_0", "leader_1", "leader_2"]}
    assert set(env.observation_spec["leader", "info"].keys()) == set(INFO_KEYS)
    assert "state" in env.observation_spec.keys()
    env.close()


def test_rollout_shows_success_and_collision() -> None:
    """The planner reaches the goal on ``hold`` (seed 0); the tensordict says so at the last step only."""
    env = wrap("hold")
    pz = env._env  # the wrapped PettingZoo env: the planner reads its engine state
    planner = AnalyticPolicy(pz)
    agents = env.group_map["leader"]

    def act(td: TensorDictBase) -> TensorDictBase:
        a = planner.act_parallel(dict.fromkeys(agents), pz)
        return td.set(("leader", "action"), torch.as_tensor(np.stack([a[k] for k in agents])))

    td = env.rollout(400, act, break_when_any_done=True)
    info = td["next", "leader", "info"]
    success, collision = info["success"].reshape(td.shape[0], -1), info["collision"].reshape(td.shape[0], -1)
    assert success[-1].all() and not success[:-1].any()
    assert not collision.any()
    assert td["next", "done"][-1].all() and td.shape[0] < 400
    env.close()
