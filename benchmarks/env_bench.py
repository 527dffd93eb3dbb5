"""Env speed against MPE2 and VMAS, PPO throughput, large swarms and memory (all in one process, interleaved).

* (a) PettingZoo parallel step: ``formation_v0`` (narrow_passage, 5 agents: 3 leaders, 2 followers
  inside, double integrators, walls and 16 rays per leader) against MPE2 ``simple_spread_v3``
  (N = 3, continuous actions), both through the parallel API with dict actions; ``hold`` (no
  obstacles) beside it. Target >= 10x. Beside it, the engine's single-env step compiled
  (``Engine.step1``) against the numpy folded step it is tested against, and (for (c)) the
  commander env's step against Pendulum-v1's.
* (b) Batched: ``FormationVecEnv`` at B = 1024 on a 10-agent framework (3 leaders, 7 followers,
  complete graph), observations and rewards computed, auto-reset included (warmed up, so that
  episodes end and restart every step as in training), with its default ``num_threads`` (the
  CPUs the process may use) and with one thread, against VMAS on CPU at the same B (and, beside
  it, with ``draw_ahead=0``: each finished env draws its next episode in the step it ends):
  ``simple_spread`` and ``navigation`` with 10 agents, and ``simple_spread`` with its default 3
  agents (no resets), VMAS timed with torch's default threads, ``torch.set_num_threads(2)`` and 1
  (a row per distinct count); ours on one thread is compared with VMAS's 3-agent case only, and
  so is ours through Gymnasium's vector API (``to_gymnasium()``: infos as arrays, as VMAS gives
  them, where SB3's ``VecEnv`` API needs a dict per slot, 3,072 at B = 1024), and ours with
  ``share_empty_infos=True`` (the slots that did not finish share one read-only empty info dict;
  finished slots keep their own). Then
  all of (b) again in a subprocess with OpenBLAS, OpenMP and MKL on one thread
  (``OPENBLAS_NUM_THREADS=1`` etc.; torch then defaults to one thread). Each comparison runs on its
  own, ours and the peer in adjacent turns. Env-steps/s = B / step time. Target >= 3x.
* (c) SB3 PPO end to end (``learn``): the commander env (``FormationCommander-v0``) against
  ``Pendulum-v1`` with the same PPO settings, one env each (and 8 envs each), in a fresh process (see
  ``bench_ppo``); each comparison on its own, ours and Pendulum in adjacent turns. Target >= 0.9x.
* (d) Large swarms: core step with a sparse stress at n = 10,000 (< 1 ms), constructive design
  for 10,000 agents (< 10 s), the env on such a framework, and a render of it.
* (e) Memory: peak RSS of the large cases, each in a fresh subprocess (``VmHWM`` of
  /proc/self/status; ``ru_maxrss`` would carry the parent's peak over fork and exec), and
  tracemalloc growth over many env steps (a leak shows as growth per step).

Ratios are ours / theirs in speed (> 1: ours faster), the median over interleaved repeats,
with the min-max of the per-repeat ratios. In (b) each fn's turn lasts about 50 ms (at least 10 calls), so
that the slower first calls after a switch weigh alike on both (``python -m benchmarks.vec_profile --switch``).
Comparisons whose package is missing (the
``bench`` extra: ``pip install formation-env[bench]``) are skipped with a message.
"""

from __future__ import annotations

import contextlib
import gc
import importlib.util
import json
import math
import os
import statistics
import subprocess
import sys
import time
import tracemalloc
from collections.abc import Callable
from typing import Any

import numpy as np

TITLE = "Env step: PettingZoo vs MPE2, batched vs VMAS, PPO throughput, large swarms, memory"

Row = dict[str, Any]


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


# ---------------------------------------------------------------------------- (a) parallel API
def bench_parallel(quick: bool) -> list[Row]:
    from formation_env.formation_v0 import parallel_env

    rng = np.random.default_rng(0)
    fns: dict[str, Callable[[], None]] = {}
    labels: dict[str, str] = {}
    for scen in ("narrow_passage", "hold"):
        env = parallel_env(scenario=scen)
        env.reset(seed=0)
        pool = [{a: rng.uniform(-0.3, 0.3, 2).astype(np.float32) for a in env.possible_agents} for _ in range(64)]

        def step(env: Any = env, pool: list[dict[str, Any]] = pool, c: list[int] = [0]) -> None:  # noqa: B006
            if not env.agents:
                env.reset()
            env.step(pool[c[0] & 63])
            c[0] += 1

        fns[scen] = step
        obstacles = "walls, 16 rays/leader" if scen == "narrow_passage" else "no obstacles"
        labels[scen] = f"formation_v0 {scen} (n=5: 3 leaders, 2 followers; {obstacles}) parallel step"
    rows: list[Row] = []
    if _have("mpe2"):
        from mpe2 import simple_spread_v3

        mpe = simple_spread_v3.parallel_env(N=3, continuous_actions=True, max_cycles=25)
        mpe.reset(seed=0)
        mpool = [{a: mpe.action_space(a).sample() for a in mpe.possible_agents} for _ in range(64)]
        jt = {"i": 0}

        def step_mpe() -> None:
            if not mpe.agents:
                mpe.reset()
            mpe.step(mpool[jt["i"] & 63])
            jt["i"] += 1

        fns["mpe2"] = step_mpe
        labels["mpe2"] = "mpe2 simple_spread_v3 (N=3, continuous) parallel step"
    else:
        rows.append(_skip("a", "mpe2 simple_spread_v3", "mpe2 not installed (pip install formation-env[bench])"))
    rates = _rates(fns, dict.fromkeys(fns, 1.0), 300 if quick else 1000, 5 if quick else 9)
    out: list[Row] = []
    for ours, other in (("narrow_passage", "hold"), ("hold", "narrow_passage")):
        out += _compare_rows("a", {k: v for k, v in rates.items() if k != other}, ours, "steps/s", 10.0, labels)
    return out + rows


def bench_single(quick: bool) -> list[Row]:
    """The single-env step behind (a) and (c): ``Engine.step1`` (compiled) against the numpy folded step on the
    same B = 1 state (the reference it is tested against), and the commander env's step against Pendulum-v1's
    (``gym.make`` both, random actions, resets included)."""
    import gymnasium as gym

    import formation_env  # noqa: F401  (registers the commander)
    from formation_env.env.engine import Engine

    eng = Engine("narrow_passage")
    fast = eng.reset(np.random.default_rng(0), 1)
    ref = fast._replace(params={k: v for k, v in fast.params.items() if k != "_ep1"})  # no packed episode arrays: numpy
    a = np.full((eng.n_l, eng.p), 0.1)
    a3 = a[None]

    def numpy_step() -> None:
        eng._kbatch = False
        eng.step(ref, a3)
        eng._kbatch = True

    fns: dict[str, Callable[[], None]] = {"step1": lambda: eng.step1(fast, a), "numpy": numpy_step}
    for name, gid in (("commander", "formation_env/FormationCommander-v0"), ("pendulum", "Pendulum-v1")):
        env = gym.make(gid)
        env.reset(seed=0)
        pool = [env.action_space.sample() for _ in range(64)]
        env.action_space.seed(0)

        def step(env: Any = env, pool: list[Any] = pool, c: list[int] = [0]) -> None:  # noqa: B006
            _, _, te, tr, _ = env.step(pool[c[0] & 63])
            c[0] += 1
            if te or tr:
                env.reset()

        fns[name] = step
    rates = _rates(fns, dict.fromkeys(fns, 1.0), 500 if quick else 2000, 5 if quick else 9)
    labels = {
        "step1": "Engine.step1, narrow_passage (n=5), B=1, compiled",
        "numpy": "Engine.step, same state, numpy folded step (the reference)",
        "commander": "gym.make(FormationCommander-v0) step, random actions, resets included",
        "pendulum": "gym.make(Pendulum-v1) step, random actions, resets included",
    }
    rows = _compare_rows("a", {k: rates[k] for k in ("step1", "numpy")}, "step1", "steps/s", None, labels)
    rows += _compare_rows("c", {k: rates[k] for k in ("commander", "pendulum")}, "commander", "steps/s", None, labels)
    return rows


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
    """B-env steps/s of ``FormationVecEnv`` (10 agents, random actions in [-0.3, 0.3], timed in the steady
    state of auto-resets) against VMAS on CPU at the same B: simple_spread and navigation with 10 agents,
    and simple_spread with its default 3 agents."""
    from formation_env.env.vector import FormationVecEnv

    fw = _ten_agent_framework()
    fns: dict[str, Callable[[], None]] = {}
    labels: dict[str, str] = {}
    rng = np.random.default_rng(0)
    resets: dict[str, list[int]] = {}
    from formation_env.env._kernel import default_threads

    ours_threads = default_threads()
    for scen in ("hold", "narrow_passage"):
        # the default threads, one thread (if they differ), the default threads drawing no episodes ahead, the
        # default with the unfinished slots sharing one read-only empty info (share_empty_infos), and the default
        # through Gymnasium's vector API (infos as arrays, as VMAS returns them: no per-slot dicts)
        variants = (
            (ours_threads, None, False, False),
            (1, None, False, False),
            (ours_threads, 0, False, False),
            (ours_threads, None, True, False),
            (ours_threads, None, False, True),
        )
        for nt, ahead, shared_infos, gym_api in dict.fromkeys(variants):
            key = scen + ("" if nt == ours_threads else f"_t{nt}") + ("" if ahead is None else "_ahead0")
            key += ("_shared" if shared_infos else "") + ("_gym" if gym_api else "")
            v = FormationVecEnv(
                scen,
                num_envs=B,
                mode="shared",
                seed=0,
                framework=fw,
                num_threads=nt,
                draw_ahead=ahead,
                share_empty_infos=shared_infos,
            )
            env: Any = v.to_gymnasium() if gym_api else v
            env.reset()
            acts = [rng.uniform(-0.3, 0.3, (v.num_envs, v.p)).astype(np.float32) for _ in range(8)]
            for i in range(100):  # into the steady state: no episode ends in the first ~15 steps, ~15 a step later
                env.step(acts[i & 7])
            resets[key] = c = [0, 0]  # steps, auto-resets

            def step(env: Any = env, v: FormationVecEnv = v, acts: list[np.ndarray] = acts, c: list[int] = c) -> None:
                env.step(acts[c[0] & 7])
                c[0] += 1
                c[1] += int(np.count_nonzero(v.last_terminated | v.last_truncated))

            fns[key] = step
            labels[key] = f"FormationVecEnv {scen} B={B} n=10 " + (
                f"via Gymnasium's vector API (threads={nt}"
                if gym_api
                else f"(3 leaders, shared, threads={nt}"
                + ("" if ahead is None else ", draw_ahead=0: each finished env draws its next episode")
                + (", share_empty_infos=True: unfinished slots share one read-only empty info" if shared_infos else "")
            )
    rows: list[Row] = []
    if _have("vmas"):
        import torch

        default_threads = torch.get_num_threads()
        for scen in ("simple_spread", "navigation"):
            env, vacts = _vmas_env(scen, B, n_agents=10)
            for threads in (default_threads, 2, 1):
                key = f"vmas_{scen}_{threads}"
                if key in fns:
                    continue
                fns[key] = _vmas_step(env, vacts, threads)
                labels[key] = f"VMAS {scen} CPU B={B} n=10, torch threads={threads}" + (
                    " (default)" if threads == default_threads else ""
                )
        # VMAS's own default size (simple_spread: n_agents=3), the cheapest VMAS case to compare with
        env3, vacts3 = _vmas_env("simple_spread", B)
        for threads in dict.fromkeys((default_threads, 1)):
            key = "vmas_simple_spread_n3" + ("" if threads == default_threads else f"_t{threads}")
            fns[key] = _vmas_step(env3, vacts3, threads)
            labels[key] = f"VMAS simple_spread CPU B={B} n={len(env3.agents)} (its default), torch threads={threads}"
        torch.set_num_threads(default_threads)
    else:
        rows.append(
            _skip("b", "VMAS simple_spread / navigation", "vmas not installed (pip install formation-env[bench])")
        )
    # each comparison on its own, ours and the peer in adjacent turns (A B, B A, ...: on this shared machine a
    # turn of all the cases one after another spread the per-repeat ratios over 2-4x); turns of ~50 ms (at least
    # 10 calls): ours steps ~1 ms, VMAS's 3-agent simple_spread ~2 ms, and each one's first call after a switch
    # costs 1.5x (measured, benchmarks.vec_profile --switch). 21 repeats against VMAS's 3-agent case, whose ratio
    # lies near the target and whose per-repeat ratios spread widely (the min-max columns), 7 against the 10-agent
    # cases (ratios of 30-190x; a navigation step takes ~0.1 s)
    calls, repeat, near, turn_s = (3, 3, 3, 0.02) if quick else (10, 7, 21, 0.05)
    peers = [k for k in fns if k.startswith("vmas")]
    runs: list[tuple[str, list[str], float | None, list[dict[str, list[float]]]]] = []
    for key in resets:  # ours at its default threads against every VMAS case, the others against VMAS n=3
        if key.endswith("_ahead0"):  # drawing ahead (the default) against not (ratio > 1: ahead faster)
            ours, mine, target = key.removesuffix("_ahead0"), [key], None
        else:
            ours, target = key, 3.0
            mine = peers if key in ("hold", "narrow_passage") else [k for k in peers if "_n3" in k]
        pairs = [  # one run per peer (without VMAS, ours alone)
            _rates(
                {k: fns[k] for k in (ours, *ks)},
                dict.fromkeys((ours, *ks), float(B)),
                calls,
                repeat if any(k.startswith("vmas") and "_n3" not in k for k in ks) else near,
                turn_s=turn_s,
            )
            for ks in ([[k] for k in mine] or [[]])
        ]
        runs.append((ours, mine, target, pairs))
    for key, (n_steps, n_resets) in resets.items():
        labels[key] += f", auto-reset: {n_resets / max(n_steps, 1):.1f} envs reset a step)"
    out: list[Row] = []
    for ours, mine, target, pairs in runs:
        rows_k = [_row("b", labels[ours], "env-steps/s", [x for r in pairs for x in r[ours]])]
        for k, r in zip(mine, pairs, strict=False):
            rows_k += _compare_rows("b", {ours: r[ours], k: r[k]}, ours, "env-steps/s", target, labels)[1:]
        out += rows_k[1:] if target is None else rows_k
    return out + rows


# ---------------------------------------------------------------------------- (c) PPO
#: PPO's settings in (c) and in ``benchmarks.ppo_profile`` (n_steps 256 with one env, 64 with 8)
PPO_SETTINGS: dict[str, Any] = {"batch_size": 64, "n_epochs": 4, "device": "cpu", "seed": 0, "verbose": 0}


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
            rows += _compare_rows("c", rates, ours, "timesteps/s", 0.9, labels)
    finally:
        torch.set_num_threads(threads)
    return rows


# ---------------------------------------------------------------------------- (d) large swarms
_LARGE = r"""
import json, resource, sys, time
import numpy as np
case, n, png = sys.argv[1], int(sys.argv[2]), sys.argv[3]
out = {}
resource.setrlimit(resource.RLIMIT_AS, (8 << 30, 8 << 30))  # never take the shared machine down

def peak_kb():
    # this process's own peak RSS (ru_maxrss would include the parent's, inherited over fork and exec)
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("VmHWM:"):
                    return float(line.split()[1])
    except OSError:
        pass
    return float(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)

def stand_in(n):
    # a jittered grid with right/up edges and 3 corner leaders: only to try the env and the renderer
    from formation_env.core.framework import Framework
    m = int(np.ceil(np.sqrt(n)))
    ij = np.stack(np.divmod(np.arange(n), m), 1).astype(float)
    r = (ij + np.random.default_rng(0).uniform(-0.2, 0.2, (n, 2))) * (20.0 / m) - 10.0
    edges = [(i, i + 1) for i in range(n - 1) if (i + 1) % m] + [(i, i + m) for i in range(n - m)]
    return Framework(r, edges, leaders=[0, m - 1, n - 1], name=f"grid_{n}")

fw = om = None
try:
    from formation_env.core.frameworks import trilateration
    from formation_env.core.design import design_stress
    t0 = time.perf_counter(); fw = trilateration(n, 2, seed=0); out["framework_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    try:
        res = design_stress(fw, "constructive")
    finally:
        out["design_tried_s"] = time.perf_counter() - t0
    out["design_s"] = out["design_tried_s"]
    om = getattr(res, "omega", res)
except Exception as exc:
    out["error"] = f"{type(exc).__name__}: {str(exc)[:300]}"
try:
    if case == "core" and om is not None:
        from formation_env.core import LinearDynamics, Partition, make_law
        part = Partition(om, list(fw.leaders))
        law = make_law("stationary", part, LinearDynamics.single_integrator(2), 0.1, gain=0.1)
        x = np.random.default_rng(0).normal(size=(n, 2)); u = np.zeros((part.n_l, 2)); mem = law.initial_memory()
        law.step(x, u, mem)
        ts = []
        for _ in range(7):
            t0 = time.perf_counter()
            for _ in range(20): law.step(x, u, mem)
            ts.append((time.perf_counter() - t0) / 20)
        out["step_s"] = sorted(ts)[3]; out["step_min_s"] = min(ts); out["step_max_s"] = max(ts)
    elif case == "env":
        if fw is None:
            fw = stand_in(n); out["framework"] = fw.name + " (stand-in: trilateration/design_stress absent)"
        from formation_env.env.formation import FormationEnv
        try:
            e = fw.edge_array()
            rad = float(np.min(np.linalg.norm(fw.positions[e[:, 0]] - fw.positions[e[:, 1]], axis=1))) / 3
            t0 = time.perf_counter()  # the env designs (constructive) and checks the sparse stress itself
            env = FormationEnv("hold", framework=fw, follower_law="stationary", dynamics="single_integrator",
                               agent_radius=rad, render_mode="rgb_array")
            out["env_build_s"] = time.perf_counter() - t0
            out["env_sparse"] = bool(env.engine.sparse)
            env.reset(seed=0)
            acts = {a: np.full(2, 0.05, np.float32) for a in env.agents}
            def step(env=env, acts=acts):
                env.step(acts)
                if not env.agents: env.reset()  # an episode ended (collision or success): go on
            for _ in range(20): step()
            ts = []
            for _ in range(7):
                t0 = time.perf_counter()
                for _ in range(20): step()
                ts.append((time.perf_counter() - t0) / 20)
            out["env_step_s"] = sorted(ts)[3]; out["env_step_min_s"] = min(ts); out["env_step_max_s"] = max(ts)
            out["rss_steps_mb"] = peak_kb() / 1024
            for _ in range(200): step()
            out["rss_growth_kb"] = peak_kb() - out["rss_steps_mb"] * 1024
            t0 = time.perf_counter()
            img = env.render()
            out["render_s"] = time.perf_counter() - t0
        except Exception as exc:
            out["env_error"] = f"{type(exc).__name__}: {exc}"
            from formation_env.env.rendering import Renderer
            lo, hi = fw.positions.min(0) - 1, fw.positions.max(0) + 1
            frame = {"positions": fw.positions, "leaders": np.asarray(fw.leaders), "edges": fw.edge_array(),
                     "targets": fw.positions,
                     "obstacles": {"segments": np.zeros((0, 2, 2)), "circles": np.zeros((0, 3))},
                     "goal": fw.positions, "trail": np.zeros((0, n, 2)), "bounds": (lo, hi), "agent_radius": 0.02,
                     "text": f"{fw.name}: {n} agents (framework only)", "time": 0.0}
            t0 = time.perf_counter()
            img = Renderer(2, "rgb_array").draw(frame)
            out["render_s"] = time.perf_counter() - t0
        import imageio.v3 as iio
        iio.imwrite(png, img); out["render_file"] = png; out["render_shape"] = list(img.shape)
except Exception as exc:
    out["error2"] = f"{type(exc).__name__}: {exc}"
out["peak_rss_mb"] = peak_kb() / 1024
print(json.dumps(out))
"""


def _subprocess(case: str, n: int) -> dict[str, Any]:
    png = os.path.abspath(f"benchmarks/swarm_{n}.png")
    cmd = [sys.executable, "-c", _LARGE, case, str(n), png]
    try:
        res = subprocess.run(cmd, capture_output=True, text=True, timeout=600, check=False)
        return json.loads(res.stdout.strip().splitlines()[-1])
    except (subprocess.TimeoutExpired, json.JSONDecodeError, IndexError) as exc:
        return {"error": f"{type(exc).__name__}: {str(exc)[:200]}"}


def bench_large(quick: bool, n: int = 10_000) -> list[Row]:
    rows: list[Row] = []
    core = _subprocess("core", n)
    if "design_s" not in core:
        tried = f" (failed after {core['design_tried_s']:.1f} s)" if "design_tried_s" in core else ""
        rows.append(_skip("d", f"constructive design + core step, n={n:,}", core.get("error", "?") + tried))
    else:
        rows.append(
            {
                "section": "d",
                "case": f"constructive design_stress, n={n:,}",
                "unit": "s",
                "median": core["design_s"],
                "target": "< 10 s",
                "met": core["design_s"] < 10.0,
            }
        )
        if "step_s" in core:
            rows.append(
                {
                    "section": "d",
                    "case": f"core step (stationary, sparse stress), n={n:,}",
                    "unit": "ms",
                    "median": core["step_s"] * 1e3,
                    "min": core["step_min_s"] * 1e3,
                    "max": core["step_max_s"] * 1e3,
                    "target": "< 1 ms",
                    "met": core["step_s"] < 1e-3,
                }
            )
        else:
            rows.append(_skip("d", f"core step, n={n:,}", core.get("error2", "?")))
        rows.append(
            {
                "section": "e",
                "case": f"peak RSS: design + core step, n={n:,}",
                "unit": "MB",
                "median": core["peak_rss_mb"],
            }
        )
    env = _subprocess("env", n)
    fw_name = env.get("framework", f"trilateration({n}, 2)")
    if "env_step_s" in env:
        rows.append(
            {
                "section": "d",
                "case": f"FormationEnv hold on {fw_name} (followers inside, sparse path): parallel step",
                "unit": "ms",
                "median": env["env_step_s"] * 1e3,
                "min": env["env_step_min_s"] * 1e3,
                "max": env["env_step_max_s"] * 1e3,
                "note": f"build (design + check + env) {env['env_build_s']:.1f} s",
            }
        )
        rows.append(
            {
                "section": "e",
                "case": f"peak RSS: env build + 160 steps on {fw_name}",
                "unit": "MB",
                "median": env["rss_steps_mb"],
                "note": f"+{env['rss_growth_kb']:.0f} kB over 200 more steps",
            }
        )
    else:
        rows.append(_skip("d", f"FormationEnv on {fw_name}", env.get("env_error", env.get("error2", "?"))))
    if "render_file" in env:
        how = "env.render()" if "env_step_s" in env else "Renderer on the framework alone"
        rows.append(
            {
                "section": "d",
                "case": f"render of {fw_name} ({how})",
                "unit": "s",
                "median": env.get("render_s", float("nan")),
                "note": f"{os.path.relpath(env['render_file'])} {env['render_shape']}",
            }
        )
    if "peak_rss_mb" in env:
        rows.append(
            {"section": "e", "case": f"peak RSS: env + render on {fw_name}", "unit": "MB", "median": env["peak_rss_mb"]}
        )
    return rows


# ---------------------------------------------------------------------------- (e) per-step allocations
def bench_leak(quick: bool) -> list[Row]:
    from formation_env.env.vector import FormationVecEnv
    from formation_env.formation_v0 import parallel_env

    rows: list[Row] = []
    steps = 500 if quick else 2000
    pz = parallel_env(scenario="narrow_passage", max_cycles=50)
    pz.reset(seed=0)
    a0 = {a: np.full(2, 0.2, np.float32) for a in pz.possible_agents}
    vec = FormationVecEnv("narrow_passage", num_envs=64, seed=0, max_cycles=50)
    vec.reset()
    va = np.full((vec.num_envs, vec.p), 0.2, np.float32)

    def pz_step() -> None:
        if not pz.agents:
            pz.reset()
        pz.step(a0)

    for name, fn in (
        ("formation_v0 parallel step (B=1)", pz_step),
        ("FormationVecEnv step (B=64)", lambda: vec.step(va)),
    ):
        for _ in range(200):
            fn()
        gc.collect()
        tracemalloc.start()
        for _ in range(200):
            fn()
        gc.collect()
        base = tracemalloc.get_traced_memory()[0]
        for _ in range(steps):
            fn()
        gc.collect()
        cur, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
        growth = (cur - base) / steps
        rows.append(
            {
                "section": "e",
                "case": f"tracemalloc growth over {steps} steps: {name}",
                "unit": "B/step",
                "median": growth,
                "note": f"peak traced {peak / 1e6:.2f} MB",
                "target": "~0 (< 64 B/step)",
                "met": growth < 64,
            }
        )
    return rows


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


def bench_batched_single_blas(quick: bool) -> list[Row]:
    """(b) again in a subprocess with ``OPENBLAS_NUM_THREADS=1`` (numpy's BLAS on one thread).

    On a shared 2-core machine a 2-thread OpenBLAS matmul was measured 5x slower than a
    1-thread one, so (b) is reported under both settings.
    """
    one = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    rows = _in_subprocess("bench_batched", quick, "b", "batched with OPENBLAS_NUM_THREADS=1", one)
    for r in rows:
        r["case"] = f"[OPENBLAS_NUM_THREADS=1] {r['case']}"
    return rows


def bench_ppo(quick: bool) -> list[Row]:
    """(c) in a fresh process, as a training run has it: after (b) this process holds about 280k objects (VMAS,
    mpe2, the 1024-env batches), and its garbage collections then cost PPO's loop more on the env that allocates
    more per step (``bench_ppo_here`` after ``bench_batched`` in one process shows it)."""
    return _in_subprocess("bench_ppo_here", quick, "c", "PPO")


# ---------------------------------------------------------------------------- runner hooks
def run(quick: bool = False) -> list[Row]:
    """All env benchmarks; each section runs in turn, comparisons interleaved within a section."""
    rows: list[Row] = []
    for fn in (
        bench_parallel,
        bench_single,
        bench_batched,
        bench_batched_single_blas,
        bench_ppo,
        bench_large,
        bench_leak,
    ):
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
