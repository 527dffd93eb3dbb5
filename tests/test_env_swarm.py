"""Large swarms: frameworks above ``config.MAX_AGENTS`` agents keep a sparse stress and step the core law."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
import warnings
from typing import Any

import numpy as np
import pytest
import scipy.sparse as sp
from pettingzoo.test import parallel_api_test

from formation_env import formation_v0
from formation_env.core.errors import FormationError
from formation_env.core.framework import Framework
from formation_env.core.frameworks import trilateration
from formation_env.env import config
from formation_env.env.engine import Engine
from formation_env.env.vector import FormationVecEnv

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _scaled(n: int, s: float, seed: int = 0) -> Framework:
    fw = trilateration(n, 2, seed=seed)
    return Framework(fw.positions * s, fw.edges, fw.leaders, name=f"trilateration_{n}x{s:g}")


def _radius(fw: Framework) -> float:
    """An agent radius a third of the shortest edge: no contact in the nominal formation."""
    e = fw.edge_array()
    return float(np.min(np.linalg.norm(fw.positions[e[:, 0]] - fw.positions[e[:, 1]], axis=1))) / 3


def _run(eng: Engine, steps: int, B: int = 3) -> list[Any]:
    st = eng.reset(np.random.default_rng(1), B)
    rng = np.random.default_rng(2)
    out: list[Any] = [eng.observe(st), eng.global_state(st), st.err, st.goal_dist]
    for _ in range(steps):
        st, obs, rew, term, trunc, info = eng.step(st, rng.uniform(-1.2, 1.2, (B, eng.n_l, eng.p)))
        out += [obs, rew, term, trunc, st.x, st.vel, st.err, eng.global_state(st), eng.affine_targets(st)]
        out += [info[k] for k in ("success", "collision", "out_of_bounds", "min_clearance", "goal_distance")]
        out.append(info["control_effort"])
    return out


@pytest.mark.parametrize(
    ("scenario", "dynamics", "law"),
    [
        ("hold", "single_integrator", "stationary"),
        ("hold", "double_integrator", "dynamic"),
        ("maneuver", "double_integrator", "dynamic_distributed"),
        ("maneuver", "single_integrator", "linear"),
        ("narrow_passage", "double_integrator", "dynamic"),
        ("obstacle_field", "single_integrator", "stationary"),
    ],
)
def test_sparse_path_matches_folded_path(
    monkeypatch: pytest.MonkeyPatch, scenario: str, dynamics: str, law: str
) -> None:
    """The same configuration through the folded step and (forced by a lower MAX_AGENTS) the sparse one."""
    fw = _scaled(40, 0.3, seed=1) if scenario in ("hold", "maneuver") else "paper"
    kw: dict[str, Any] = {"framework": fw, "agent_radius": 0.005, "max_cycles": 50}
    dense = Engine(scenario, dynamics, law, **kw)
    monkeypatch.setattr(config, "MAX_AGENTS", 3)
    swarm = Engine(scenario, dynamics, law, **kw)
    assert not dense.sparse and swarm.sparse
    assert sp.issparse(swarm.omega) and swarm._M is None and dense._M is not None
    assert swarm.law_params.keys() == dense.law_params.keys()
    assert swarm.spectral_radius == pytest.approx(dense.spectral_radius, rel=1e-9)
    a, b = _run(dense, 120), _run(swarm, 120)
    for x, y in zip(a, b, strict=True):
        np.testing.assert_allclose(np.asarray(y, dtype=float), np.asarray(x, dtype=float), rtol=0, atol=1e-9)
    assert any(np.any(np.asarray(v)) for v in a[14::15]), "some collision expected from the random actions"


def test_large_env_passes_parallel_api_test() -> None:
    fw = _scaled(400, 0.25)
    env = formation_v0.parallel_env(scenario="hold", framework=fw, agent_radius=_radius(fw), max_cycles=40)
    assert env.unwrapped.engine.sparse
    assert env.possible_agents == ["leader_0", "leader_1", "leader_2"]  # followers stay inside
    parallel_api_test(env, num_cycles=60)


def test_followers_converge_with_the_analytic_law() -> None:
    """Leaders hold still; the formation error decays as rho^k, rho = 1 - g T = 0.9 (Theorem 2)."""
    fw = trilateration(1200, 2, seed=3)
    env = formation_v0.parallel_env(
        scenario="hold", framework=fw, dynamics="single_integrator", follower_law="dynamic", max_cycles=200,
        agent_radius=_radius(fw), follower_noise=0.5 * _radius(fw),  # no two paths closer than 2 radii
    )  # fmt: skip
    eng = env.unwrapped.engine
    assert eng.sparse and eng.spectral_radius == pytest.approx(0.9)
    env.reset(seed=0)
    st = env.unwrapped.engine_state
    e0 = float(st.err[0])
    assert e0 > 0.0
    zero = {a: np.zeros(2, np.float32) for a in env.agents}
    errs = []
    for _ in range(60):
        _, _, term, _, info = env.step(zero)
        errs.append(info["leader_0"]["formation_error"])
        assert not any(term.values())
    # e(k+1) = (1 - g T) e(k) and the fit residual is linear in e: exactly 0.9^k
    np.testing.assert_allclose(errs, e0 * 0.9 ** np.arange(1, 61), rtol=1e-6)
    tgt = eng.affine_targets(env.unwrapped.engine_state)[0]
    np.testing.assert_allclose(env.unwrapped.engine_state.pos[0], tgt, atol=1e-2)


def test_maneuver_is_tracked_by_a_large_swarm() -> None:
    from formation_env.env.control import track_targets

    fw = _scaled(600, 0.1)
    r = _radius(fw)
    eng = Engine("maneuver", "single_integrator", "dynamic", framework=fw, agent_radius=r, follower_noise=r / 2)
    st = eng.reset(np.random.default_rng(0), 2)
    worst = 0.0
    for _ in range(eng.max_cycles):
        lead = eng.leaders
        st, _, _, term, _, info = eng.step(st, track_targets(eng, st, st.goal[:, lead], st.goal_vel[:, lead]))
        assert not term.any()
        worst = max(worst, float(info["goal_distance"].max()))
    assert info["formation_error"].max() < 0.01 and worst < 0.3 and info["success"].all()


def test_vector_env_on_a_large_framework() -> None:
    fw = _scaled(500, 0.25)
    v = FormationVecEnv("hold", num_envs=2, seed=0, framework=fw, agent_radius=_radius(fw))
    obs = v.reset()
    assert obs.shape == (2 * 3, v.engine.obs_dim)
    obs, rew, _, _ = v.step(np.zeros((v.num_envs, v.p), np.float32))
    assert np.isfinite(obs).all() and np.isfinite(rew).all()


def test_render_of_a_large_swarm(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    fw = trilateration(2000, 2, seed=0)
    env = formation_v0.parallel_env(scenario="hold", framework=fw, agent_radius=_radius(fw), render_mode="rgb_array")
    env.reset(seed=0)
    env.step({a: np.full(2, 0.5, np.float32) for a in env.agents})
    img = env.render()
    assert img is not None and img.shape == (640, 640, 3)
    assert len(np.unique(img.reshape(-1, 3), axis=0)) > 5  # agents drawn, not a blank frame
    env.close()


def test_world_grows_for_hold_and_fixed_worlds_refuse_large_frameworks() -> None:
    fw = trilateration(400, 2, seed=0)  # spans about 30 m
    r = _radius(fw)
    eng = Engine("hold", framework=fw, agent_radius=r)
    assert eng.bounds[1, 0] > np.abs(fw.positions).max() * 2
    for name in ("narrow_passage", "obstacle_field"):
        with pytest.raises(FormationError, match=f"scenario '{name}' has obstacles.*spans"):
            Engine(name, framework=fw, agent_radius=r)


def test_touching_agents_warn() -> None:
    fw = trilateration(400, 2, seed=0)
    with pytest.warns(UserWarning, match="agents touch in the nominal formation"):
        Engine("hold", framework=fw, agent_radius=0.1)


def test_no_dense_n_by_n_and_no_growth_at_10000_agents() -> None:
    """n = 10,000 under a 3 GB address-space limit (a dense n x n is 0.8 GB, the folded map far more)."""
    script = textwrap.dedent(
        """
        import json, resource, time, warnings
        resource.setrlimit(resource.RLIMIT_AS, (3 << 30, 3 << 30))
        import numpy as np, scipy.sparse as sp
        from formation_env.core.frameworks import trilateration
        from formation_env.formation_v0 import parallel_env
        fw = trilateration(10000, 2, seed=0)
        t0 = time.perf_counter()
        env = parallel_env(scenario="hold", framework=fw, agent_radius=1e-3, render_mode="rgb_array")
        build = time.perf_counter() - t0
        eng = env.unwrapped.engine
        env.reset(seed=0)
        acts = {a: np.full(2, 0.3, np.float32) for a in env.agents}
        def advance(steps):  # a new episode where one ends (agents 1 mm in radius may touch on the way)
            for _ in range(steps):
                if not env.agents:
                    env.reset()
                env.step(acts)
        advance(20)
        rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        advance(100)
        rss1 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        img = env.render()
        print(json.dumps({"sparse": eng.sparse, "omega_sparse": sp.issparse(eng.omega), "build": build,
                          "resid": "_resid" in vars(eng.affine), "growth_kb": rss1 - rss0,
                          "state": env.state().shape[0], "img": list(img.shape)}))
        """
    )
    env = {**os.environ, "SDL_VIDEODRIVER": "dummy"}
    res = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, cwd=ROOT, env=env, timeout=120)
    assert res.returncode == 0, res.stderr[-2000:]
    out = json.loads(res.stdout.strip().splitlines()[-1])
    assert out["sparse"] and out["omega_sparse"] and not out["resid"]
    assert out["img"] == [640, 640, 3] and out["state"] > 4 * 10000 * 2
    assert out["growth_kb"] < 2048, out


def test_sparse_stress_input_is_kept_sparse(monkeypatch: pytest.MonkeyPatch) -> None:
    from formation_env.core.design import design_stress

    fw = _scaled(300, 0.25)
    om = design_stress(fw, "constructive")
    assert sp.issparse(om)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        eng = Engine("hold", "single_integrator", "stationary", framework=fw, omega=om, agent_radius=_radius(fw))
    assert sp.issparse(eng.omega) and eng.spectral_radius < 1.0
    monkeypatch.setattr(config, "MAX_AGENTS", 1000)  # a sparse omega for the folded path is densified
    assert isinstance(Engine("hold", framework=fw, omega=om, agent_radius=_radius(fw)).omega, np.ndarray)
