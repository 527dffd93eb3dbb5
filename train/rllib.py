"""Train the shared leader policy with RLlib's PPO on a local Ray or a cluster: ``python -m train.rllib``.

Every leader acts on its own observation with one shared policy (``"shared"``); the followers run their law
inside the env. The env is :class:`formation_env.integrations.rllib.FormationMultiAgentEnv` (fixed agent
order, truncation, ``state()``), and :class:`~formation_env.integrations.rllib.FormationMetrics` puts success,
collision, time to goal and formation error into RLlib's metrics.

Examples::

    python -m train.rllib --smoke --seed 0                     # a tiny run; last line: one JSON object
    python -m train.rllib --scenario hold --iterations 200 --num-env-runners 2 --out runs/rllib_hold
    python -m train.rllib --address auto --num-env-runners 32  # on a running Ray cluster

Outputs in ``--out``: ``checkpoint/`` (``Algorithm.save_to_path``; ``formation-env evaluate --policy
<out>/checkpoint`` evaluates it), ``config.json`` (everything needed to rebuild the env) and ``metrics.json``.
With ``--num-env-runners 0`` (the default of ``--smoke``) sampling runs in the driver and the same seed gives the
same metrics in every process (the script runs itself with ``PYTHONHASHSEED=0``: RLlib iterates sets of
ids); with remote runners the order in which their samples arrive can change a run.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import sys
import time
from pathlib import Path
from typing import Any

from .recipes import json_object, load_recipe

#: PPO settings over RLlib's defaults (a recipe's ``algo_kwargs`` and the flags override them).
PPO_DEFAULTS: dict[str, Any] = {
    "lr": 3e-4,
    "gamma": 0.995,
    "lambda_": 0.95,
    "train_batch_size_per_learner": 4000,
    "minibatch_size": 256,
    "num_epochs": 5,
    "entropy_coeff": 0.0,
}
SMOKE: dict[str, Any] = {"train_batch_size_per_learner": 200, "minibatch_size": 100, "num_epochs": 1}
#: Keys a YAML recipe (``--config``) may hold.
CONFIG_KEYS = ("scenario", "env_version", "env_kwargs", "iterations", "num_env_runners", "algo_kwargs", "hidden")


def build_config(
    scenario: str, seed: int, num_env_runners: int, env_kwargs: dict[str, Any], algo_kwargs: dict[str, Any],
    hidden: list[int], env_version: int = 1,
) -> Any:  # fmt: skip
    """The ``PPOConfig`` of the shared leader policy."""
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.core.rl_module.multi_rl_module import MultiRLModuleSpec
    from ray.rllib.core.rl_module.rl_module import RLModuleSpec

    from formation_env.integrations.rllib import FormationMetrics, register

    env_config = {"scenario": scenario, "env_version": env_version, **env_kwargs}
    return (
        PPOConfig()
        .environment(register(), env_config=env_config)
        .multi_agent(policies={"shared"}, policy_mapping_fn=lambda agent_id, episode, **kw: "shared")
        .rl_module(
            rl_module_spec=MultiRLModuleSpec(
                rl_module_specs={"shared": RLModuleSpec(model_config={"fcnet_hiddens": list(hidden)})}
            )
        )
        .env_runners(num_env_runners=num_env_runners, num_envs_per_env_runner=1, rollout_fragment_length="auto")
        .learners(num_learners=0)
        .training(**{**PPO_DEFAULTS, **algo_kwargs})
        .callbacks(FormationMetrics)
        .debugging(seed=seed)
    )


def metrics_of(result: dict[str, Any]) -> dict[str, Any]:
    """The formation metrics, mean return and timesteps of one ``Algorithm.train()`` result."""
    runners = result.get("env_runners", {})
    form = runners.get("formation", {})
    out: dict[str, Any] = {k: (None if form.get(k) is None else float(form[k])) for k in
                           ("success_rate", "collision_rate", "time_to_goal", "formation_error")}  # fmt: skip
    ret = runners.get("episode_return_mean")
    out["episode_return_mean"] = None if ret is None else float(ret)
    key = "num_env_steps_sampled_lifetime"
    out["env_steps"] = int(result.get(key, runners.get(key, 0)))
    return out


def main(argv: list[str] | None = None) -> dict[str, Any]:
    ap = argparse.ArgumentParser(prog="python -m train.rllib", description=__doc__.splitlines()[0],
                                 formatter_class=argparse.ArgumentDefaultsHelpFormatter)  # fmt: skip
    ap.add_argument("--config", help="a YAML recipe (keys: " + ", ".join(CONFIG_KEYS) + "); flags override it")
    ap.add_argument("--scenario", default=None, help="scenario name (default narrow_passage)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--iterations", type=int, default=None, help="Algorithm.train() calls (default 100; smoke 2)")
    ap.add_argument("--num-env-runners", type=int, default=None, help="remote env runners (default 0: the driver)")
    ap.add_argument("--address", default=None, help="Ray cluster address (default: start a local Ray)")
    ap.add_argument("--env-kwargs", default=None, help='JSON env arguments, e.g. {"dt": 0.05}')
    ap.add_argument("--out", default="runs/rllib", help="output folder")
    ap.add_argument("--smoke", action="store_true", help="a tiny run; prints one JSON object of metrics last")
    args = ap.parse_args(argv)
    cfg: dict[str, Any] = {}
    if args.config:
        try:
            cfg = load_recipe(args.config, CONFIG_KEYS)
        except (OSError, ValueError) as exc:
            ap.error(str(exc))
    scenario = args.scenario or cfg.get("scenario", "narrow_passage")
    env_kwargs = dict(cfg.get("env_kwargs") or {})
    if args.env_kwargs:
        try:
            env_kwargs.update(json_object("--env-kwargs", args.env_kwargs))
        except ValueError as exc:
            ap.error(str(exc))
    iterations = args.iterations if args.iterations is not None else (2 if args.smoke else cfg.get("iterations", 100))
    runners = args.num_env_runners if args.num_env_runners is not None else int(cfg.get("num_env_runners", 0))
    if iterations < 1 or runners < 0:
        ap.error(f"--iterations must be >= 1 and --num-env-runners >= 0, got {iterations}, {runners}")
    algo_kwargs = {**dict(cfg.get("algo_kwargs") or {}), **(SMOKE if args.smoke else {})}
    hidden = list(cfg.get("hidden", [16, 16] if args.smoke else [64, 64]))
    env_version = int(cfg.get("env_version", 1))

    import ray

    ray.init(address=args.address, include_dashboard=False, log_to_driver=False, logging_level=logging.ERROR)
    t0 = time.time()
    algo = build_config(scenario, args.seed, runners, env_kwargs, algo_kwargs, hidden, env_version).build_algo()
    history = []
    for i in range(iterations):
        m = metrics_of(algo.train())
        history.append(m)
        if not args.smoke:
            print(json.dumps({"iteration": i + 1, **m}), flush=True)
    wall = time.time() - t0
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    algo.save_to_path(str((out / "checkpoint").resolve()))
    algo.stop()
    ray.shutdown()
    record = {"scenario": scenario, "env_version": env_version, "env_kwargs": env_kwargs, "seed": args.seed,
              "iterations": iterations, "num_env_runners": runners, "hidden": hidden, "algo_kwargs": algo_kwargs,
              "wall_time_s": round(wall, 1), "command": "python -m train.rllib " + " ".join(sys.argv[1:])}  # fmt: skip
    (out / "config.json").write_text(json.dumps(record, indent=2))
    final = {**history[-1], "iterations": iterations, "steps_per_s": history[-1]["env_steps"] / max(wall, 1e-9)}
    (out / "metrics.json").write_text(json.dumps({"final": final, "history": history}, indent=2))
    shown = {k: v for k, v in final.items() if not (args.smoke and k == "steps_per_s")}  # wall-clock rates vary
    print(json.dumps(shown))
    return final


if __name__ == "__main__":
    if os.environ.get("PYTHONHASHSEED") != "0":
        # RLlib iterates sets of agent and module ids: with Python's per-process string hashing their order, and
        # with it a run, changes from process to process. Run again with hashing fixed (Ray's workers inherit it).
        os.execve(sys.executable, [sys.executable, "-m", "train.rllib", *sys.argv[1:]],
                  {**os.environ, "PYTHONHASHSEED": "0"})  # fmt: skip
    main()
