"""The batched engine against references: the core laws, a per-env loop, the generic geometry, AffineImage."""

from __future__ import annotations

import pickle
import warnings
from pathlib import Path

import numpy as np
import pytest
from conftest import random_framework

from formation_env import formation_v0
from formation_env.core.affine import AffineImage, hold, rotate, scale, shear, translate
from formation_env.core.dynamics import LinearDynamics
from formation_env.core.errors import FormationError, StabilityWarning
from formation_env.env import geometry
from formation_env.env.engine import Engine
from formation_env.env.scenarios import REGISTRY
from formation_env.env.scenarios.narrow_passage import scripted_action

SCENARIOS = sorted(REGISTRY)


def test_registry_matches_scenario_files():
    folder = Path(REGISTRY["hold"].__code__.co_filename).parent
    files = {p.stem for p in folder.glob("*.py") if not p.stem.startswith("_")}
    assert files == set(REGISTRY)


@pytest.mark.parametrize(
    ("dynamics", "law"),
    [
        ("single_integrator", "stationary"),
        ("single_integrator", "dynamic"),
        ("single_integrator", "dynamic_distributed"),
        ("single_integrator", "linear"),
        ("double_integrator", "dynamic"),
        ("double_integrator", "dynamic_distributed"),
        ("double_integrator", "linear"),
    ],
)
def test_folded_step_matches_the_core_law(dynamics, law):
    eng = Engine("hold", dynamics, law)
    rng = np.random.default_rng(0)
    s = eng.reset(rng, 4)
    x = s.x + rng.normal(size=s.x.shape)
    mem = None if s.memory is None else rng.normal(size=s.memory.shape)
    s = s._replace(x=x, pos=eng.dynamics.position(x), memory=mem)
    a = rng.uniform(-1.5, 1.5, size=(4, eng.n_l, eng.p))
    new = eng.step(s, a)[0]
    x_ref, mem_ref = eng.law.step(x, np.clip(a, -1, 1) * eng.u_max, mem)
    np.testing.assert_allclose(new.x, x_ref, atol=1e-12)
    np.testing.assert_allclose(new.pos, eng.dynamics.position(x_ref), atol=1e-12)
    if mem is not None:
        np.testing.assert_allclose(new.memory, mem_ref, atol=1e-12)


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_batch_equals_per_env_loop(scenario):
    """B = 3 stepped at once equals three B = 1 engines with the same seeds and actions."""
    eng = Engine(scenario, "double_integrator", "dynamic_distributed", max_cycles=30)
    singles = [eng.reset(np.random.default_rng(seed), 1) for seed in (0, 1, 2)]
    batch = Engine.concat(singles)
    rng = np.random.default_rng(9)
    for _ in range(25):
        a = rng.uniform(-1, 1, size=(3, eng.n_l, eng.p))
        batch, obs, rew, term, trunc, info = eng.step(batch, a)
        for i in range(3):
            singles[i], o1, r1, t1, tr1, inf1 = eng.step(singles[i], a[i : i + 1])
            np.testing.assert_allclose(obs[i], o1[0], rtol=1e-6, atol=1e-6)
            np.testing.assert_allclose(rew[i], r1[0], rtol=1e-10, atol=1e-10)
            assert term[i] == t1[0] and trunc[i] == tr1[0]
            for key, val in info.items():
                np.testing.assert_allclose(val[i], inf1[key][0], rtol=1e-10, atol=1e-10)
            np.testing.assert_allclose(batch.x[i], singles[i].x[0], rtol=1e-12, atol=1e-12)


def test_reset_each_equals_single_resets():
    eng = Engine("obstacle_field", "double_integrator", "dynamic_distributed")
    batch = eng.reset_each([np.random.default_rng(s) for s in (4, 5, 6)])
    for i, seed in enumerate((4, 5, 6)):
        one = eng.reset(np.random.default_rng(seed), 1)
        for f in ("x", "pos", "vel", "memory", "k", "ref", "goal_dist", "err", "streak"):
            np.testing.assert_allclose(getattr(batch, f)[i], getattr(one, f)[0], rtol=1e-13, atol=1e-13)
        assert set(one.params) - set(batch.params) == {"_ep1"}  # the B = 1 step's packed episode arrays
        for key, arr in batch.params.items():
            np.testing.assert_allclose(arr[i], one.params[key][0], rtol=1e-13, atol=1e-13)


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_step_is_pure_and_obs_match_observe(scenario):
    eng = Engine(scenario, "single_integrator", "dynamic")
    s = eng.reset(np.random.default_rng(1), 2)
    copies = {f: np.copy(getattr(s, f)) for f in ("x", "pos", "vel", "k", "ref", "goal_dist", "err", "streak")}
    with pytest.raises(ValueError, match="read-only"):
        s.params["goal_theta" if "goal_theta" in s.params else "b0"][...] = 0.0
    new, obs, *_ = eng.step(s, np.full((2, eng.n_l, eng.p), 0.4))
    for f, v in copies.items():
        np.testing.assert_array_equal(getattr(s, f), v)
    np.testing.assert_allclose(obs, eng.observe(new), atol=1e-6)
    assert obs.dtype == np.float32 and np.all(obs >= eng.obs_low) and np.all(obs <= eng.obs_high)


def _reference_metrics(eng: Engine, prev: np.ndarray, pos: np.ndarray, params: dict) -> tuple[np.ndarray, np.ndarray]:
    """Brute-force min clearance and ray readings from the raw obstacles (circles swept on fast steps)."""
    B, r = pos.shape[0], eng.agent_radius
    iu, ju = np.triu_indices(eng.n, 1)
    clear = np.linalg.norm(pos[:, iu] - pos[:, ju], axis=-1).min(axis=1) - 2 * r
    seg, circ = params["segments"], params["circles"]
    if seg.shape[1]:
        a, e = seg[:, :, 0], seg[:, :, 1] - seg[:, :, 0]
        d = geometry.segment_clearance(pos, a, e, 1.0 / np.sum(e * e, -1))
        clear = np.minimum(clear, d.min(axis=(1, 2)) - r)
    if circ.shape[1]:  # swept in the envs with a fast agent, only: an env's step depends on that env alone
        fast = np.abs(pos - prev).max(axis=(1, 2)) > 2 * r / np.sqrt(eng.d)
        d = np.linalg.norm(pos[:, :, None, :] - circ[:, None, :, :-1], axis=-1) - circ[:, None, :, -1]
        d[fast] = geometry.circle_clearance(prev[fast], pos[fast], circ[fast])
        clear = np.minimum(clear, d.min(axis=(1, 2)) - r)
    rays = None
    if eng.d == 2:
        a = seg[:, :, 0] if seg.shape[1] else np.zeros((B, 0, 2))
        e = seg[:, :, 1] - seg[:, :, 0] if seg.shape[1] else np.zeros((B, 0, 2))
        rays = geometry.ray_ranges(pos[:, eng.leaders], eng._dirs, a, e, circ, eng.sensor_range) / eng.sensor_range
    return clear, rays


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_contacts_sensing_and_error_match_references(scenario):
    eng = Engine(scenario, "single_integrator", "dynamic", max_cycles=60)
    s = eng.reset(np.random.default_rng(2), 6)
    rng = np.random.default_rng(3)
    fit = AffineImage(eng.fw.positions)
    blk = eng.obs_blocks
    for _ in range(40):
        prev = s.pos
        s, obs, _, _, _, info = eng.step(s, rng.uniform(-1, 1, size=(6, eng.n_l, eng.p)))
        clear, rays = _reference_metrics(eng, prev, s.pos, s.params)
        np.testing.assert_allclose(info["min_clearance"], clear, atol=1e-9)
        np.testing.assert_allclose(info["formation_error"], fit.error(s.pos), atol=1e-9)
        gd = np.linalg.norm(s.goal - s.pos, axis=-1)
        np.testing.assert_allclose(info["goal_distance"], gd.max(axis=1), atol=1e-9)
        if rays is not None:
            np.testing.assert_allclose(obs[:, :, blk["obstacles"]], rays, atol=1e-5)
        theta = fit.fit(s.pos)[0].reshape(6, -1)
        np.testing.assert_allclose(obs[:, 0, blk["theta"]], np.clip(theta, -3, 3), atol=1e-5)


def test_sensing_sees_the_wall():
    eng = Engine("narrow_passage", "single_integrator", "dynamic")
    s = eng.reset(np.random.default_rng(0), 1)
    obs = eng.observe(s)[0]
    p = s.pos[0, eng.leaders[0]]
    wall = float(s.params["wall_x"][0])
    ray_plus_x = obs[0, eng.obs_blocks["obstacles"]][0]  # ray 0 points along +x
    expected = min(wall - p[0], eng.sensor_range) / eng.sensor_range
    gap = abs(p[1] - s.params["gap_center"][0]) < s.params["gap_width"][0] / 2
    assert ray_plus_x == pytest.approx(1.0 if gap else expected, abs=1e-6)


def test_fast_step_through_a_wall_is_a_collision():
    """A leader jumping 3 m across the wall in one step collides (swept check), though both samples are clear."""
    eng = Engine(
        "narrow_passage", "single_integrator", "dynamic", u_max=30.0, gap_center=(3.9, 3.9), gap_width=(1.0, 1.0)
    )
    s = eng.reset(np.random.default_rng(0), 1)
    wall = float(s.params["wall_x"][0])
    x = s.x.copy()
    x[0, :, 0] += wall - 1.5 - x[0, :, 0].max()  # whole formation 1.5 m before the wall
    x[0, :, 1] -= x[0, :, 1].mean()  # centred far from the gap
    s = s._replace(x=x, pos=x.copy())
    a = np.zeros((1, eng.n_l, eng.p))
    a[0, 0, 0] = 0.1  # leader 0 moves 0.3 m: still clear
    _, _, _, term, _, info = eng.step(s, a)
    assert not info["collision"][0]
    a[0, 0, 0] = 1.0  # 3 m in one step: lands beyond the wall
    s2, _, _, term, _, info = eng.step(s, a)
    assert s2.pos[0, 0, 0] > wall + 1.0 and info["collision"][0] and term[0]


@pytest.mark.parametrize(
    ("dynamics", "law"),
    [("double_integrator", "dynamic"), ("single_integrator", "stationary"), ("double_integrator", "linear")],
)
def test_narrow_passage_is_solvable_by_the_scripted_policy(dynamics, law):
    eng = Engine("narrow_passage", dynamics, law)
    s = eng.reset(np.random.default_rng(4), 8)
    done = np.zeros(8, dtype=bool)
    success = np.zeros(8, dtype=bool)
    shrunk = np.zeros(8, dtype=bool)
    for _ in range(eng.max_cycles):
        s, _, _, term, trunc, info = eng.step(s, scripted_action(eng, s))
        assert not np.any(info["collision"] & ~done)
        theta = eng.affine.fit(s.pos)[0]
        shrunk |= np.abs(theta[:, 1, 1]) < 0.6
        success |= info["success"] & ~done
        done |= term | trunc
        if done.all():
            break
    assert success.all() and shrunk.all()


def test_scripted_policy_through_the_pettingzoo_env():
    env = formation_v0.parallel_env(scenario="narrow_passage")
    env.reset(seed=12)
    info: dict = {}
    while env.agents:
        act = scripted_action(env.engine, env.engine_state)[0]
        _, _, _, _, infos = env.step({a: act[i] for i, a in enumerate(env.agents)})
        info = infos["leader_0"]
    assert info["success"] and not info["collision"]


def test_nominal_formation_does_not_fit_any_gap():
    eng = Engine("narrow_passage")
    s = eng.reset(np.random.default_rng(0), 256)
    width = np.ptp(eng.fw.positions[:, 1]) + 2 * eng.agent_radius
    assert np.all(s.params["gap_width"] < width)
    assert np.all(s.pos[:, :, 0].max(axis=1) < s.params["wall_x"] - 1.0)
    assert np.all(s.goal[:, :, 0].min(axis=1) > s.params["wall_x"] + 1.0)


def test_maneuver_reference_matches_core_composition():
    eng = Engine("maneuver", max_cycles=400)
    sc = eng.scenario
    s = eng.reset(np.random.default_rng(5), 1)
    p = {k: v for k, v in s.params.items() if not k.startswith("_")}
    H = eng.dt * eng.max_cycles
    th0 = p["theta0"][0]
    m = (
        translate(p["offset"][0], 0.05 * H, 0.95 * H)
        @ hold(2, b=p["b0"][0])
        @ shear(p["shear"][0], 0.6 * H, 0.9 * H)
        @ scale(p["scale"][0], 0.35 * H, 0.65 * H)
        @ rotate(p["angle"][0], 0.1 * H, 0.4 * H)
        @ hold(2, theta=th0)
    )
    for t in (0.0, 3.3, 10.0, 17.7, 25.0, 33.3, 40.0):
        th, b = sc.reference(p, np.array([t]))
        th_ref, b_ref = m(t)
        np.testing.assert_allclose(th[0], th_ref, atol=1e-12)
        np.testing.assert_allclose(b[0], b_ref, atol=1e-12)


@pytest.mark.parametrize("scenario", ["maneuver", "maneuver_3d"])
def test_maneuver_analytic_answer_tracks(scenario):
    """Leaders commanding u = (x*((k+1) T) - x(k)) / T track the reference; the dynamic law brings the followers."""
    eng = Engine(scenario, "single_integrator", "dynamic", u_max=2.0)
    s = eng.reset(np.random.default_rng(6), 4)
    blk, L = eng.obs_blocks, eng.leaders
    for _ in range(eng.max_cycles):
        obs = eng.observe(s)
        u = obs[:, :, blk["goal_velocity"]] + obs[:, :, blk["goal"]] / eng.dt
        s, _, _, term, trunc, info = eng.step(s, u / eng.u_max)
        assert not term.any()
        assert np.max(np.linalg.norm(s.goal[:, L] - s.pos[:, L], axis=-1)) < 1e-4
    assert trunc.all() and info["success"].all()


def test_hold_paper_start_reproduces_the_papers_example():
    """Section 4.3: leaders at rest, followers from (-4, 3) and (-3, -2) reach (-1, 0) and (-2, 0) (T = 1, g = 1)."""
    eng = Engine(
        "hold", "single_integrator", "stationary", dt=1.0, max_cycles=200, law_params={"gain": 1.0}, start="paper"
    )
    s = eng.reset(np.random.default_rng(0), 1)
    np.testing.assert_array_equal(s.pos[0, 3:], [[-4.0, 3.0], [-3.0, -2.0]])
    zero = np.zeros((1, 3, 2))
    for _ in range(180):
        s, _, _, term, _, info = eng.step(s, zero)
        if term[0]:
            break
    assert info["success"][0] and not info["collision"][0]
    np.testing.assert_allclose(s.pos[0, 3:], [[-1.0, 0.0], [-2.0, 0.0]], atol=0.15)


def test_custom_frameworks_in_2d_and_3d_and_custom_dynamics():
    for d in (2, 3):
        rf = random_framework(seed=3, n=d + 4, d=d)
        damped = LinearDynamics(
            np.block([[np.zeros((d, d)), np.eye(d)], [np.zeros((d, d)), -0.5 * np.eye(d)]]),
            np.vstack([np.zeros((d, d)), np.eye(d)]),
            np.hstack([np.eye(d), np.zeros((d, d))]),
        )
        for dyn in ("single_integrator", damped):
            env = formation_v0.parallel_env(
                scenario="hold", framework=rf.fw, omega=rf.omega, dynamics=dyn, max_cycles=20
            )
            obs, _ = env.reset(seed=0)
            assert len(obs) == d + 1
            clone = pickle.loads(pickle.dumps(env))
            np.testing.assert_array_equal(clone.reset(seed=0)[0]["leader_0"], obs["leader_0"])
            for _ in range(20):
                if not env.agents:
                    break
                env.step({a: env.action_space(a).sample() for a in env.agents})
    with pytest.raises(FormationError, match="omega"):
        formation_v0.parallel_env(scenario="hold", framework=rf.fw, omega=rf.omega + 0.01)


def test_unstable_law_warns_with_the_spectral_radius():
    with pytest.warns(StabilityWarning, match="spectral radius"):
        Engine("hold", "double_integrator", "dynamic_distributed", law_params={"rounds": 1})
    with warnings.catch_warnings():
        warnings.simplefilter("error", StabilityWarning)
        eng = Engine("hold", "double_integrator", "dynamic_distributed")
    assert eng.law_params["rounds"] == 2 and eng.spectral_radius < 1


def test_nan_action_in_batch_names_leader_and_entry():
    eng = Engine("hold")
    s = eng.reset(np.random.default_rng(0), 3)
    a = np.zeros((3, eng.n_l, eng.p))
    a[2, 1, 0] = np.nan
    with pytest.raises(ValueError, match=r"leader_1 \(batch entry 2\)"):
        eng.step(s, a)
    with pytest.raises(FormationError, match="shape"):
        eng.step(s, np.zeros((3, eng.n_l)))


def test_geometry_helpers():
    p0 = np.array([[[-1.0, 0.0]]])
    p1 = np.array([[[1.0, 0.0]]])
    a = np.array([[[0.0, -1.0]]])
    e = np.array([[[0.0, 2.0]]])
    assert geometry.segment_crossings(p0, p1, a, e)[0, 0]
    assert not geometry.segment_crossings(p0, p0 * 0.5, a, e)[0, 0]
    circ = np.array([[[0.0, 0.5, 0.2]]])
    assert geometry.circle_clearance(p0, p1, circ)[0, 0, 0] == pytest.approx(0.3)
    rng = geometry.ray_ranges(p0, geometry.ray_directions(4), a, e, circ, 5.0)
    np.testing.assert_allclose(rng[0, 0], [1.0, 5.0, 5.0, 5.0])
    vec = geometry.nearest_obstacle_vectors(
        np.zeros((1, 1, 3)), np.array([[[2.0, 0, 0, 1.0], [0, 0, 9.0, 1.0]]]), 2, 2.0
    )
    np.testing.assert_allclose(vec[0, 0], [[0.5, 0, 0], [0, 0, 0]])
    d = geometry.fibonacci_directions(50)
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0)


def test_dense_path_fits_the_world_to_a_large_framework():
    """A framework too large for the world box (here 200 agents, dense path): ``hold`` grows its world, so the
    agents start inside it; ``narrow_passage`` (fixed walls) refuses it and says what to do."""
    from formation_env.core.frameworks import trilateration

    fw = trilateration(200, 2, seed=0)
    eng = Engine("hold", "single_integrator", "stationary", framework=fw, agent_radius=0.01)
    assert not eng.sparse and eng.bounds[1, 0] > 7.0
    s = eng.reset(np.random.default_rng(0), 2)
    lo, hi = eng.bounds
    assert np.all(s.pos > lo) and np.all(s.pos < hi)
    info = eng.step(s, np.zeros((2, eng.n_l, eng.p)))[5]
    assert not info["out_of_bounds"].any()
    with pytest.raises(FormationError, match="scale its positions"):
        Engine("narrow_passage", framework=fw, agent_radius=0.01)


@pytest.mark.parametrize("scenario", ["obstacle_field", "narrow_passage"])
@pytest.mark.parametrize("compiled", [True, False])
def test_an_envs_step_depends_on_that_env_alone(scenario, compiled):
    """Each row of a batched step equals the step of that env batched with a copy of itself, fast agents (the
    swept obstacle checks) included: no env's info or observation depends on the others in its batch."""
    eng = Engine(scenario, "single_integrator", "dynamic", max_cycles=60)
    eng._kbatch = compiled and eng._kbatch
    B = 6
    s = eng.reset(np.random.default_rng(2), B)
    rng = np.random.default_rng(3)
    fast_steps = 0
    for _ in range(30):
        a = rng.uniform(-1, 1, size=(B, eng.n_l, eng.p))
        prev = s.pos
        new, obs, rew, term, trunc, info = eng.step(s, a)
        fast = np.abs(new.pos - prev).max(axis=(1, 2)) > 2 * eng.agent_radius / np.sqrt(eng.d)
        fast_steps += int(fast.any() and not fast.all())
        for b in range(B):
            pair = eng.select(s, [b, b])
            _, obs2, rew2, term2, trunc2, info2 = eng.step(pair, a[[b, b]])
            np.testing.assert_array_equal(obs2[0], obs[b])
            np.testing.assert_array_equal(rew2[0], rew[b])
            assert (term2[0], trunc2[0]) == (term[b], trunc[b])
            for key, val in info.items():
                np.testing.assert_array_equal(np.asarray(info2[key])[0], np.asarray(val)[b], err_msg=key)
        s = new
    assert fast_steps > 0  # the case that coupled the envs: some envs fast, others not


@pytest.mark.parametrize("scenario", ["narrow_passage", "obstacle_field", "hold"])
def test_reset_each_observed_gives_the_observations_of_the_new_episodes(scenario):
    """``reset_each_observed`` (the vec env's auto-resets) returns ``reset_each``'s episodes, and observations
    equal to ``observe`` of them, taken from the reset's own measurement."""
    eng = Engine(scenario, "double_integrator", "dynamic")
    state, obs = eng.reset_each_observed([np.random.default_rng(s) for s in range(5)])
    want = eng.reset_each([np.random.default_rng(s) for s in range(5)])
    np.testing.assert_array_equal(state.pos, want.pos)
    np.testing.assert_array_equal(obs, eng.observe(want))
    assert obs.shape == (5, eng.n_l, eng.obs_dim) and obs.dtype == np.float32


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_single_reset_through_the_compiled_draws_is_the_reference_reset(scenario):
    """``reset(rng, 1)`` takes ``reset_each([rng])`` where the draws are compiled: the same bits as the episode of
    the scenario's own ``reset(rng, 1)`` (the numpy reference), and the generator left at the same place."""
    eng = Engine(scenario)
    for seed in range(20):
        g, g_ref = np.random.default_rng(seed), np.random.default_rng(seed)
        got = eng.reset(g, 1)
        want = eng._reset_from(dict(eng.scenario.reset(g_ref, 1)))[0]
        for f in ("x", "pos", "vel", "k", "ref", "goal_dist", "err", "streak"):
            assert np.array_equal(getattr(got, f), getattr(want, f)), f
        assert set(got.params) == set(want.params)
        for key, arr in want.params.items():
            assert np.array_equal(got.params[key], arr), key
        assert g.random() == g_ref.random()
