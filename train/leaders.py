"""Train leader policies with Stable-Baselines3 (PPO or SAC), seeded and reproducible.

Modes:

* ``commander``: one policy commands every leader: observation = the global state
  (``Engine.global_state``, as ``FormationCommander-v0``), action = every leader's (n_l p,). Runs on the
  batched :class:`formation_env.env.vector.FormationVecEnv` (``mode="commander"``, ``--n-envs`` copies).
* ``shared``: decentralised leaders share one policy on their own observations: the batched
  :class:`formation_env.env.vector.FormationVecEnv` in ``shared`` mode (one slot per leader of each copy).

``--residual S`` (commander mode) learns a correction on top of the analytic planner:
action = clip(planner + S * policy, -1, 1) (the planner reads the engine state of each copy).

Outputs in ``--out`` (``<name>`` = ``<scenario>_<mode>``): ``<name>.zip``, ``<name>_vecnormalize.pkl``
and ``<name>_config.json`` side by side (what :class:`agents.policy.LearnedPolicy` loads),
``checkpoints/`` (CheckpointCallback), ``tb/`` (TensorBoard), ``curve.csv`` and ``curve.png``
(training curve: episode return and success rate against timesteps), ``eval.json``.

Reproducibility: the same ``--seed`` gives the same weights (torch on one thread; the vector env
seeds copy i with ``TRAIN_SEED_OFFSET`` + seed + i, away from the evaluation seeds; PPO/SAC seeded).
``--smoke``: a tiny run (train, save, load, evaluate
two episodes) for CI.

Example::

    python -m train.leaders --algo ppo --mode commander --scenario narrow_passage \\
        --timesteps 300000 --seed 0 --out runs/np_ppo
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import os
import re
import shlex
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any, cast

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback, CallbackList, CheckpointCallback
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper, VecMonitor, VecNormalize

from .recipes import json_object, load_recipe

__all__ = [
    "ALGO_DEFAULTS",
    "POLICY_DEFAULTS",
    "TRAIN_SEED_OFFSET",
    "RangeCurriculum",
    "ResidualVecEnv",
    "load_config",
    "main",
    "make_venv",
    "train",
]

#: Training episodes come from generators seeded TRAIN_SEED_OFFSET + seed + copy, disjoint from the
#: evaluation suite's episode seeds (0..999) and the planner's tuning seeds (10_000..).
TRAIN_SEED_OFFSET = 1_000_000


#: Hyperparameters of each algorithm unless a recipe (``train/configs/*.yaml``) or a flag sets them.
ALGO_DEFAULTS: dict[str, dict[str, Any]] = {
    "ppo": {
        "n_steps": 256,
        "batch_size": 256,
        "n_epochs": 5,
        "learning_rate": 3e-4,
        "gamma": 0.99,
        "gae_lambda": 0.95,
        "ent_coef": 0.0,
    },
    "sac": {"buffer_size": 100_000, "learning_starts": 2_000, "batch_size": 256, "train_freq": 1, "gradient_steps": 1},
}
#: SB3 ``policy_kwargs`` of each algorithm unless a recipe sets them.
POLICY_DEFAULTS: dict[str, dict[str, Any]] = {"ppo": {"net_arch": [64, 64]}, "sac": {"net_arch": [64, 64]}}
#: What ``--smoke`` shrinks.
SMOKE_OVERRIDES: dict[str, dict[str, Any]] = {
    "ppo": {"n_steps": 16, "n_epochs": 2},
    "sac": {"learning_starts": 64, "batch_size": 64},
}
#: The keys a recipe file may hold (the rest is refused, naming the key).
CONFIG_KEYS = (
    "algo", "mode", "scenario", "timesteps", "seed", "n_envs", "residual", "env_kwargs", "eval_episodes",
    "curriculum", "algo_kwargs", "policy_kwargs", "env_version", "range_curriculum", "action_mode", "central_critic",
    "checkpoints", "threads", "obs_norm", "reward_curriculum",
)  # fmt: skip
#: How the observations are normalised: SB3's running mean and deviation, or each entry's declared bounds mapped
#: onto [-1, 1] (:class:`agents.normalization.FixedMeanStd`; what a curriculum on episode draws needs).
OBS_NORMS = ("running", "bounds")


def usable_cores() -> int:
    """The CPU cores this process may run on (its affinity mask; ``os.cpu_count()`` where there is none)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not on Linux
        return os.cpu_count() or 1


def set_threads(threads: int) -> None:
    """Run torch and the env's compiled step (numba's worker threads) on ``threads`` threads each (numba's at most
    its pool, ``NUMBA_NUM_THREADS``)."""
    import numba
    import torch

    torch.set_num_threads(threads)
    numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))  # type: ignore[attr-defined]  # set at import


def machine() -> dict[str, Any]:
    """What a run's wall time was measured on: CPU model, cores usable, Python and the main packages' versions."""
    import platform
    from importlib.metadata import version

    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:  # pragma: no cover - not on Linux
        pass
    pkgs = {p: version(p) for p in ("torch", "numpy", "numba", "stable_baselines3")}
    return {"cpu": cpu, "cores": usable_cores(), "python": platform.python_version(), **pkgs}


def load_config(path: str | Path) -> dict[str, Any]:
    """A training recipe (YAML) as a dict of :func:`train` arguments; unknown keys raise ValueError."""
    cfg = load_recipe(path, CONFIG_KEYS)
    if "curriculum" in cfg and cfg["curriculum"] is not None:
        cfg["curriculum"] = tuple(float(v) for v in cfg["curriculum"])
    return cfg


class LinearSchedule:
    """A value shrinking linearly to 0 over training (``"lin_<value>"`` in a recipe, as in RL Zoo): SB3 calls it with
    the fraction of training left, 1 at the start and 0 at the end. SB3's own ``LinearSchedule(value, 0, 1)`` equals
    it only to rounding (a third of the updates differ in the last bit); this form trained the shipped policies.

    ``start`` (``"lin_<value>_from_<start>"``) holds the value constant over that fraction of training first and
    shrinks it linearly to 0 over the rest; ``start`` 0 is the plain linear schedule, bit for bit."""

    start: float = 0.0  # class default: models saved before ``start`` existed load unchanged

    def __init__(self, initial: float, start: float = 0.0) -> None:
        if not 0.0 <= start < 1.0:
            raise ValueError(f"start: the fraction of training before the decay must be in [0, 1), got {start}")
        self.initial = float(initial)
        self.start = float(start)

    def __call__(self, remaining: float) -> float:
        return min(1.0, remaining / (1.0 - self.start)) * self.initial


class AdaptiveLR:
    """A learning rate adapted to the policy's change at every update (``"kl_<initial>_<target>"`` in a recipe), as
    rsl_rl's adaptive schedule: after an update whose mean KL divergence between the old and new policy (SB3's
    ``approx_kl``, last epoch) exceeds 2 x ``target`` the rate is divided by 1.5, below ``target`` / 2 multiplied by
    1.5, kept in [``low``, ``high``]. :class:`KLAdaptation` applies it; SB3 calls it like any schedule.

    ``"kl_<initial>_<target>_from_<f>"``: adapted over the fraction ``f`` of training, then shrinking linearly to 0
    from the rate reached (no more adaptation), so that the last updates settle the policy."""

    low: float = 1e-5
    high: float = 1e-2

    def __init__(self, initial: float, target: float, anneal_from: float = 1.0) -> None:
        if not (initial > 0 and target > 0):
            raise ValueError(f"kl_<initial>_<target>: both must be > 0, got {initial}, {target}")
        if not 0.0 < anneal_from <= 1.0:
            raise ValueError(f"kl_<initial>_<target>_from_<f>: f must be in (0, 1], got {anneal_from}")
        self.value = float(initial)
        self.target = float(target)
        self.anneal_from = float(anneal_from)
        self._remaining = 1.0

    def __call__(self, remaining: float) -> float:
        self._remaining = remaining
        left = 1.0 - self.anneal_from  # the fraction of training that anneals
        return self.value if remaining >= left else self.value * remaining / left

    def adapt(self, kl: float) -> None:
        """Move the rate after an update whose mean KL divergence was ``kl`` (not once annealing has begun)."""
        if self._remaining < 1.0 - self.anneal_from:
            return
        if kl > 2.0 * self.target:
            self.value = max(self.value / 1.5, self.low)
        elif kl < 0.5 * self.target:
            self.value = min(self.value * 1.5, self.high)


class KLAdaptation(BaseCallback):
    """Feeds each update's ``train/approx_kl`` to the model's :class:`AdaptiveLR` before the next rollout."""

    def __init__(self, schedule: AdaptiveLR) -> None:
        super().__init__()
        self.schedule = schedule

    def _on_rollout_start(self) -> None:
        kl = self.model.logger.name_to_value.get("train/approx_kl")
        if kl is not None:
            self.schedule.adapt(float(kl))

    def _on_step(self) -> bool:
        return True


def training_done(model: Any) -> float:
    """The fraction of a ``learn`` call's timesteps an SB3 model has taken (its private ``_total_timesteps``, which
    ``learn`` sets; the schedule callbacks' tests would catch a rename)."""
    return float(model.num_timesteps) / float(model._total_timesteps)


class EntropySchedule(BaseCallback):
    """An entropy coefficient that follows a :class:`LinearSchedule` (``ent_coef: lin_<value>_from_<f>`` in a recipe:
    held over the fraction ``f`` of training, then shrinking linearly to 0). SB3's PPO takes a float, so this sets
    ``model.ent_coef`` before each update from the fraction of training left after the rollout, as SB3 computes it
    for its own schedules."""

    def __init__(self, schedule: LinearSchedule) -> None:
        super().__init__()
        self.schedule = schedule

    def _on_rollout_end(self) -> None:
        self.model.ent_coef = float(self.schedule(1.0 - training_done(self.model)))  # type: ignore[attr-defined]  # PPO's

    def _on_step(self) -> bool:
        return True


class ActionStdCap(BaseCallback):
    """A falling bound on PPO's action standard deviation (``action_std_cap: <final>_from_<f>`` in a recipe's
    ``algo_kwargs``, e.g. ``0.1_from_0.5``): over the first fraction ``f`` of training the policy's deviation is its
    own; from there the bound falls geometrically from the policy's largest deviation at ``f`` to ``final`` at the end,
    and before each rollout every entry of the policy's ``log_std`` above it is set to it. The saved policy's
    deviation is capped by ``final``.

    Why: every evaluation acts on the policy's mean action, which a policy trained with wide noise need not have
    learned to use well (the sampled team can be quicker and surer than its mean: ``python -m train.noise_gap``).
    SB3 has no such bound, and an entropy bonus falling to 0 shrinks the deviation only a little."""

    def __init__(self, final: float, start: float) -> None:
        super().__init__()
        if not final > 0.0:
            raise ValueError(f"action_std_cap: the final deviation must be > 0, got {final}")
        if not 0.0 <= start < 1.0:
            raise ValueError(f"action_std_cap: the fraction of training before the cap must be in [0, 1), got {start}")
        self.final, self.start = float(final), float(start)
        self.log_std0: float | None = None  # the policy's largest log deviation when the cap begins

    def cap(self, progress: float) -> float | None:
        """The bound on log_std at ``progress`` (the fraction of training done), None before the cap begins."""
        if progress < self.start or self.log_std0 is None:
            return None
        frac = min((progress - self.start) / (1.0 - self.start), 1.0)
        return min(self.log_std0, self.log_std0 + frac * (math.log(self.final) - self.log_std0))

    def _apply(self, progress: float) -> None:
        import torch

        log_std = cast(torch.nn.Parameter, self.model.policy.log_std)  # a Gaussian PPO policy's
        if progress >= self.start and self.log_std0 is None:
            self.log_std0 = float(log_std.detach().max())
        bound = self.cap(progress)
        if bound is not None:
            with torch.no_grad():
                log_std.clamp_(max=bound)

    def _on_rollout_start(self) -> None:
        self._apply(training_done(self.model))

    def _on_training_end(self) -> None:
        self._apply(1.0)

    def _on_step(self) -> bool:
        return True


_STD_CAP = re.compile(r"(?P<final>[^_]+)_from_(?P<start>[^_]+)")
_SCHEDULE = re.compile(r"lin_(?P<initial>[^_]+)(_from_(?P<start>[^_]+))?")
_ADAPTIVE = re.compile(r"kl_(?P<initial>[^_]+)_(?P<target>[^_]+)(_from_(?P<start>[^_]+))?")


def schedules(hp: dict[str, Any]) -> dict[str, Any]:
    """``hp`` with every ``"lin_<value>"`` or ``"lin_<value>_from_<start>"`` string (e.g. ``learning_rate: lin_3e-4``)
    as a :class:`LinearSchedule`; another string raises ValueError naming the key."""
    out = dict(hp)
    for key, val in hp.items():
        adaptive = _ADAPTIVE.fullmatch(val) if isinstance(val, str) and key == "learning_rate" else None
        if adaptive is not None:
            out[key] = AdaptiveLR(float(adaptive["initial"]), float(adaptive["target"]), float(adaptive["start"] or 1))
        elif isinstance(val, str):
            match = _SCHEDULE.fullmatch(val)
            try:
                if match is None:
                    raise ValueError
                out[key] = LinearSchedule(float(match["initial"]), float(match["start"] or 0.0))
            except ValueError:
                raise ValueError(
                    f"algo_kwargs[{key!r}]: a string must be 'lin_<number>' (linear to 0) or 'lin_<number>_from_<f>' "
                    f"(constant over the fraction f of training in [0, 1), then linear to 0), got {val!r} (YAML reads "
                    "3e-4 as a string: write 3.0e-4)"
                ) from None
    return out


def sb3_schedules(hp: dict[str, Any]) -> tuple[dict[str, Any], list[BaseCallback]]:
    """SB3's arguments for ``hp`` (:func:`schedules` applied) and the callbacks that apply what SB3 does not: the
    learning rate's adaptation to each update's KL divergence (:class:`KLAdaptation`), an entropy coefficient's
    schedule (:class:`EntropySchedule`; SB3 is given its first value) and a falling bound on the action deviation
    (``action_std_cap``, :class:`ActionStdCap`; not given to SB3)."""
    hp = dict(hp)
    cap = hp.pop("action_std_cap", None)
    out = schedules(hp)
    callbacks: list[BaseCallback] = []
    if cap is not None:
        match = _STD_CAP.fullmatch(cap) if isinstance(cap, str) else None
        try:
            if match is None:
                raise ValueError
            callbacks.append(ActionStdCap(float(match["final"]), float(match["start"])))
        except ValueError as exc:
            raise ValueError(
                f"algo_kwargs['action_std_cap'] must be '<final deviation>_from_<f>' (e.g. '0.1_from_0.5': from the "
                f"fraction f of training the action deviation's bound falls to 0.1), got {cap!r}"
                + (f": {exc}" if str(exc) else "")
            ) from None
    if isinstance(out.get("learning_rate"), AdaptiveLR):
        callbacks.append(KLAdaptation(out["learning_rate"]))
    if isinstance(out.get("ent_coef"), LinearSchedule):
        callbacks.append(EntropySchedule(out["ent_coef"]))
        out["ent_coef"] = float(out["ent_coef"](1.0))
    return out, callbacks


class ResidualVecEnv(VecEnvWrapper):
    """Commander actions as corrections of the analytic planner: a = clip(planner + scale * action, -1, 1).

    Wraps a :class:`FormationVecEnv` in ``commander`` mode (the planner reads its batched ``state``).
    """

    def __init__(self, venv: Any, scale: float) -> None:
        super().__init__(venv)
        from agents.planner import make_planner

        self.base = venv
        self.scale = float(scale)
        self.planner = make_planner(venv.engine.scenario_name)

    def reset(self) -> Any:
        return self.venv.reset()

    def step_async(self, actions: np.ndarray) -> None:
        eng = self.base.engine
        plan = self.planner(eng, self.base.state).reshape(self.base.n_envs, -1)
        self.venv.step_async(np.clip(plan + self.scale * np.asarray(actions), -1.0, 1.0))

    def step_wait(self) -> Any:
        return self.venv.step_wait()


def make_venv(
    mode: str,
    scenario: str,
    n_envs: int,
    seed: int,
    env_kwargs: dict[str, Any],
    residual: float = 0.0,
    action_mode: str = "leaders",
    central_critic: bool = False,
) -> VecEnv:
    """The raw (un-normalised) training VecEnv of ``mode``, seeded with ``seed`` (``central_critic``: shared
    slots see the global state after their own observation, :class:`agents.central_critic.LocalActorPolicy`)."""
    if action_mode != "leaders" and (mode != "commander" or residual > 0):
        raise ValueError(f"action_mode {action_mode!r} is for commander mode without --residual")
    if mode not in ("commander", "shared"):
        raise ValueError(f"mode must be 'commander' or 'shared', got {mode!r}")
    if residual > 0 and mode != "commander":
        raise ValueError("--residual is for commander mode only")
    if central_critic and mode != "shared":
        raise ValueError("--central-critic is for shared mode only")
    from formation_env.env.vector import FormationVecEnv

    venv: VecEnv = FormationVecEnv(
        scenario, num_envs=n_envs, mode=mode, seed=seed, action_mode=action_mode, critic_state=central_critic,
        **env_kwargs,
    )  # fmt: skip
    return ResidualVecEnv(venv, residual) if residual > 0 else venv


class CurveCallback(BaseCallback):
    """Records (timesteps, mean return, success rate, mean episode time) over finished episodes per rollout."""

    def __init__(self) -> None:
        super().__init__()
        self.rows: list[tuple[int, float, float, float]] = []
        self._ret: list[float] = []
        self._succ: list[float] = []
        self._time: list[float] = []

    def _on_step(self) -> bool:
        for info in self.locals.get("infos", []):
            ep = info.get("episode")
            if ep is not None:
                self._ret.append(float(ep["r"]))
                self._succ.append(float(info.get("success", False)))
                self._time.append(float(info.get("time", np.nan)))
        return True

    def _on_rollout_end(self) -> None:
        if self._ret:
            self.rows.append(
                (self.num_timesteps, float(np.mean(self._ret)), float(np.mean(self._succ)), float(np.mean(self._time)))
            )
            self.logger.record("rollout/success_rate", float(np.mean(self._succ)))
            self._ret, self._succ, self._time = [], [], []


class ToleranceCurriculum(BaseCallback):
    """A curriculum on the success test: the scenario's ``goal_tol`` and ``formation_tol`` start ``factor`` times
    their values and shrink linearly to them over the first ``fraction`` of the training timesteps (in the one
    engine of the ``FormationVecEnv``). Evaluation always uses the scenario's own test."""

    def __init__(self, engine: Any, factor: float, fraction: float, total: int) -> None:
        super().__init__()
        if not (factor >= 1.0 and 0.0 < fraction <= 1.0):
            raise ValueError(f"--curriculum needs FACTOR >= 1 and 0 < FRACTION <= 1, got {factor}, {fraction}")
        self.scenario = engine.scenario
        self.final = (self.scenario.goal_tol, self.scenario.formation_tol)
        self.factor, self.span = float(factor), max(1, int(fraction * total))

    def _scale(self) -> float:
        left = max(0.0, 1.0 - self.num_timesteps / self.span)
        return 1.0 + (self.factor - 1.0) * left

    def _on_step(self) -> bool:
        s = self._scale()
        self.scenario.goal_tol, self.scenario.formation_tol = self.final[0] * s, self.final[1] * s
        return True

    def _on_training_end(self) -> None:
        self.scenario.goal_tol, self.scenario.formation_tol = self.final


class _LinearSchedule(BaseCallback):
    """Values that start at ``start``, stay there until ``begin`` of the training timesteps (a fraction, default
    0) and move linearly to their final values until ``fraction`` of them (``_set(left)``: left = 1 at the start
    values, 0 at the final ones); the final values hold from then on and after training."""

    kind = "schedule"

    def __init__(self, engine: Any, start: dict[str, Any], fraction: float, total: int, begin: float = 0.0) -> None:
        super().__init__()
        if not 0.0 < fraction <= 1.0:
            raise ValueError(f"{self.kind}: fraction must be in (0, 1], got {fraction}")
        if not 0.0 <= begin < fraction:
            raise ValueError(f"{self.kind}: begin must be in [0, fraction) = [0, {fraction}), got {begin}")
        self.first = int(begin * total)
        self.span = max(1, int(fraction * total) - self.first)

    @classmethod
    def from_recipe(cls, engine: Any, recipe: dict[str, Any], total: int) -> _LinearSchedule:
        """From a recipe's mapping: ``start``, ``fraction`` and optionally ``begin``."""
        if set(recipe) - {"start", "fraction", "begin"} or not {"start", "fraction"} <= set(recipe):
            raise ValueError(f"{cls.kind}: give start, fraction and optionally begin, got {sorted(recipe)}")
        if not isinstance(recipe["start"], dict):
            raise ValueError(f"{cls.kind}: start must be a mapping, got {recipe['start']!r}")
        return cls(engine, recipe["start"], float(recipe["fraction"]), total, float(recipe.get("begin", 0.0)))

    def _set(self, left: float) -> None:
        raise NotImplementedError

    def _on_step(self) -> bool:
        self._set(min(1.0, max(0.0, 1.0 - (self.num_timesteps - self.first) / self.span)))
        return True

    def _on_training_end(self) -> None:
        self._set(0.0)


class RangeCurriculum(_LinearSchedule):
    """A curriculum on a scenario's episode draws: each named range (e.g. ``gap_width``) starts at the given
    (lo, hi), stays there until ``begin`` of the training timesteps (a fraction, default 0) and moves linearly
    to the scenario's own until ``fraction`` of them, in the one engine of the ``FormationVecEnv``. Evaluation
    always uses the scenario's own ranges.

    The global state's and observations' bounds stay the scenario's own: a parameter drawn outside them is
    seen clipped.
    """

    kind = "range curriculum"

    def __init__(
        self, engine: Any, start: dict[str, Sequence[float]], fraction: float, total: int, begin: float = 0.0
    ) -> None:
        super().__init__(engine, start, fraction, total, begin)
        self.scenario = sc = engine.scenario
        for key, rng in start.items():
            if not isinstance(getattr(sc, key, None), tuple) or len(rng) != 2:
                raise ValueError(f"range curriculum: {key!r} is not a (lo, hi) range of {sc.name!r}")
        self.final = {k: tuple(getattr(sc, k)) for k in start}
        self.start = {k: (float(v[0]), float(v[1])) for k, v in start.items()}

    def _set(self, left: float) -> None:
        for k, (a0, a1) in self.start.items():
            b0, b1 = self.final[k]
            setattr(self.scenario, k, (b0 + left * (a0 - b0), b1 + left * (a1 - b1)))
            self.scenario.__dict__.pop("_plan", None)  # the draws read the ranges when the plan is built


class RewardCurriculum(_LinearSchedule):
    """A curriculum on the reward: each named term's weight (e.g. ``collision``) starts at the given value,
    stays there until ``begin`` of the training timesteps and moves linearly to the run's own weight (its
    ``env_kwargs``' ``reward_weights`` over the scenario's) until ``fraction`` of them
    (:meth:`~formation_env.env.engine.Engine.set_reward_weights`, no recompilation). A term must be nonzero in
    the run's own weights, so that the compiled step computes it. Evaluation never sees the reward.
    """

    kind = "reward curriculum"

    def __init__(self, engine: Any, start: dict[str, float], fraction: float, total: int, begin: float = 0.0) -> None:
        super().__init__(engine, start, fraction, total, begin)
        self.engine = engine
        final = {k: engine.reward_weights.get(k, 0.0) for k in start}
        engine.set_reward_weights(start)  # the engine's checks; training's first step pays the start weights
        self.final = final
        self.start = {k: float(engine.reward_weights[k]) for k in start}

    def _set(self, left: float) -> None:
        self.engine.set_reward_weights({k: b + left * (self.start[k] - b) for k, b in self.final.items()})


def plot_curve(rows: Sequence[tuple[int, float, float, float]], path: Path, title: str) -> Path:
    """Training curve PNG: mean episode return, success rate and episode length (s) against timesteps.

    Thin lines are per rollout, thick ones a moving average over 20 rollouts.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    arr = np.array(rows, dtype=np.float64).reshape(-1, 4)
    fig, ax = plt.subplots(1, 3, figsize=(12, 3.2))
    labels = ("mean episode return", "success rate (training episodes)", "episode length (s)")
    w = min(20, max(len(arr), 1))
    for j, lab in enumerate(labels):
        y = arr[:, j + 1]
        ax[j].plot(arr[:, 0], y, lw=0.6, alpha=0.5)
        if len(y) >= w:
            ax[j].plot(arr[w - 1 :, 0], np.convolve(y, np.ones(w) / w, mode="valid"), lw=2)
        ax[j].set_xlabel("timesteps")
        ax[j].set_ylabel(lab)
    ax[1].set_ylim(-0.02, 1.02)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def train(
    algo: str = "ppo",
    mode: str = "commander",
    scenario: str = "narrow_passage",
    timesteps: int = 100_000,
    seed: int = 0,
    out: str | Path = "runs/leaders",
    *,
    smoke: bool = False,
    n_envs: int = 16,
    residual: float = 0.0,
    env_kwargs: dict[str, Any] | None = None,
    progress_bar: bool | None = None,
    eval_episodes: int | None = None,
    name: str | None = None,
    curriculum: tuple[float, float] | None = None,
    algo_kwargs: dict[str, Any] | None = None,
    policy_kwargs: dict[str, Any] | None = None,
    extra_callbacks: Sequence[BaseCallback] = (),
    config_file: str | None = None,
    env_version: int = 0,
    range_curriculum: dict[str, Any] | None = None,
    reward_curriculum: dict[str, Any] | None = None,
    action_mode: str = "leaders",
    central_critic: bool = False,
    checkpoints: int = 4,
    threads: int | None = None,
    command: str = "",
    obs_norm: str = "running",
) -> dict[str, Any]:
    """Train, save model + VecNormalize statistics + config, evaluate; returns the config (with results).

    Args:
        algo: ``"ppo"`` | ``"sac"``. mode: ``"commander"`` | ``"shared"``.
        timesteps: environment steps (slots x steps) to train.
        n_envs: environment copies (commander: slots; shared: copies x leaders slots).
        residual: > 0 learns a correction of scale ``residual`` on the analytic planner (commander).
        env_kwargs: engine arguments, e.g. ``{"reward_weights": {"distance": 0.2}}``.
        progress_bar: SB3's progress bar (None: only on a TTY and not in smoke runs).
        eval_episodes: evaluation episodes after training (default 2 for smoke, 50 otherwise; 0: none).
        curriculum: (factor, fraction): the success test's tolerances start ``factor`` times the scenario's and
            reach them after ``fraction`` of the timesteps (:class:`ToleranceCurriculum`).
        algo_kwargs: the algorithm's hyperparameters over :data:`ALGO_DEFAULTS` (e.g. ``n_steps``, ``gamma``).
        policy_kwargs: SB3 ``policy_kwargs`` over :data:`POLICY_DEFAULTS` (e.g. ``net_arch``, ``log_std_init``).
        extra_callbacks: SB3 callbacks run beside the run's own (e.g. ``benchmarks.train_bench``'s timers).
        config_file: the recipe file these came from (recorded in the saved config).
        range_curriculum: ``{"start": {range name: [lo, hi]}, "fraction": f, "begin": b}``: those episode draws
            start at the given ranges, stay there until ``b`` of the timesteps (optional, default 0) and reach the
            scenario's own after ``f`` of them (:class:`RangeCurriculum`).
        reward_curriculum: ``{"start": {term: weight}, "fraction": f, "begin": b}``: those reward weights start at
            the given values, stay there until ``b`` of the timesteps and reach the run's own after ``f`` of them
            (:class:`RewardCurriculum`).
        env_version: the env version whose defaults ``env_kwargs`` sit over (:mod:`formation_env.env.versions`;
            1 is ``formation_v1``).
        central_critic: (shared PPO) the critic reads the global state too, the actor only the leader's own
            observation (MAPPO's split, :class:`agents.central_critic.LocalActorPolicy`).
        checkpoints: how many checkpoints to save in ``checkpoints/``, evenly spaced over the run.
        threads: CPU threads of torch and of the env's compiled step (None: every core this process may use,
            :func:`usable_cores`); give each of several runs side by side its share.
        command: the command line that started the run (recorded in the config).
        obs_norm: ``"running"`` (SB3's running statistics) or ``"bounds"`` (each observation entry's declared
            bounds mapped onto [-1, 1], fixed for the whole run: :mod:`agents.normalization`).
    """
    threads = usable_cores() if threads is None else threads
    if isinstance(threads, bool) or not isinstance(threads, int) or threads < 1:
        raise ValueError(f"threads must be an integer >= 1, got {threads!r}")
    set_threads(threads)
    from stable_baselines3 import PPO, SAC

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    from formation_env.env.versions import with_version

    env_kwargs = with_version(env_version, dict(env_kwargs or {}))
    if smoke:
        timesteps = min(int(timesteps), 1024)
        n_envs = min(n_envs, 4)
    name = name or f"{scenario}_{mode}"
    t0 = time.time()
    if not isinstance(checkpoints, int) or checkpoints < 1:
        raise ValueError(f"checkpoints must be an integer >= 1, got {checkpoints!r}")
    if central_critic and algo != "ppo":
        raise ValueError("central_critic is for PPO only")
    if obs_norm not in OBS_NORMS:
        raise ValueError(f"obs_norm must be one of {OBS_NORMS}, got {obs_norm!r}")
    raw = make_venv(mode, scenario, n_envs, TRAIN_SEED_OFFSET + seed, env_kwargs, residual, action_mode, central_critic)
    base: Any = raw.venv if isinstance(raw, ResidualVecEnv) else raw  # the FormationVecEnv
    venv = VecNormalize(VecMonitor(raw), norm_obs=True, norm_reward=True, clip_obs=10.0, gamma=0.99)
    if obs_norm == "bounds":
        from gymnasium.spaces import Box

        from agents.normalization import FixedMeanStd

        space = venv.observation_space
        if not isinstance(space, Box):
            raise ValueError(f"obs_norm='bounds' needs a Box observation space, got {space}")
        venv.obs_rms = FixedMeanStd(space.low, space.high)  # type: ignore[assignment]  # a Box: one array of stats
    pk: dict[str, Any] = {**POLICY_DEFAULTS.get(algo, {}), **(policy_kwargs or {})}
    if algo == "ppo" and residual > 0:
        pk.setdefault("log_std_init", -1.0)
    if algo not in ALGO_DEFAULTS:
        raise ValueError(f"algo must be 'ppo' or 'sac', got {algo!r}")
    hp: dict[str, Any] = {**ALGO_DEFAULTS[algo], **(algo_kwargs or {})}
    if smoke:
        hp.update(SMOKE_OVERRIDES[algo])
    if algo == "ppo":
        hp["batch_size"] = min(int(hp["batch_size"]), int(hp["n_steps"]) * venv.num_envs)
    cls = PPO if algo == "ppo" else SAC
    if algo != "ppo" and str(hp.get("ent_coef", "")).startswith("lin_"):
        raise ValueError(
            f"algo_kwargs['ent_coef']: a schedule is for ppo only (SAC tunes its own), got {hp['ent_coef']!r}"
        )
    if algo != "ppo" and "action_std_cap" in hp:
        raise ValueError(
            f"algo_kwargs['action_std_cap'] is for ppo only (SAC tunes its own entropy), got {hp['action_std_cap']!r}"
        )
    hps, schedule_callbacks = sb3_schedules(hp)
    policy: Any = "MlpPolicy"
    if central_critic:
        from agents.central_critic import LocalActorPolicy

        policy, pk = LocalActorPolicy, {**pk, "actor_dim": base.engine.obs_dim}
    model: Any = cls(
        policy,
        venv,
        policy_kwargs=pk,
        seed=seed,
        device="cpu",
        tensorboard_log=str(out / "tb"),
        verbose=0,
        **hps,
    )
    curve = CurveCallback()
    ckpt = CheckpointCallback(
        save_freq=max(int(timesteps) // (checkpoints * venv.num_envs), 1),
        save_path=str(out / "checkpoints"),
        name_prefix=name,
        save_vecnormalize=True,
    )
    if progress_bar is None:
        progress_bar = sys.stdout.isatty() and not smoke
    callbacks: list[BaseCallback] = [curve, ckpt, *extra_callbacks]
    callbacks += schedule_callbacks
    if curriculum is not None:
        callbacks.append(ToleranceCurriculum(base.engine, *curriculum, int(timesteps)))
    if range_curriculum is not None:
        callbacks.append(RangeCurriculum.from_recipe(base.engine, range_curriculum, int(timesteps)))
    if reward_curriculum is not None:
        callbacks.append(RewardCurriculum.from_recipe(base.engine, reward_curriculum, int(timesteps)))
    model.learn(int(timesteps), callback=CallbackList(callbacks), progress_bar=progress_bar, tb_log_name=name)
    wall = time.time() - t0
    stem = out / name
    model.save(str(stem) + ".zip")
    venv.save(f"{stem}_vecnormalize.pkl")
    config: dict[str, Any] = {
        "name": f"{algo}_{mode}" + ("_residual" if residual > 0 else ""),
        "algo": algo,
        "mode": mode,
        "action_mode": action_mode,
        "central_critic": bool(central_critic),
        "scenario": scenario,
        "timesteps": int(timesteps),
        "seed": int(seed),
        "n_envs": int(n_envs),
        "residual": float(residual),
        "curriculum": None if curriculum is None else list(curriculum),
        "range_curriculum": range_curriculum,
        "reward_curriculum": reward_curriculum,
        "env_version": int(env_version),
        "env_kwargs": env_kwargs,
        "observation": "global_state" if mode == "commander" else "leader_observation",
        "wall_time_s": round(wall, 1),
        "command": command,
        "threads": threads,
        "machine": machine(),
        "algo_kwargs": hp,
        "sb3_policy_kwargs": pk,
        "config_file": config_file,
        "checkpoints": checkpoints,
        "obs_norm": obs_norm,
    }
    (out / f"{name}_config.json").write_text(json.dumps(config, indent=2))
    with open(out / "curve.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["timesteps", "mean_return", "success_rate", "mean_episode_time_s"])
        w.writerows(curve.rows)
    if curve.rows:
        plot_curve(curve.rows, out / "curve.png", f"{algo} {mode} {scenario}, seed {seed}")
    venv.close()
    from train.evaluate import evaluate

    n_eval = eval_episodes if eval_episodes is not None else (2 if smoke else 50)
    if n_eval == 0:
        return config
    res = evaluate(
        str(stem) + ".zip",
        scenario,
        n_eval,
        seed=0,
        gif=not smoke,
        generalisation=not smoke,
        out=None if smoke else out / "eval",
    )
    config["eval"] = {"episodes": n_eval, "metrics": res["metrics"]}
    (out / "eval.json").write_text(json.dumps(config["eval"], indent=2))
    return config


def _json_flag(parser: argparse.ArgumentParser, flag: str, text: str) -> dict[str, Any]:
    """The JSON object given to ``flag``; a usage error (exit 2) naming the flag otherwise."""
    try:
        return json_object(flag, text)
    except ValueError as exc:
        parser.error(str(exc))


def parse_run(argv: Sequence[str] | None = None, prog: str = "python -m train.leaders") -> dict[str, Any]:
    """The :func:`train` arguments of a command line: the recipe (``--config``), then the flags over it (``prog``
    names the command in help and errors). A bad flag is a usage error (SystemExit 2) naming it."""
    p = argparse.ArgumentParser(prog=prog, description=__doc__.splitlines()[0])
    p.add_argument("--config", default=None, help="a training recipe (YAML, train/configs/); flags override it")
    p.add_argument("--algo", choices=["ppo", "sac"], default=None, help="default ppo")
    p.add_argument("--mode", choices=["commander", "shared"], default=None, help="default commander")
    p.add_argument("--scenario", default=None, help="default narrow_passage")
    p.add_argument("--timesteps", type=int, default=None, help="default 100000")
    p.add_argument("--seed", type=int, default=None, help="default 0")
    p.add_argument("--out", default="runs/leaders")
    p.add_argument("--n-envs", type=int, default=None, help="default 16")
    p.add_argument("--residual", type=float, default=None, help="learn a correction of this scale on the planner")
    p.add_argument("--env-kwargs", default="", help='JSON engine arguments, e.g. {"reward_weights": {"distance": 0.2}}')
    p.add_argument("--algo-kwargs", default="", help='JSON hyperparameters over the recipe\'s, e.g. {"gamma": 0.995}')
    p.add_argument("--policy-kwargs", default="", help='JSON SB3 policy_kwargs, e.g. {"log_std_init": -1.0}')
    p.add_argument("--eval-episodes", type=int, default=None)
    p.add_argument(
        "--action-mode", choices=["leaders", "maneuver"], default=None,
        help="commander actions: every leader's input, or pose rates (formation_env.env.maneuver); default leaders",
    )  # fmt: skip
    p.add_argument(
        "--range-curriculum", default="", metavar="JSON",
        help='episode-draw curriculum over the recipe\'s, e.g. {"start": {"gap_width": [2.4, 3.0]}, "fraction": 0.5}; '
        '"begin": b holds the start ranges until b of training',
    )  # fmt: skip
    p.add_argument(
        "--reward-curriculum", default="", metavar="JSON",
        help='reward-weight curriculum over the recipe\'s, e.g. {"start": {"collision": 50.0}, "fraction": 0.5}: '
        "those weights move linearly to the run's own",
    )  # fmt: skip
    p.add_argument("--env-version", type=int, default=None, help="env version of the defaults (0, 1); default 0")
    p.add_argument(
        "--central-critic", action="store_true", default=None,
        help="shared PPO: the critic also reads the global state, the actor only the leader's observation (MAPPO)",
    )  # fmt: skip
    p.add_argument("--checkpoints", type=int, default=None, help="checkpoints saved over the run; default 4")
    p.add_argument(
        "--threads", type=int, default=None,
        help="CPU threads of torch and the env step; default every usable core (give runs side by side a share)",
    )  # fmt: skip
    p.add_argument(
        "--obs-norm", choices=list(OBS_NORMS), default=None,
        help="observation normalisation: SB3's running statistics, or each entry's declared bounds onto [-1, 1] "
        "(fixed; for curricula on episode draws); default running",
    )  # fmt: skip
    p.add_argument("--smoke", action="store_true", help="tiny end-to-end run for CI")
    p.add_argument(
        "--curriculum",
        default="",
        metavar="FACTOR:FRACTION",
        help="success-test tolerances from FACTOR times the scenario's down to them over FRACTION of training",
    )
    a = p.parse_args(argv)
    try:
        cfg: dict[str, Any] = load_config(a.config) if a.config else {}
    except (FileNotFoundError, ValueError) as exc:
        p.error(str(exc))
    keys = ("algo", "mode", "scenario", "timesteps", "seed", "n_envs", "residual", "eval_episodes", "env_version",
            "action_mode", "central_critic", "checkpoints", "threads", "obs_norm")  # fmt: skip
    for key in keys:
        if getattr(a, key) is not None:
            cfg[key] = getattr(a, key)
    if a.env_kwargs:
        cfg["env_kwargs"] = {**cfg.get("env_kwargs", {}), **_json_flag(p, "--env-kwargs", a.env_kwargs)}
    if a.algo_kwargs:
        cfg["algo_kwargs"] = {**cfg.get("algo_kwargs", {}), **_json_flag(p, "--algo-kwargs", a.algo_kwargs)}
    if a.policy_kwargs:
        cfg["policy_kwargs"] = {**cfg.get("policy_kwargs", {}), **_json_flag(p, "--policy-kwargs", a.policy_kwargs)}
    if a.range_curriculum:
        cfg["range_curriculum"] = _json_flag(p, "--range-curriculum", a.range_curriculum)
    if a.reward_curriculum:
        cfg["reward_curriculum"] = _json_flag(p, "--reward-curriculum", a.reward_curriculum)
    if a.curriculum:
        cur = tuple(float(v) for v in a.curriculum.split(":"))
        if len(cur) != 2:
            p.error(f"--curriculum must be FACTOR:FRACTION, got {a.curriculum!r}")
        cfg["curriculum"] = cur
    command = shlex.join(["python", "-m", "train.leaders", *(sys.argv[1:] if argv is None else argv)])
    return {**cfg, "out": a.out, "smoke": a.smoke, "config_file": a.config, "command": command}


def main(argv: Sequence[str] | None = None, prog: str = "python -m train.leaders") -> int:
    """Parse the flags (``formation-env train`` runs this too, with its own ``prog``), train, and print the run's
    name, wall time and evaluation as JSON."""
    config = train(**parse_run(argv, prog))
    print(json.dumps({k: config[k] for k in ("name", "wall_time_s", "eval") if k in config}, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
