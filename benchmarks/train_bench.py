"""Time to policy: end-to-end training speed of the shipped recipes, beside the PettingZoo route, in one run.

``python -m benchmarks.train_bench [--steps N] [--quick] [--recipes NAME ...] [--out FOLDER]`` (or
``formation-env bench --train``). Each recipe of ``train/configs/*.yaml`` trains through the same code path as
``python -m train.leaders --config RECIPE --timesteps N`` (:func:`train.leaders.parse_run`, then
:func:`train.leaders.train`, without the evaluation after it) and, beside them, SB3 PPO with the settings of the
peer recipe (``--peer-recipe``, default the shared-policy passage recipe: its hyperparameters, network, copies,
threads as ``train.leaders`` sets them, and the same ``VecNormalize(VecMonitor(...))`` stack) on MPE2
``simple_spread_v3`` (N = 3, continuous actions) through SuperSuit (``pettingzoo_env_to_vec_env_v1`` and
``concat_vec_envs_v1``, one shared policy over every agent: the route PettingZoo users take).

Per run: timesteps/s of ``learn`` with its updates, and the shares of its wall time spent in the env's step (the
outermost VecEnv's ``step_async`` and ``step_wait``: the env, its wrappers and normalisation), in the policy's
forward passes while collecting (``forward``, ``predict``, ``predict_values``), in the updates (``train()``), and
the rest (rollout buffer, callbacks, checkpoints, logging); the four sum to 1. :class:`TimeShares` is the
callback that times them. A run takes whole rollouts: the timesteps done are ``--steps`` rounded up to them. The
env's compiled step is built (or loaded from numba's disk cache) before the timer starts.

``--quick`` is the CI smoke: the recipes as ``train.leaders --smoke`` shrinks them (at most 1,024 timesteps and 4
copies, rollouts of 16 steps), the peer alike. Writes ``train_bench.md`` and ``train_bench.json`` into ``--out``.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from stable_baselines3.common.callbacks import BaseCallback

from .timing import machine

#: The recipes: every ``train/configs/*.yaml``.
CONFIGS = Path(__file__).resolve().parents[1] / "train" / "configs"
#: The recipe whose PPO settings the PettingZoo peer runs with (one policy shared by every agent, as SuperSuit).
PEER_RECIPE = "narrow_passage_ppo_shared"
#: The share keys of a row, in table order; they sum to 1.
SHARES = ("env_step", "policy_forward", "update", "other")

Row = dict[str, Any]


class TimeShares(BaseCallback):
    """Times a ``learn`` call: wall time, and the time in the env's step, the policy's forward passes while
    collecting, and the updates, by wrapping those methods for this model's objects while it learns (restored at
    the end; a call inside another timed call counts once).

    After ``learn``: ``wall`` (s), ``seconds`` {env_step, policy_forward, update} (s), ``timesteps`` (the model's
    ``num_timesteps`` over the call), ``slots`` (the VecEnv's ``num_envs``) and :meth:`shares`.
    """

    def __init__(self) -> None:
        super().__init__()
        self.seconds = {"env_step": 0.0, "policy_forward": 0.0, "update": 0.0}
        self.wall = 0.0
        self.timesteps = self.slots = 0
        self._depth = 0
        self._patched: list[tuple[type, str, Any]] = []
        self._t0 = self._n0 = 0.0

    def _wrap(self, owner: Any, method: str, key: str) -> None:
        """Time ``method`` of ``owner``'s class while learning (on the class, not the object: SB3's checkpoints
        pickle the model and the VecNormalize, which must not hold the timers)."""
        cls = type(owner)
        fn: Callable[..., Any] = getattr(cls, method)

        def timed(obj: Any, *args: Any, **kwargs: Any) -> Any:
            if self._depth or obj is not owner:
                return fn(obj, *args, **kwargs)
            self._depth += 1
            t0 = time.perf_counter()
            try:
                return fn(obj, *args, **kwargs)
            finally:
                self.seconds[key] += time.perf_counter() - t0
                self._depth -= 1

        self._patched.append((cls, method, cls.__dict__.get(method)))
        setattr(cls, method, timed)

    def _on_training_start(self) -> None:
        model = self.model
        self._wrap(model.env, "step_async", "env_step")
        self._wrap(model.env, "step_wait", "env_step")
        for method in ("forward", "predict", "predict_values"):
            if hasattr(model.policy, method):
                self._wrap(model.policy, method, "policy_forward")
        self._wrap(model, "train", "update")
        assert model.env is not None  # learn() set it
        self.slots = int(model.env.num_envs)
        self._n0 = model.num_timesteps
        self._t0 = time.perf_counter()

    def _on_step(self) -> bool:
        return True

    def _on_training_end(self) -> None:
        self.wall = time.perf_counter() - self._t0
        self.timesteps = int(self.model.num_timesteps - self._n0)
        for cls, method, own in reversed(self._patched):
            if own is None:
                delattr(cls, method)  # the inherited method shows through again
            else:
                setattr(cls, method, own)
        self._patched = []

    def shares(self) -> dict[str, float]:
        """The fraction of ``learn``'s wall time in each part, and ``other``: the rest (they sum to 1)."""
        if self.wall <= 0:
            raise RuntimeError("TimeShares.shares() before the end of learn()")
        out = {key: sec / self.wall for key, sec in self.seconds.items()}
        out["other"] = 1.0 - sum(out.values())
        return out


def _row(name: str, cfg: dict[str, Any], timer: TimeShares) -> Row:
    import numba
    import torch

    return {
        "run": name,
        "algo": cfg.get("algo", "ppo"),
        "mode": cfg.get("mode", "commander"),
        "scenario": cfg.get("scenario", "narrow_passage"),
        "slots": timer.slots,
        "timesteps": timer.timesteps,
        "wall_s": timer.wall,
        "steps_per_s": timer.timesteps / timer.wall,
        "shares": timer.shares(),
        "torch_threads_update": torch.get_num_threads(),  # after learn: the update's
        "numba_threads": numba.get_num_threads(),
    }


def _compile(cfg: dict[str, Any]) -> None:
    """Build (or load from the disk cache) the env's compiled step kernels of a recipe's training env, serial and
    threaded, so that numba's one-time compilation stays out of the timed ``learn``."""
    import numba
    import numpy as np

    from formation_env.env.versions import with_version
    from train.leaders import make_venv

    env_kwargs = with_version(int(cfg.get("env_version", 0)), dict(cfg.get("env_kwargs") or {}))
    venv = make_venv(cfg.get("mode", "commander"), cfg.get("scenario", "narrow_passage"), int(cfg.get("n_envs", 16)),
                     0, env_kwargs, float(cfg.get("residual", 0.0)), cfg.get("action_mode", "leaders"),
                     bool(cfg.get("central_critic", False)))  # fmt: skip
    venv.reset()
    act = np.zeros((venv.num_envs, *(venv.action_space.shape or ())), np.float32)
    threads = numba.get_num_threads()
    for n in {1, threads}:
        numba.set_num_threads(n)
        venv.step(act)
    numba.set_num_threads(threads)
    venv.close()


def bench_recipe(path: Path, steps: int, quick: bool, workdir: Path) -> Row:
    """Train recipe ``path`` for ``steps`` timesteps as ``python -m train.leaders --config path`` does."""
    from train.leaders import parse_run, train

    argv = ["--config", str(path), "--timesteps", str(steps), "--eval-episodes", "0", "--out", str(workdir)]
    cfg = parse_run([*argv, "--smoke"] if quick else argv)
    _compile(cfg)
    timer = TimeShares()
    train(**cfg, extra_callbacks=[timer], progress_bar=False)
    return _row(path.stem, cfg, timer)


def bench_peer(steps: int, quick: bool, recipe: Path, seed: int = 0) -> Row:
    """SB3 PPO with ``recipe``'s settings on MPE2 ``simple_spread_v3`` through SuperSuit, timed as the recipes."""
    import supersuit as ss
    from mpe2 import simple_spread_v3
    from stable_baselines3 import PPO
    from stable_baselines3.common.utils import set_random_seed
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

    from train.leaders import (
        ALGO_DEFAULTS,
        POLICY_DEFAULTS,
        SMOKE_OVERRIDES,
        load_config,
        sb3_schedules,
        set_threads,
        usable_cores,
    )

    cfg = load_config(recipe)
    if cfg.get("algo", "ppo") != "ppo":
        raise ValueError(f"the peer recipe must be a PPO recipe, {recipe} is {cfg['algo']!r}")
    hp: dict[str, Any] = {**ALGO_DEFAULTS["ppo"], **cfg.get("algo_kwargs", {})}
    n_envs = int(cfg.get("n_envs", 16))
    if quick:  # as train.leaders --smoke
        steps, n_envs = min(steps, 1024), min(n_envs, 4)
        hp.update(SMOKE_OVERRIDES["ppo"])
    pk = {**POLICY_DEFAULTS["ppo"], **cfg.get("policy_kwargs", {})}
    threads = int(cfg.get("threads") or usable_cores())  # as train.leaders: torch and numba on them
    set_threads(threads)
    env = ss.pettingzoo_env_to_vec_env_v1(simple_spread_v3.parallel_env(continuous_actions=True))
    raw = ss.concat_vec_envs_v1(env, n_envs, num_cpus=0, base_class="stable_baselines3")
    raw.venv.reset(seed=seed)  # SuperSuit's vec env has no seed(): seed its envs once, SB3 resets them unseeded
    venv = VecNormalize(VecMonitor(raw), norm_obs=True, norm_reward=True, clip_obs=10.0, gamma=0.99)
    hp["batch_size"] = min(int(hp["batch_size"]), int(hp["n_steps"]) * venv.num_envs)
    set_random_seed(seed)  # PPO(seed=...) would call the missing seed()
    args, schedule_callbacks = sb3_schedules(hp)  # the recipe's schedules, applied as train.leaders applies them
    model = PPO("MlpPolicy", venv, policy_kwargs=pk, device="cpu", verbose=0, **args)
    model.action_space.seed(seed)
    timer = TimeShares()
    model.learn(int(steps), callback=[timer, *schedule_callbacks])
    venv.close()
    peer = {"algo": "ppo", "mode": "shared", "scenario": "simple_spread"}
    row = _row("mpe2 simple_spread_v3 N=3 (SuperSuit)", peer, timer)
    row.update(settings_of=recipe.stem)
    return row


def recipes(names: Sequence[str] | None = None) -> list[Path]:
    """The recipe files named (stems of ``train/configs/*.yaml``), or all of them, sorted."""
    found = {p.stem: p for p in sorted(CONFIGS.glob("*.yaml"))}
    if not names:
        return list(found.values())
    unknown = [n for n in names if n not in found]
    if unknown:
        raise ValueError(f"--recipes: no recipe {unknown} in {CONFIGS}; there are {sorted(found)}")
    return [found[n] for n in names]


def markdown(rows: list[Row]) -> str:
    """One table: a row per run, steps/s with updates and the shares of the wall time."""
    out = [
        "| run | algo | mode | scenario | slots | timesteps | wall s | timesteps/s | env step | policy forward "
        "| update | other |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        if "skipped" in r:
            out.append(f"| {r['run']} | skipped: {r['skipped']} | | | | | | | | | | |")
            continue
        sh = " | ".join(f"{r['shares'][k]:.0%}" for k in SHARES)
        out.append(
            f"| {r['run']} | {r['algo']} | {r['mode']} | {r['scenario']} | {r['slots']} | {r['timesteps']:,} "
            f"| {r['wall_s']:.1f} | {r['steps_per_s']:,.0f} | {sh} |"
        )
    return "\n".join(out)


def run(steps: int, quick: bool, names: Sequence[str] | None = None, peer: str = PEER_RECIPE) -> list[Row]:
    """Every recipe named (all by default), then the PettingZoo peer with ``peer``'s settings."""
    rows: list[Row] = []
    with tempfile.TemporaryDirectory(prefix="train_bench_") as tmp:
        for path in recipes(names):
            print(f"[train] {path.stem} ...", file=sys.stderr, flush=True)
            rows.append(bench_recipe(path, steps, quick, Path(tmp) / path.stem))
    print("[train] mpe2 simple_spread_v3 through SuperSuit ...", file=sys.stderr, flush=True)
    try:
        rows.append(bench_peer(steps, quick, recipes([peer])[0]))
    except ImportError as exc:
        rows.append({"run": "mpe2 simple_spread_v3 (SuperSuit)", "skipped": f"{exc} (pip install -e '.[bench]')"})
    return rows


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.train_bench", description=__doc__.splitlines()[0])
    p.add_argument("--steps", type=int, default=50_000, help="timesteps per run (whole rollouts); default 50000")
    p.add_argument("--quick", action="store_true", help="CI smoke: the recipes as train.leaders --smoke runs them")
    p.add_argument("--recipes", nargs="*", default=None, help="recipe names (train/configs stems); default all")
    p.add_argument(
        "--peer-recipe", default=PEER_RECIPE, help=f"whose PPO settings the peer uses; default {PEER_RECIPE}"
    )
    p.add_argument("--out", default="out", help="folder of train_bench.md and train_bench.json (default out)")
    args = p.parse_args(argv)
    if args.steps < 1:
        p.error(f"--steps must be a positive integer, got {args.steps}")
    try:
        recipes(args.recipes)
        recipes([args.peer_recipe])
    except ValueError as exc:
        p.error(str(exc))
    out = Path(args.out)
    if out.suffix in (".md", ".json"):
        p.error(f"--out is a folder (train_bench.md and .json are written inside it), got {args.out!r}")
    rows = run(args.steps, args.quick, args.recipes, args.peer_recipe)
    stamp = dt.datetime.now(dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    command = "python -m benchmarks.train_bench " + " ".join(argv if argv is not None else sys.argv[1:])
    table = markdown(rows)
    print(table)
    out.mkdir(parents=True, exist_ok=True)
    head = f"# Time to policy\n\nMeasured {stamp} on {machine()} by `{command.strip()}`.\n\n"
    (out / "train_bench.md").write_text(head + (__doc__ or "").strip() + "\n\n" + table + "\n")
    meta = {"measured": stamp, "machine": machine(), "command": command.strip(), "steps": args.steps,
            "quick": args.quick}  # fmt: skip
    (out / "train_bench.json").write_text(json.dumps({**meta, "rows": rows}, indent=2))
    print(f"wrote {out / 'train_bench.md'} and {out / 'train_bench.json'}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
