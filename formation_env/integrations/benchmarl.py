"""The formation env as a BenchMARL task (benchmarl 1.5, torchrl 0.10-0.11; extra ``benchmarl``).

* :class:`FormationTask`: one task per scenario (``FormationTask.NARROW_PASSAGE``, ``FormationTask.HOLD``, ...).
  ``FormationTask.NARROW_PASSAGE.get_task(config)`` gives its :class:`FormationTaskClass` with ``config`` the env
  arguments; ``get_from_yaml(path)`` reads them from a YAML file; without a path it reads
  :data:`DEFAULT_CONFIG` (``formation_env/integrations/benchmarl_task.yaml``).
* :class:`FormationTaskClass`: the PettingZoo parallel env through TorchRL's ``PettingZooWrapper``: one group
  ``"leader"`` of all leaders, continuous actions in [-1, 1], the global state for centralised critics
  (MAPPO, MASAC, QMIX-like mixers), every step info key in the specs, and success and collision rates of the
  episodes that ended in a batch logged as ``collection/formation/success_rate`` and ``.../collision_rate``.

Example (MAPPO; ``docs/benchmarl.md``)::

    from benchmarl.algorithms import MappoConfig
    from benchmarl.experiment import Experiment, ExperimentConfig
    from benchmarl.models.mlp import MlpConfig
    from formation_env.integrations.benchmarl import FormationTask

    task = FormationTask.NARROW_PASSAGE.get_from_yaml()
    Experiment(task=task, algorithm_config=MappoConfig.get_from_yaml(), model_config=MlpConfig.get_from_yaml(),
               critic_model_config=MlpConfig.get_from_yaml(), seed=0,
               config=ExperimentConfig.get_from_yaml()).run()
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from pathlib import Path
from typing import Any

from formation_env._extras import require

require("benchmarl", "benchmarl", "formation_env.integrations.benchmarl")

import torch  # noqa: E402
from benchmarl.environments.common import Task, _read_yaml_config  # noqa: E402
from benchmarl.environments.pettingzoo.common import PettingZooClass  # noqa: E402
from tensordict import TensorDictBase  # noqa: E402
from torchrl.envs import EnvBase, PettingZooWrapper  # noqa: E402

from formation_env.env.formation import FormationEnv  # noqa: E402
from formation_env.env.versions import with_version  # noqa: E402

__all__ = ["DEFAULT_CONFIG", "FormationTask", "FormationTaskClass"]

#: The task configuration shipped with the package: env arguments over the scenario's (``env_version`` 1).
DEFAULT_CONFIG = Path(__file__).with_name("benchmarl_task.yaml")


class FormationTaskClass(PettingZooClass):
    """A scenario of the formation env in BenchMARL; ``config``: ``{"env_version": 0 | 1, **FormationEnv
    keyword arguments}`` (the scenario comes from the task's name)."""

    def _env(self, render: bool = True) -> FormationEnv:
        kw = copy.deepcopy(dict(self.config))
        version = int(kw.pop("env_version", 1))
        kw = with_version(version, {"scenario": self.name.lower(), **kw})
        return FormationEnv(render_mode="rgb_array" if render else None, **kw)

    def get_env_fun(
        self, num_envs: int, continuous_actions: bool, seed: int | None, device: Any
    ) -> Callable[[], EnvBase]:
        """A maker of one TorchRL env (BenchMARL batches it with ``SerialEnv`` or ``ParallelEnv``)."""
        return lambda: PettingZooWrapper(self._env(), return_state=True, seed=seed, device=device)

    def supports_continuous_actions(self) -> bool:
        return True

    def supports_discrete_actions(self) -> bool:
        return False

    def has_state(self) -> bool:
        return True

    def max_steps(self, env: EnvBase) -> int:
        """Samples per episode (``max_cycles``)."""
        return int(self._env(render=False).max_cycles)

    @staticmethod
    def log_info(batch: TensorDictBase) -> dict[str, float]:
        """Success and collision rates over the episodes that ended in ``batch`` (none ended: nothing logged)."""
        done = batch.get(("next", "done"), None)
        if done is None:
            return {}
        ended = done.reshape(*done.shape[: batch.ndim], -1).any(-1)
        if not bool(ended.any()):
            return {}
        out: dict[str, float] = {}
        nxt = batch.get("next")
        for group in nxt.keys():
            sub = nxt.get(group)
            info = sub.get("info", None) if isinstance(sub, TensorDictBase) else None
            if not isinstance(info, TensorDictBase) or "success" not in info.keys():
                continue
            for key in ("success", "collision"):
                v = info.get(key).reshape(*ended.shape, -1)[..., 0]  # the team's: every leader reports the same
                out[f"collection/formation/{key}_rate"] = float(v[ended].to(torch.float32).mean())
        return out

    @staticmethod
    def env_name() -> str:
        return "formation_env"


class FormationTask(Task):
    """The formation env's scenarios as BenchMARL tasks."""

    HOLD = None
    MANEUVER = None
    NARROW_PASSAGE = None
    OBSTACLE_FIELD = None
    MOVING_OBSTACLES = None

    @staticmethod
    def associated_class() -> type[FormationTaskClass]:
        return FormationTaskClass

    def get_from_yaml(self, path: str | None = None) -> FormationTaskClass:
        """The task with the env arguments of the YAML file at ``path`` (default :data:`DEFAULT_CONFIG`)."""
        return self.get_task(config=_read_yaml_config(str(path or DEFAULT_CONFIG)))
