"""The formation env in RLlib's multi-agent API (ray 2.50+, new API stack); extra ``rllib``.

* :class:`FormationMultiAgentEnv`: the PettingZoo parallel env (``formation_v0`` or ``v1``) as an RLlib
  ``MultiAgentEnv``. Agents come in a fixed order (``leader_0``, ``leader_1``, ...; RLlib's own
  ``ParallelPettingZooEnv`` builds them from a set, so their order, and with it a run, changes from process to
  process), every agent has its own space entry, truncation is reported as such (``"__all__"`` keys), and
  :meth:`~FormationMultiAgentEnv.state` gives the global state for a centralised critic.
* :class:`FormationMetrics`: an RLlib callback that logs each finished episode's success, collision, time to goal
  (successful episodes) and formation error under ``env_runners/formation/...`` (window of 100 episodes).
* :func:`register`: ``tune.register_env(ENV_NAME, ...)``, so that configs can say ``.environment(ENV_NAME)``.

``python -m train.rllib`` trains the shared leader policy with PPO on it (``docs/rllib.md``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from formation_env._extras import require

require("ray", "rllib", "formation_env.integrations.rllib")

from ray.rllib.callbacks.callbacks import RLlibCallback  # noqa: E402
from ray.rllib.env.multi_agent_env import MultiAgentEnv  # noqa: E402

from formation_env.env.formation import FormationEnv  # noqa: E402
from formation_env.env.versions import with_version  # noqa: E402

__all__ = ["ENV_NAME", "METRICS", "FormationMetrics", "FormationMultiAgentEnv", "register"]

#: The name :func:`register` gives the env in RLlib's registry.
ENV_NAME = "formation_env"
#: The episode metrics :class:`FormationMetrics` logs (keys under ``env_runners/formation/``).
METRICS = ("success_rate", "collision_rate", "time_to_goal", "formation_error")


class FormationMultiAgentEnv(MultiAgentEnv):
    """The parallel env for RLlib: one agent per leader, followers inside.

    Args:
        config: ``{"env_version": 0 | 1 (default 1), **FormationEnv keyword arguments}``, e.g.
            ``{"scenario": "narrow_passage", "env_version": 1, "dt": 0.1}`` (RLlib's ``env_config``).
    """

    def __init__(self, config: dict[str, Any] | None = None) -> None:
        super().__init__()
        kw = dict(config or {})
        version = int(kw.pop("env_version", 1))
        self.par_env = FormationEnv(**with_version(version, kw))
        self.agents = self.possible_agents = list(self.par_env.possible_agents)
        self.observation_spaces = dict[Any, Any](self.par_env.observation_spaces)  # agent -> Box, RLlib's key type
        self.action_spaces = dict[Any, Any](self.par_env.action_spaces)

    @property
    def engine(self) -> Any:
        """The env's :class:`~formation_env.env.engine.Engine`."""
        return self.par_env.engine

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[dict, dict]:
        obs, infos = self.par_env.reset(seed=seed, options=options)
        self.agents = list(self.possible_agents)
        return obs, infos

    # RLlib's multi-agent step returns a dict per agent (and "__all__") where gymnasium.Env declares one agent's values
    def step(self, action_dict: dict[Any, Any]) -> tuple[dict, dict, dict, dict, dict]:  # type: ignore[override]
        obs, rew, term, trunc, infos = self.par_env.step(action_dict)
        term = {**term, "__all__": all(term.values())}
        trunc = {**trunc, "__all__": all(trunc.values())}
        if term["__all__"] or trunc["__all__"]:
            self.agents = []
        return obs, rew, term, trunc, infos

    def state(self) -> np.ndarray:
        """The global state (``FormationEnv.state()``, float32 (state_dim,)): for a centralised critic."""
        return self.par_env.state()


class FormationMetrics(RLlibCallback):
    """Logs success, collision, time to goal and formation error of every finished episode (any agent's last
    info: they are the team's)."""

    def on_episode_end(self, *, episode: Any, metrics_logger: Any = None, **kwargs: Any) -> None:
        if metrics_logger is None:
            return
        infos = episode.get_infos(-1)
        info = next((v for v in infos.values() if v), None)
        if info is None:
            return
        log = lambda key, val: metrics_logger.log_value(("formation", key), float(val), reduce="mean", window=100)  # noqa: E731
        log("success_rate", info["success"])
        log("collision_rate", info["collision"])
        log("formation_error", info["formation_error"])
        if info["success"]:
            log("time_to_goal", info["time"])


def register() -> str:
    """Register :class:`FormationMultiAgentEnv` in RLlib's registry as :data:`ENV_NAME`; returns the name."""
    from ray.tune.registry import register_env

    register_env(ENV_NAME, FormationMultiAgentEnv)
    return ENV_NAME
