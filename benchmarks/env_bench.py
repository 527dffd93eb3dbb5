"""Env speed against its peers, each as a ratio measured side by side in one run (the speed guards against regressions).

* (a) PettingZoo parallel step: ``formation_v0`` on ``narrow_passage`` (5 agents: 3 leaders, 2 followers
  inside, double integrators, walls and 16 rays per leader) against MPE2 ``simple_spread_v3`` (N = 3,
  continuous actions), both through the parallel API with dict actions, resets included. Guard >= 5x.
* (b) Batched: ``FormationVecEnv`` at B = 1024 through SB3's ``VecEnv`` API with its per-slot info dicts, on a
  10-agent framework (3 leaders, 7 followers, complete graph) in shared mode, auto-resets included, against
  VMAS ``simple_spread`` with 10 agents on CPU at the same B (torch's default threads). Guard >= 7x.
* (c) SB3 PPO end to end (``learn``) on the commander env (``FormationCommander-v0``, narrow passage) against
  ``Pendulum-v1`` with the same PPO settings, one env each, in a fresh process. No guard: time to a trained
  policy is what users feel, and ``formation-env bench --train`` measures it.
* (d) The env on ``trilateration(10_000, 2)``: step time and peak RSS in a fresh process. Floors <= 10 ms and
  <= 500 MB.
* (e) ``moving_obstacles`` step against ``obstacle_field`` step (PettingZoo, B = 1). Floor: at most 2x the time.
* (f) ``gym.make_vec("formation_env/NarrowPassage-v1", num_envs=64)``: the batched env (its
  ``vector_entry_point``, the default) against ``vectorization_mode="sync"`` (Gymnasium's ``SyncVectorEnv`` of 64
  single envs), both ``NEXT_STEP`` auto-reset with 20-step episodes so that resets are part of the time; and the
  batched env on one numba thread (from B = 64 its step runs on numba's threads, which lose much when the cores
  are shared). No floor.

Each comparison alternates ours and the peer turn by turn (A B, B A, ...); ratios are of medians, with the
min-max of the per-turn ratios. Peers come from the optional extra ``bench`` (``pip install -e ".[bench]"``).
"""

from __future__ import annotations

import contextlib
import importlib.util
import json
import math
import os
import statistics
import subprocess
import sys
import time
from collections.abc import Callable
from typing import Any

import numpy as np

TITLE = "Env step: PettingZoo vs MPE2, batched vs VMAS, PPO throughput, large swarms, moving obstacles"

Row = dict[str, Any]

PPO_SETTINGS: dict[str, Any] = {"batch_size": 64, "n_epochs": 4, "device": "cpu", "seed": 0, "verbose": 0}


# ---------------------------------------------------------------------------- helpers
def _have(mod: str) -> bool:
    return importlib.util.find_spec(mod) is not None


def _rates(
    fns: dict[str, Callable[[], None]],
    items: dict[str, float],
    calls: int,
    repeat: int,
    warmup: bool = True,
    turn_s: float = 0.0,
) -> dict[str, list[float]]:
    """Items/s of each fn per repeat (a turn of at least ``calls`` calls a repeat), the fns taking turns repeat by
    repeat.

    The order alternates (A B, B A, ...) so that a drift in machine load hits both alike. With ``turn_s`` > 0, a
    fn's turn has as many calls as fill about ``turn_s`` seconds (timed on three warm-up calls), so that the cost
    of a switch (caches refilled, the other library's OpenMP threads still spinning) weighs alike on every fn.
    """
    out: dict[str, list[float]] = {k: [] for k in fns}
    turns = dict.fromkeys(fns, calls)
    if warmup:
        for name, fn in fns.items():
            t0 = time.perf_counter()
            for _ in range(3 if turn_s > 0 else 1):
                fn()
            if turn_s > 0:
                turns[name] = max(calls, math.ceil(turn_s * 3 / (time.perf_counter() - t0)))
    names = list(fns)
    for rep in range(repeat):
        for name in names if rep % 2 == 0 else names[::-1]:
            fn, n = fns[name], turns[name]
            t0 = time.perf_counter()
            for _ in range(n):
                fn()
            out[name].append(items[name] * n / (time.perf_counter() - t0))
    return out


def _row(section: str, case: str, unit: str, rates: list[float], **extra: Any) -> Row:
    return {
        "section": section,
        "case": case,
        "unit": unit,
        "median": statistics.median(rates),
        "min": min(rates),
        "max": max(rates),
        **extra,
    }


def _ratio(ours: list[float], theirs: list[float]) -> tuple[float, float, float]:
    r = [a / b for a, b in zip(ours, theirs, strict=True)]
    return statistics.median(r), min(r), max(r)


def _compare_rows(
    section: str, rates: dict[str, list[float]], ours: str, unit: str, target: float | None, labels: dict[str, str]
) -> list[Row]:
    """A row for ``ours`` and one per peer with the ratio ours / peer (and the target, if there is one)."""
    rows = [_row(section, labels[ours], unit, rates[ours])]
    for name, r in rates.items():
        if name == ours:
            continue
        med, lo, hi = _ratio(rates[ours], r)
        goal = {} if target is None else {"target": target, "met": med >= target}
        rows.append(_row(section, labels[name], unit, r, ratio=med, ratio_min=lo, ratio_max=hi, **goal))
    return rows


def _skip(section: str, what: str, why: str) -> Row:
    print(f"[env] {section}: skipped {what}: {why}", file=sys.stderr)
    return {"section": section, "case": what, "skipped": why}


def _ten_agent_framework() -> Any:
    """10 agents in 2D: 3 leaders spanning the plane, 7 followers, complete graph (Gram stress)."""
    from formation_env.core.framework import Framework

    rng = np.random.default_rng(0)
    leaders = np.array([[1.0, 0.0], [-0.5, 0.9], [-0.5, -0.9]])
    ang = np.linspace(0, 2 * np.pi, 8)[:-1] + 0.3
    followers = np.stack([np.cos(ang), np.sin(ang)], 1) * 0.5 + rng.normal(scale=0.02, size=(7, 2))
    r = np.concatenate([leaders, followers]) * 1.2
    edges = [(i, j) for i in range(10) for j in range(i + 1, 10)]
    return Framework(r, edges, leaders=[0, 1, 2], name="ten_agents")


# ---------------------------------------------------------------------------- (a) parallel API, (e) moving obstacles
def _pz_step(scenario: str, **kwargs: Any) -> Callable[[], None]:
    """One parallel step of ``formation_v0`` with random actions from a pool, resetting where an episode ends."""
    from formation_env.formation_v0 import parallel_env

    env = parallel_env(scenario=scenario, **kwargs)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    pool = [{a: rng.uniform(-0.3, 0.3, 2).astype(np.float32) for a in env.possible_agents} for _ in range(64)]
    count = [0]

    def step() -> None:
        if not env.agents:
            env.reset()
        env.step(pool[count[0] & 63])
        count[0] += 1

    return step


def bench_parallel(quick: bool) -> list[Row]:
    fns = {"ours": _pz_step("narrow_passage")}
    labels = {"ours": "formation_v0 narrow_passage (n=5: 3 leaders, 2 followers; walls, 16 rays/leader) parallel step"}
    if not _have("mpe2"):
        return [_skip("a", "mpe2 simple_spread_v3", "mpe2 not installed (pip install -e '.[bench]')")]
    from mpe2 import simple_spread_v3

    mpe = simple_spread_v3.parallel_env(N=3, continuous_actions=True, max_cycles=25)
    mpe.reset(seed=0)
    mpool = [{a: mpe.action_space(a).sample() for a in mpe.possible_agents} for _ in range(64)]
    count = [0]

    def step_mpe() -> None:
        if not mpe.agents:
            mpe.reset()
        mpe.step(mpool[count[0] & 63])
        count[0] += 1

    fns["mpe2"] = step_mpe
    labels["mpe2"] = "mpe2 simple_spread_v3 (N=3, continuous) parallel step"
    rates = _rates(fns, dict.fromkeys(fns, 1.0), 300 if quick else 1000, 5 if quick else 9)
    return _compare_rows("a", rates, "ours", "steps/s", 5.0, labels)


def bench_moving(quick: bool) -> list[Row]:
    fns = {"moving": _pz_step("moving_obstacles"), "field": _pz_step("obstacle_field")}
    labels = {
        "moving": "formation_v0 moving_obstacles (3 moving discs) parallel step",
        "field": "formation_v0 obstacle_field (6 static discs) parallel step",
    }
    rates = _rates(fns, dict.fromkeys(fns, 1.0), 300 if quick else 1000, 5 if quick else 9)
    return _compare_rows("e", rates, "moving", "steps/s", 0.5, labels)


# ---------------------------------------------------------------------------- (b) batched
def _vmas_env(scenario: str, B: int, **kwargs: Any) -> tuple[Any, list[Any]]:
    """A reset VMAS CPU env of ``B`` envs (continuous actions, seed 0) and 8 prepared random action sets."""
    import vmas

    env = vmas.make_env(scenario, num_envs=B, device="cpu", continuous_actions=True, seed=0, **kwargs)
    env.reset()
    return env, [[env.get_random_action(a) for a in env.agents] for _ in range(8)]


def _vmas_step(env: Any, vacts: list[Any], threads: int) -> Callable[[], None]:
    """One VMAS step on ``threads`` torch threads, cycling through the 8 prepared action sets ``vacts``."""
    import torch

    count = [0]

    def step() -> None:
        torch.set_num_threads(threads)
        with torch.no_grad():
            env.step(vacts[count[0] & 7])
        count[0] += 1

    return step


def bench_batched(quick: bool, B: int = 1024) -> list[Row]:
    from formation_env.env.vector import FormationVecEnv

    rng = np.random.default_rng(0)
    v = FormationVecEnv("narrow_passage", num_envs=B, mode="shared", seed=0, framework=_ten_agent_framework())
    v.reset()
    acts = [rng.uniform(-1, 1, (v.num_envs, v.p)).astype(np.float32) for _ in range(8)]
    for a in acts * 8:  # warm up: episodes end and restart every step, as in training
        v.step(a)
    count = [0]

    def step() -> None:
        v.step(acts[count[0] & 7])
        count[0] += 1

    fns: dict[str, Callable[[], None]] = {"ours": step}
    labels = {"ours": f"FormationVecEnv narrow_passage B={B} n=10 (3 leaders, shared mode, SB3 VecEnv, auto-reset)"}
    if not _have("vmas"):
        return [_skip("b", "VMAS simple_spread", "vmas not installed (pip install -e '.[bench]')")]
    import torch

    env, vacts = _vmas_env("simple_spread", B, n_agents=10)
    fns["vmas"] = _vmas_step(env, vacts, torch.get_num_threads())
    labels["vmas"] = f"VMAS simple_spread CPU B={B} n=10, torch's default threads ({torch.get_num_threads()})"
    rates = _rates(fns, dict.fromkeys(fns, float(B)), 3 if quick else 10, 5 if quick else 7, turn_s=0.05)
    return _compare_rows("b", rates, "ours", "env-steps/s", 7.0, labels)


def bench_make_vec(quick: bool, n: int = 64) -> list[Row]:
    """(f) ``gym.make_vec`` of a Gymnasium id: the batched env against Gymnasium's loop over single envs."""
    import gymnasium as gym

    import formation_env

    env_id = formation_env.SCENARIO_IDS_V1["narrow_passage"]
    rng = np.random.default_rng(0)
    fns: dict[str, Callable[[], None]] = {}
    for name, mode in (("batched", "vector_entry_point"), ("sync", "sync")):
        venv = gym.make_vec(env_id, num_envs=n, vectorization_mode=mode, max_episode_steps=20)
        venv.reset(seed=0)
        acts = [rng.uniform(-1, 1, venv.action_space.shape).astype(np.float32) for _ in range(8)]
        count = [0]

        def step(venv: Any = venv, acts: list[Any] = acts, count: list[int] = count) -> None:
            venv.step(acts[count[0] & 7])
            count[0] += 1

        fns[name] = step

    import numba

    def one_thread(step: Callable[[], None] = fns["batched"]) -> None:
        threads = numba.get_num_threads()
        numba.set_num_threads(1)
        try:
            step()
        finally:
            numba.set_num_threads(threads)

    fns["batched_1"] = one_thread
    labels = {
        "batched": f"gym.make_vec({env_id!r}, num_envs={n}): the batched env (vector_entry_point, the default)",
        "sync": f"the same with vectorization_mode='sync' (SyncVectorEnv of {n} gym.make envs)",
        "batched_1": "the batched env with numba.set_num_threads(1) (as a training process sets it)",
    }
    rates = _rates(fns, dict.fromkeys(fns, float(n)), 20 if quick else 50, 3 if quick else 7, turn_s=0.2)
    rows = []
    for ours in ("batched", "batched_1"):  # each against the same sync turns
        rows += _compare_rows("f", {ours: rates[ours], "sync": rates["sync"]}, ours, "env-steps/s", None, labels)
    return rows


def bench_ppo_here(quick: bool) -> list[Row]:
    """PPO ``learn`` timesteps/s in this process, torch on 1 thread (a 64x64 MLP gains nothing from more; on a shared
    machine more threads made the spread of repeats 15x wider)."""
    import gymnasium as gym
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.env_util import make_vec_env

    import formation_env  # noqa: F401  (registers FormationCommander-v0)
    from formation_env.env.vector import FormationVecEnv

    steps = 1024 if quick else 2048
    cid = "formation_env/FormationCommander-v0"
    makers: dict[str, tuple[Callable[[], Any], int]] = {
        "commander": (lambda: gym.make(cid), 1),
        "commander_vec1": (lambda: FormationVecEnv("narrow_passage", 1, mode="commander"), 1),
        "pendulum": (lambda: gym.make("Pendulum-v1"), 1),
        "commander_vec8": (lambda: FormationVecEnv("narrow_passage", 8, mode="commander"), 8),
        "pendulum8": (lambda: make_vec_env("Pendulum-v1", n_envs=8, seed=0), 8),
    }

    def learn(name: str, total: int = steps) -> Callable[[], None]:
        make, n_envs = makers[name]

        def go() -> None:
            env = make()
            PPO("MlpPolicy", env, n_steps=256 if n_envs == 1 else 64, **PPO_SETTINGS).learn(total_timesteps=total)
            env.close()

        return go

    labels = {
        "commander": f"PPO on gym.make(FormationCommander-v0) (narrow_passage), 1 env, {steps} timesteps",
        "commander_vec1": "PPO on FormationVecEnv(mode='commander', num_envs=1), same env",
        "pendulum": "PPO on gym.make(Pendulum-v1), 1 env, same settings",
        "commander_vec8": "PPO on FormationVecEnv(mode='commander', num_envs=8), n_steps 64",
        "pendulum8": "PPO on make_vec_env(Pendulum-v1, 8), n_steps 64",
    }
    pairs = [("commander", "pendulum"), ("commander_vec1", "pendulum"), ("commander_vec8", "pendulum8")]
    rows: list[Row] = []
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        for name in makers:  # warm torch and the envs up
            learn(name, 256)()
        for ours, peer in pairs:  # each comparison on its own, ours and the peer in adjacent turns (A B, B A, ...)
            fns = {ours: learn(ours), peer: learn(peer)}
            rates = _rates(fns, dict.fromkeys(fns, float(steps)), 1, 4 if quick else 12, warmup=False)
            rows += _compare_rows("c", rates, ours, "timesteps/s", None, labels)
    finally:
        torch.set_num_threads(threads)
    return rows


# ---------------------------------------------------------------------------- (d) large swarms
_LARGE = r"""
import json, resource, sys, time
import numpy as np
from formation_env.core.frameworks import trilateration
from formation_env.formation_v0 import parallel_env
n = int(sys.argv[1])
fw = trilateration(n, 2, seed=0)
env = parallel_env(scenario="hold", framework=fw, agent_radius=1e-3)
env.reset(seed=0)
acts = {a: np.full(2, 0.3, np.float32) for a in env.agents}
times = []
for _ in range(60):
    if not env.agents:
        env.reset()
    t0 = time.perf_counter()
    env.step(acts)
    times.append(time.perf_counter() - t0)
with open("/proc/self/status") as fh:
    hwm = next(float(line.split()[1]) for line in fh if line.startswith("VmHWM:"))
print(json.dumps({"step_ms": [1e3 * t for t in times[10:]], "peak_mb": hwm / 1024}))
"""


def bench_large(quick: bool, n: int = 10_000) -> list[Row]:
    try:
        res = subprocess.run([sys.executable, "-c", _LARGE, str(n)], capture_output=True, text=True, timeout=600)
        out = json.loads(res.stdout.strip().splitlines()[-1])
    except (subprocess.TimeoutExpired, json.JSONDecodeError, IndexError) as exc:
        return [_skip("d", f"trilateration({n})", f"{type(exc).__name__}: {str(exc)[:200]}")]
    ms = out["step_ms"]
    step = _row("d", f"formation_v0 hold on trilateration({n:,}, 2), dynamic law, sparse stress: step", "ms", ms)
    step.update(target="<= 10 ms", met=statistics.median(ms) <= 10.0)
    rss = {"section": "d", "case": "the same, peak RSS of the fresh process (VmHWM)", "unit": "MB",
           "median": out["peak_mb"], "min": out["peak_mb"], "max": out["peak_mb"],
           "target": "<= 500 MB", "met": out["peak_mb"] <= 500.0}  # fmt: skip
    return [step, rss]


def _in_subprocess(fn: str, quick: bool, section: str, label: str, env: dict[str, str] | None = None) -> list[Row]:
    """The rows of ``fn(quick)`` (a function of this module) run in a fresh Python process with ``env`` added to the
    environment; a skip row on a timeout or no output."""
    from pathlib import Path

    code = f"import json; from benchmarks import env_bench as e; print(json.dumps(e.{fn}({quick!r})))"
    root = Path(__file__).resolve().parents[1]
    try:
        res = subprocess.run(
            [sys.executable, "-c", code],
            capture_output=True,
            text=True,
            timeout=900,
            env={**os.environ, **(env or {})},
            cwd=root,
            check=False,
        )
        return list(json.loads(res.stdout.strip().splitlines()[-1]))
    except (subprocess.TimeoutExpired, json.JSONDecodeError, IndexError) as exc:
        return [_skip(section, label, f"{type(exc).__name__}: {str(exc)[:200]}")]


def bench_ppo(quick: bool) -> list[Row]:
    """(c) in a fresh process, as a training run has it: after (b) this process holds about 280k objects (VMAS,
    mpe2, the 1024-env batches), and its garbage collections then cost PPO's loop more on the env that allocates
    more per step (``bench_ppo_here`` after ``bench_batched`` in one process shows it)."""
    return _in_subprocess("bench_ppo_here", quick, "c", "PPO")


# ---------------------------------------------------------------------------- runner hooks
def run(quick: bool = False) -> list[Row]:
    """All env benchmarks, section by section."""
    rows: list[Row] = []
    for fn in (bench_parallel, bench_batched, bench_ppo, bench_large, bench_moving, bench_make_vec):
        print(f"[env] {fn.__name__} ...", file=sys.stderr, flush=True)
        with contextlib.suppress(KeyboardInterrupt):
            rows += fn(quick)
    return rows


def _fmt(x: float) -> str:
    if abs(x) >= 1000:
        return f"{x:,.0f}"
    if abs(x) >= 10:
        return f"{x:.1f}"
    return f"{x:.3g}"


def markdown(rows: list[Row]) -> str:
    """One table: median (min-max) per case, ours/theirs speed ratio and the target."""
    out = [
        "| § | case | median | min-max | unit | ours / this (min-max) | target | met |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        if "skipped" in r:
            out.append(f"| {r['section']} | {r['case']} | skipped: {r['skipped']} | | | | | |")
            continue
        med = _fmt(r["median"]) if "median" in r else r.get("note", "")
        rng = f"{_fmt(r['min'])}-{_fmt(r['max'])}" if "min" in r else r.get("note", "") if "median" in r else ""
        ratio = f"{r['ratio']:.2f}x ({r['ratio_min']:.2f}-{r['ratio_max']:.2f})" if "ratio" in r else ""
        tgt = r.get("target", "")
        tgt = f">= {tgt}x" if isinstance(tgt, float) else tgt
        met = {True: "yes", False: "**no**"}.get(r.get("met"), "")  # type: ignore[call-overload]
        out.append(f"| {r['section']} | {r['case']} | {med} | {rng} | {r['unit']} | {ratio} | {tgt} | {met} |")
    return "\n".join(out)


if __name__ == "__main__":
    print(markdown(run(quick="--quick" in sys.argv)))
