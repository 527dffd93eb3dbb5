"""The engine against references: the numpy oracle (tests/oracle.py), the core laws, a per-env loop, the
dense against the sparse path, and the scenarios' reference policies."""

from __future__ import annotations

import pickle
import warnings
from pathlib import Path

import numba
import numpy as np
import pytest
from conftest import random_framework
from oracle import capsule_distance, oracle_step, path_distance, ray_ranges

from agents.scripted import crossing_action, passage_action
from formation_env import formation_v0
from formation_env.core.affine import hold, rotate, scale, shear, translate
from formation_env.core.dynamics import LinearDynamics
from formation_env.core.errors import FormationError, StabilityWarning
from formation_env.env import config, obstacles
from formation_env.env.engine import INFO_KEYS, Engine, offered_combinations
from formation_env.env.obstacles import Capsules, MovingCircle
from formation_env.env.scenarios import REGISTRY
from formation_env.env.scenarios._base import Draw, DrawPlan

SCENARIOS = sorted(REGISTRY)
COMBOS = offered_combinations()


def test_registry_matches_scenario_files():
    folder = Path(REGISTRY["hold"].__module__.replace(".", "/")).parent
    files = {p.stem for p in (Path(__file__).parents[1] / folder).glob("*.py") if not p.stem.startswith("_")}
    assert files == set(REGISTRY)
    for name, cls in REGISTRY.items():
        assert cls.name == name and cls.__doc__ and __import__(cls.__module__, fromlist=["x"]).__doc__


def _compare(new, ref, obs, obs_ref, rew, rew_ref, flags, flags_ref, info, info_ref):
    np.testing.assert_allclose(new.pos, ref.pos, atol=1e-9)
    np.testing.assert_allclose(new.vel, ref.vel, atol=1e-8)
    np.testing.assert_allclose(new.x, ref.x, atol=1e-9)
    np.testing.assert_allclose(new.err, ref.err, atol=1e-9)
    np.testing.assert_allclose(new.goal, ref.goal, atol=1e-9)
    np.testing.assert_allclose(new.goal_vel, ref.goal_vel, atol=1e-8)
    np.testing.assert_array_equal(new.streak, ref.streak)
    for field in ("net_sent", "net_corr", "net_held"):  # with a network: its buffers
        if getattr(ref, field) is not None:
            np.testing.assert_allclose(getattr(new, field), getattr(ref, field), atol=1e-9, err_msg=field)
    for field in ("net_rng", "net_lost"):
        np.testing.assert_array_equal(getattr(new, field), getattr(ref, field), err_msg=field)
    np.testing.assert_allclose(obs, obs_ref, atol=2e-3)  # the marched rays: 1 mm steps over the range
    np.testing.assert_allclose(rew, rew_ref, atol=1e-8)
    for f, g in zip(flags, flags_ref, strict=True):
        np.testing.assert_array_equal(f, g)
    assert set(info) == set(info_ref) == set(INFO_KEYS)
    for key in info:
        got, want = np.asarray(info[key], float), np.asarray(info_ref[key], float)
        if key == "min_clearance":  # the oracle samples swept motions: it may overestimate by a fraction of a step
            assert np.all(got <= want + 1e-9), (got, want)
            np.testing.assert_allclose(got, want, atol=5e-3, err_msg=key)
        else:
            np.testing.assert_allclose(got, want, atol=1e-5, err_msg=key)


def run_against_oracle(eng: Engine, steps: int, B: int, seed: int, amplitude: float = 1.0) -> None:
    """``steps`` engine steps of ``B`` envs with uniform random actions in [-amplitude, amplitude], each against the
    numpy oracle; finished envs are reset (seeded 7 + their row) and go on."""
    rng = np.random.default_rng(seed)
    s = eng.reset(rng, B)
    for _ in range(steps):
        a = rng.uniform(-amplitude, amplitude, (B, eng.n_l, eng.p))
        new, obs, rew, term, trunc, info = eng.step(s, a)
        ref, obs_r, rew_r, term_r, trunc_r, info_r = oracle_step(eng, s, a)
        _compare(new, ref, obs, obs_r, rew, rew_r, (term, trunc), (term_r, trunc_r), info, info_r)
        done = np.flatnonzero(term | trunc)
        s = new
        if done.size:
            s = Engine.replace_rows(s, done, eng.reset_each([np.random.default_rng(int(b) + 7) for b in done]))


@pytest.mark.parametrize("combo", COMBOS, ids=[f"{s}-{d}-{law}" for s, d, law in COMBOS])
def test_step_matches_the_numpy_oracle(combo):
    """Every combination, through resets, fast agents (large actions) and agents leaving the world box."""
    scenario, dynamics, law = combo
    run_against_oracle(Engine(scenario, dynamics, law, u_max=4.0, max_cycles=15), 24, 3, seed=0, amplitude=1.5)


def test_geometry_rows_match_the_oracle():
    rng = np.random.default_rng(1)
    B, n, m = 5, 7, 6
    for d in (2, 3):
        a = rng.uniform(-2, 2, (B, m, d))
        e = rng.uniform(-1, 1, (B, m, d)) * (rng.random((B, m, 1)) < 0.6)  # some of length 0 (circles)
        rad = rng.uniform(0, 0.5, (B, m)) * (rng.random((B, m)) < 0.7)  # some of radius 0 (walls)
        caps = Capsules(a, e, rad)
        p0, p1 = rng.uniform(-3, 3, (B, n, d)), rng.uniform(-3, 3, (B, n, d))
        got = [obstacles.point_clearance(p0[b], a[b], e[b], rad[b]) for b in range(B)]
        np.testing.assert_allclose(got, capsule_distance(p0, caps).min(axis=(1, 2)))
        a1 = a + rng.uniform(-0.5, 0.5, (B, m, d))
        ref = path_distance(p0, p1, caps, Capsules(a1, e, rad)).min(axis=(1, 2))
        got = np.array([obstacles.path_clearance(p0[b], p1[b], a[b], a1[b], e[b], rad[b]) for b in range(B)])
        assert np.all(got <= ref + 1e-12) and np.all(got >= ref - 5e-3)  # sampling overestimates by < 5 mm
    o = rng.uniform(-3, 3, (B, 3, 2))
    caps2 = Capsules(rng.uniform(-2, 2, (B, m, 2)), rng.uniform(-1, 1, (B, m, 2)), rng.uniform(0, 0.4, (B, m)))
    u = obstacles.ray_directions(16)
    got = np.array([[[obstacles.ray_range(*o[b, i], *u[k], caps2.a[b], caps2.e[b], caps2.rad[b], 3.0)
                      for k in range(16)] for i in range(3)] for b in range(B)])  # fmt: skip
    np.testing.assert_allclose(got, ray_ranges(o, u, caps2, 3.0), atol=2e-3)


def test_moving_circles_bounce_inside_the_box():
    bounds = np.array([[-8.0, -5.0], [8.0, 5.0]])
    p = np.array([[[0.0, 4.0, 0.3, 1.0, 0.5]]])  # c0, v, radius
    mc = MovingCircle()
    ts = np.linspace(0, 60, 6001)
    c = np.stack([mc.capsules(p, np.array([t]), bounds).a[0, 0] for t in ts])
    assert c[:, 1].max() == pytest.approx(4.5, abs=1e-3) and c[:, 1].min() == pytest.approx(-4.5, abs=1e-3)
    speed = np.linalg.norm(np.diff(c, axis=0), axis=1) / np.diff(ts)[0]
    np.testing.assert_allclose(np.median(speed), np.hypot(0.3, 1.0), rtol=1e-6)
    disc = np.array([[[0.0, 4.0, 0.0, 1.0, 0.5]]])
    np.testing.assert_allclose(mc.capsules(disc, np.array([1.0]), bounds).a[0, 0], [0.0, 4.0])  # 4 -> 4.5, back to 4
    vel = mc.velocity(p, np.array([1.0]), bounds)[0, 0]
    np.testing.assert_allclose(vel, [0.3, -1.0])  # after the bounce off y = 4.5


def test_draw_each_equals_one_draw_per_generator_bit_for_bit():
    """Runs of uniform draws are one generator call per episode: every entry and every generator's next number
    equal those of ``draw(rng, 1)`` (a degenerate range, normal and sign draws break or do not break a run)."""
    plan = DrawPlan([
        Draw("a", (3,), bounds=(-2.0, 0.5)), Draw("c", (2,), bounds=(1.5, 1.5)),
        Draw("b", bounds=(-np.pi / 12, np.pi / 12)), Draw("s", (2,), "sign"),
        Draw("e", (2, 2), bounds=(0.0, 4.0)), Draw("n", (2, 3), "normal"), Draw("u", (2,)),
    ])  # fmt: skip
    assert [[d.name for d in run] for run, _ in plan._runs] == [["a", "b"], ["s"], ["e"], ["n"], ["u"]]
    each = plan.draw_each([np.random.default_rng(s) for s in range(50)])
    for b in range(50):
        g = np.random.default_rng(b)
        one = plan.draw(g, 1)
        for name, arr in one.items():
            assert each[name].shape == (50, *arr.shape[1:]) and np.array_equal(each[name][b], arr[0]), name
    assert list(each) == [dr.name for dr in plan.draws]
    after = [np.random.default_rng(s) for s in range(3)]
    plan.draw_each(after)
    for s, g in enumerate(after):
        ref = np.random.default_rng(s)
        plan.draw(ref, 1)
        assert g.random() == ref.random()
    for name in SCENARIOS:
        sc = Engine(name).scenario
        rngs = [np.random.default_rng(s) for s in range(6)]
        batch = sc._plan.draw_each(rngs)
        for b in range(6):
            one = sc._plan.draw(np.random.default_rng(b), 1)
            assert all(np.array_equal(batch[k][b], one[k][0]) for k in one), name


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_batch_equals_per_env_loop(scenario):
    eng = Engine(scenario)
    rngs = [np.random.default_rng(s) for s in range(4)]
    batch = eng.reset_each(rngs)
    singles = [eng.reset(np.random.default_rng(s), 1) for s in range(4)]
    act_rng = np.random.default_rng(9)
    for _ in range(25):
        a = act_rng.uniform(-1, 1, (4, eng.n_l, eng.p))
        batch, ob, rb, tb, _, ib = eng.step(batch, a)
        for b in range(4):
            singles[b], o1, r1, t1, _, i1 = eng.step(singles[b], a[b : b + 1])
            np.testing.assert_allclose(batch.pos[b], singles[b].pos[0], atol=1e-12)
            np.testing.assert_allclose(ob[b], o1[0], atol=1e-6)
            np.testing.assert_allclose(rb[b], r1[0], atol=1e-10)
            assert tb[b] == t1[0]
            for key in ib:
                np.testing.assert_allclose(ib[key][b], i1[key][0], atol=1e-10)


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="numba has one thread: no threaded kernel to compare")
def test_threaded_step_equals_the_one_thread_step():
    """From PARALLEL_FROM rows the step runs on numba's threads unless numba has one (what a trainer sets): the
    same rows give the same outputs bit for bit either way."""
    from formation_env.env.engine import PARALLEL_FROM

    eng = Engine("narrow_passage")
    B = PARALLEL_FROM
    a = np.random.default_rng(9).uniform(-1, 1, (B, eng.n_l, eng.p))
    outs = []
    before = numba.get_num_threads()  # a trainer test in this process may have set 1
    for threads in (numba.config.NUMBA_NUM_THREADS, 1):
        numba.set_num_threads(threads)
        try:
            s = eng.reset(np.random.default_rng(3), B)
            for _ in range(20):
                s, obs, rew, term, trunc, _ = eng.step(s, a)
            outs.append((s.pos, obs, rew, term, trunc))
        finally:
            numba.set_num_threads(before)
    for threaded, single in zip(*outs, strict=True):
        np.testing.assert_array_equal(threaded, single)


def test_step_is_pure():
    eng = Engine("moving_obstacles")
    s = eng.reset(np.random.default_rng(3), 2)
    copy = pickle.loads(pickle.dumps(s))
    a = np.full((2, eng.n_l, eng.p), 0.4)
    out1 = eng.step(s, a)
    out2 = eng.step(s, a)
    for f in (f for f in s._fields if f != "params"):
        if getattr(s, f) is not None:
            np.testing.assert_array_equal(getattr(s, f), getattr(copy, f))
    np.testing.assert_array_equal(out1[1], out2[1])
    np.testing.assert_array_equal(eng.observe(s), eng.observe(copy))


@pytest.mark.parametrize(
    ("scenario", "kwargs"),
    [
        ("narrow_passage", {"state_blocks": ["task", "agent_clearance"], "obs_noise": 0.1}),
        ("obstacle_field", {"follower_law": "linear", "network": {"loss": 0.3, "quantise": ("uniform", 0.05)}}),
        ("moving_obstacles", {"state_blocks": ["task", "crossing_windows", "obstacles"]}),
        ("obstacle_field", {"state_blocks": ["task", "agent_clearance"]}),
        ("hold", {}),
        (
            "narrow_passage",
            {"state_blocks": ["task"], "follower_law": "linear", "network": {"delay": 1, "jitter": (0.08, 0.12)}},
        ),
    ],
)
def test_the_state_observing_step_gives_the_commanders_state_to_the_last_bit(scenario, kwargs):
    """``advance(observe="state")`` (what the commander envs run) computes the global state's blocks inside the
    step, without the leaders' observations or their noise: the same next state, rewards and info as the
    leaders' step, and the same global state, to the last bit, as ``global_state`` computes from the state alone."""
    eng = Engine(scenario, **kwargs)
    B = 70  # the threaded step (PARALLEL_FROM)
    s = eng.reset(np.random.default_rng(4), B)
    rng = np.random.default_rng(9)
    for _ in range(40):
        a = rng.uniform(-1, 1, (B, eng.n_l, eng.p))
        new, ctx, rew, term, trunc, info = eng.advance(s, a, np.random.default_rng(1), observe="state")
        ref, ref_ctx, ref_rew, ref_term, ref_trunc, ref_info = eng.advance(s, a, np.random.default_rng(1))
        assert ctx.obs is None and ref_ctx.blocks is None and ref_ctx.obs is not None
        assert (ctx.blocks is None) == (not kwargs.get("state_blocks"))
        for f in (f for f in new._fields if f != "params"):
            if getattr(new, f) is not None:
                np.testing.assert_array_equal(getattr(new, f), getattr(ref, f), err_msg=f)
        for got, want in ((rew, ref_rew), (term, ref_term), (trunc, ref_trunc), (ctx.theta, ref_ctx.theta)):
            np.testing.assert_array_equal(got, want)
        for key in INFO_KEYS:
            np.testing.assert_array_equal(info[key], ref_info[key], err_msg=key)
        np.testing.assert_array_equal(eng.global_state(new, ctx), eng.global_state(new))
        s = new
    with pytest.raises(FormationError, match="observe must be one of"):
        eng.advance(s, a, observe="global")


def test_sparse_path_matches_the_dense_path(monkeypatch):
    """The same framework stepped with a dense stress (the law's map) and, above a lowered threshold, a CSR stress
    (the core law itself): the same states, observations, rewards, and every info key with its unit."""
    from formation_env.core.frameworks import trilateration

    fw = trilateration(90, 2, seed=0)
    runs = {}
    for sparse in (False, True):
        monkeypatch.setattr(config, "MAX_AGENTS", 50 if sparse else 256)
        eng = Engine("hold", "double_integrator", "dynamic", framework=fw, agent_radius=0.01)
        assert eng.sparse == sparse
        s = eng.reset(np.random.default_rng(2), 2)
        rng = np.random.default_rng(5)
        out = []
        for _ in range(10):
            s, obs, rew, _, _, info = eng.step(s, rng.uniform(-1, 1, (2, eng.n_l, eng.p)))
            out.append((s.pos, obs, rew, info, eng.global_state(s)))
        runs[sparse] = out
    for dense, sp_ in zip(runs[False], runs[True], strict=True):
        np.testing.assert_allclose(dense[0], sp_[0], atol=1e-9)
        np.testing.assert_allclose(dense[1], sp_[1], atol=1e-5)
        np.testing.assert_allclose(dense[2], sp_[2], atol=1e-9)
        np.testing.assert_allclose(dense[4], sp_[4], atol=1e-5)
        for key in INFO_KEYS:
            np.testing.assert_allclose(dense[3][key], sp_[3][key], atol=1e-9, err_msg=key)
    info = runs[True][0][3]
    assert info["time"][0] == pytest.approx(0.1)  # seconds on both paths


def test_observation_and_reward_tables_are_the_registries():
    from formation_env.env.observations import OBS_BLOCKS, observation_table
    from formation_env.env.rewards import REWARD_TERMS, TERMS, reward_table

    doc = formation_v0.raw_env.__doc__
    assert all(line.strip() in doc for line in observation_table().splitlines())
    assert all(line.strip() in doc for line in reward_table().splitlines())
    assert REWARD_TERMS == tuple(TERMS) and set(OBS_BLOCKS) >= {"position", "nearest_agents", "agent_id"}
    eng = Engine("narrow_passage")
    assert eng.obs_dim == 34 and next(iter(eng.obs_blocks)) == "position"


def test_sensing_options_for_decentralised_leaders():
    kw = {"observation": ["position", "nearest_agents", "agent_id", "obstacles"], "k_nearest": 2}
    eng = Engine("narrow_passage", **kw, sense_radius=1.5)
    s = eng.reset(np.random.default_rng(0), 1)
    o = eng.observe(s)[0]
    blk = eng.obs_blocks
    np.testing.assert_array_equal(o[:, blk["agent_id"]], np.eye(3))
    near = o[:, blk["nearest_agents"]].reshape(3, 2, 3)
    for li, i in enumerate(eng.leaders):
        dist = np.linalg.norm(s.pos[0] - s.pos[0, i], axis=1)
        dist[i] = np.inf
        order = np.argsort(dist)[:2]
        for slot, j in enumerate(order):
            seen = dist[j] <= 1.5
            assert near[li, slot, 2] == seen
            np.testing.assert_allclose(near[li, slot, :2], (s.pos[0, j] - s.pos[0, i]) * seen, atol=1e-6)
    assert eng.obstacle_range == 1.5
    noisy = Engine("narrow_passage", obs_noise=0.05)
    s = noisy.reset(np.random.default_rng(0), 1)
    clean = noisy.observe(s)
    o1 = noisy.observe(s, np.random.default_rng(1))
    o2 = noisy.observe(s, np.random.default_rng(1))
    np.testing.assert_array_equal(o1, o2)
    delta = (o1 - clean)[0]
    assert np.std(delta[:, noisy.obs_blocks["position"]]) > 0.01
    np.testing.assert_array_equal(delta[:, noisy.obs_blocks["time"]], 0.0)
    with pytest.raises(ValueError, match="observation"):
        Engine("hold", observation=["position", "telepathy"])


def test_moving_obstacles_are_solvable_by_the_reference_policy():
    eng = Engine("moving_obstacles")
    s = eng.reset_each([np.random.default_rng(100 + i) for i in range(48)])
    done = np.zeros(48, dtype=bool)
    success = np.zeros(48, dtype=bool)
    waited = np.zeros(48, dtype=bool)
    for _ in range(eng.max_cycles):
        s, _, _, term, trunc, info = eng.step(s, crossing_action(eng, s))
        assert not np.any(info["collision"] & ~done)
        success |= info["success"] & ~done
        done |= term | trunc
        if done.all():
            break
    assert success.all()
    del waited


def test_moving_obstacles_geometry_and_contacts():
    eng = Engine("moving_obstacles")
    s = eng.reset(np.random.default_rng(0), 64)
    discs = s.params["moving_circles"]
    assert np.all(np.abs(discs[:, :, 2]) == 0) and np.all(np.abs(discs[:, :, 3]) >= 0.5)
    reach = discs[:, :, 0] + discs[:, :, 4]
    assert np.all(s.pos[:, :, 0].max(axis=1) + eng.agent_radius < (discs[:, :, 0] - discs[:, :, 4]).min(axis=1))
    assert np.all(s.goal[:, :, 0].min(axis=1) - eng.agent_radius > reach.max(axis=1))
    # a disc driven onto a resting agent is a contact (the agent is still, the disc moves)
    one = eng.select(s, [0])
    x = one.x.copy()
    x[0, 0, :2] = discs[0, 0, :2] + np.array([0.0, 0.6 * np.sign(discs[0, 0, 3])])
    one = one._replace(x=x, pos=x[..., :2].copy())
    hit = False
    for _ in range(20):
        one, _, _, _, _, info = eng.step(one, np.zeros((1, eng.n_l, eng.p)))
        hit |= bool(info["collision"][0])
    assert hit


def test_an_agent_and_a_disc_that_pass_through_each_other_in_one_step_collide():
    """Each moves 0.115 m (under the 0.141 m swept threshold alone), together 0.23 m: both samples are clear, the
    relative motion crosses the disc, so the swept check must run and find the contact."""
    eng = Engine("moving_obstacles", "single_integrator", "dynamic", u_max=1.15, n_moving=1, follower_noise=0.0)
    s = eng.reset(np.random.default_rng(0), 1)
    lead = int(eng.leaders[0])
    x = s.x - s.x[:, lead : lead + 1]  # the formation moved so that leader 0 is at the origin
    contacts = []
    for vx in (-1.15, 1.15):  # toward the agent (they cross), and away from it (they never meet)
        disc = np.array([[[0.115, 0.0, vx, 0.0, 0.01]]])
        params = {**s.params, "moving_circles": disc}
        one = s._replace(x=x, pos=x.copy(), params=params)
        a = np.zeros((1, eng.n_l, eng.p))
        a[0, :, 0] = 1.0  # the team translates 0.115 m toward +x
        new, _, _, _, _, info = eng.step(one, a)
        assert np.abs(new.pos - one.pos).max() < 0.12  # no agent moved past the threshold on its own
        end_gap = abs(new.pos[0, lead, 0] - (0.115 + vx * eng.dt)) - eng.agent_radius - 0.01
        assert end_gap > 0.0  # clear at both samples
        contacts.append(bool(info["collision"][0]))
    assert contacts == [True, False]


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
        s, _, _, term, trunc, info = eng.step(s, passage_action(eng, s))
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
        act = passage_action(env.engine, env.engine_state)[0]
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


def test_first_compile_of_the_kernels_says_so_once(tmp_path) -> None:
    """An empty numba cache: one line on stderr while the kernels compile; the next process loads them silently."""
    import os
    import subprocess
    import sys

    code = (
        "from formation_env import formation_v0\n"
        "env = formation_v0.parallel_env(scenario='obstacle_field'); env.reset(seed=0)\n"
        "env.step({a: env.action_space(a).sample() for a in env.agents})\n"
    )
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)}
    errs = [
        subprocess.run(
            [sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True, timeout=600
        ).stderr
        for _ in range(2)
    ]
    notice = "compiling the env's step kernels with numba"
    assert errs[0].count(notice) == 1 and notice not in errs[1]


def _lanes_by_grid(circles, lo, hi, step=1e-4):
    """Free lanes of the world's height [lo, hi] outside every disc's shadow on y, by marching a fine grid:
    (centre, width) pairs, widest first."""
    y = np.arange(lo, hi + step / 2, step)
    free = np.all(np.abs(y[:, None] - circles[None, :, 1]) > circles[None, :, 2], axis=1)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], free.astype(int), [0]])))
    runs = [(y[s], y[e - 1]) for s, e in zip(edges[::2], edges[1::2], strict=True)]
    return sorted([((a + b) / 2, b - a) for a, b in runs], key=lambda cw: -cw[1])


def _route_by_hand(x_near, x_far, room, p, g):
    """One agent's route length through a lane whose disc-centre room is ``room`` (lo, hi): to the field's near
    edge at the straight line's height clipped to the room, across, then to the goal (straight once past)."""
    lo, hi = room
    if p[0] > x_far:
        return float(np.hypot(*(g - p)))
    if p[0] < x_near:
        ys = np.clip(p[1] + np.clip((x_near - p[0]) / max(g[0] - p[0], 1e-9), 0, 1) * (g[1] - p[1]), lo, hi)
        return float(np.hypot(x_near - p[0], ys - p[1]) + (x_far - x_near) + np.hypot(g[0] - x_far, g[1] - ys))
    ys = np.clip(p[1], lo, hi)
    return float(abs(ys - p[1]) + (x_far - p[0]) + np.hypot(g[0] - x_far, g[1] - ys))


def test_obstacle_field_task_block_matches_a_marched_grid():
    """The ``task`` block's lanes (``obstacle_field``) equal the free runs of a fine grid over the world's
    height, the route's lane first (of the lanes LANE_WIDTH wide, the least summed route over the team, by
    hand), then the widest; overlapping discs, discs past the world's edge and fewer lanes than N_LANES
    included."""
    from formation_env.env.scenarios.obstacle_field import LANE_WIDTH, N_LANES, ROUTE_MARGIN

    eng = Engine("obstacle_field", observation=["position", "task"])
    s = eng.reset(np.random.default_rng(4), 4)
    circles = s.params["circles"].copy()
    circles[1] = [[0.0, -1.0, 0.5], [0.2, -0.4, 0.4], [-1.0, 3.0, 0.6], [0.5, 4.8, 0.5], [0.9, 2.0, 0.3],
                  [-0.5, -4.5, 0.6]]  # fmt: skip
    circles[2] = [[0.0, -3.0, 2.5], [0.0, 2.5, 2.55], [0, 0, 0.3], [0, 0, 0.3], [0, 0, 0.3], [0, 0, 0.3]]
    s.params["_pvec"] = np.ascontiguousarray(eng.scenario.param_vector({"circles": circles}))  # what the row reads
    obs = eng.observe(s)[..., eng.observer.slices["task"]].astype(float)
    lo_y, hi_y = eng.bounds[:, 1]
    firsts = 0
    for b in range(4):
        c = circles[b]
        pos = s.pos[b]
        b_y = eng.affine.fit(s.pos[b : b + 1])[1][0, 1]
        half = (pos[:, 1].max() - pos[:, 1].min()) / 2 + eng.agent_radius
        lanes = _lanes_by_grid(c, lo_y, hi_y)
        near, far = (c[:, 0] - c[:, 2]).min(), (c[:, 0] + c[:, 2]).max()
        room = eng.agent_radius + ROUTE_MARGIN
        sums = [sum(_route_by_hand(near, far, (yc - w / 2 + room, yc + w / 2 - room), p, g)
                    for p, g in zip(pos, s.goal[b], strict=True)) if w >= LANE_WIDTH else np.inf
                for yc, w in lanes]  # fmt: skip
        if np.isfinite(min(sums, default=np.inf)):
            lanes.insert(0, lanes.pop(int(np.argmin(sums))))
            firsts += int(np.argmin(sums)) > 0
        want_lanes = []
        for q in range(N_LANES):
            if q < len(lanes):
                want_lanes += [lanes[q][0] - b_y, lanes[q][1] / 2 - half]
            else:
                want_lanes += [0.0, -2 * (hi_y - lo_y)]
        for i, a in enumerate(eng.leaders):
            want = [near - pos[a, 0], far - pos[a, 0], *want_lanes]
            np.testing.assert_allclose(obs[b, i], want, atol=2e-4, err_msg=f"env {b}, leader {i}")
    assert firsts >= 1  # at least one env's route lane is not its widest: the order is tested
    with pytest.raises(FormationError, match="obstacle_field: the task observation block is defined in 2D only"):
        Engine("obstacle_field", framework="bipyramid_3d", observation=["position", "task"])


def _moving_task_by_hand(eng, s):
    """``moving_obstacles``' task block from the state (numpy, MovingCircle's own capsules and velocity)."""
    from formation_env.env.scenarios.moving_obstacles import FORECAST

    t, p, mc = eng.time(s), s.params["moving_circles"], MovingCircle()
    b_y = eng.affine.fit(s.pos)[1][:, 1]
    half = 0.5 * (s.pos[:, :, 1].max(1) - s.pos[:, :, 1].min(1)) + eng.agent_radius
    v_y = mc.velocity(p, t, eng.bounds)[:, :, 1]
    ahead = [mc.capsules(p, t + tau, eng.bounds).a for tau in FORECAST]
    rows = []
    for j in range(p.shape[1]):
        rows += [ahead[0][:, j, 0, None] - s.pos[:, eng.leaders, 0]]
        rows += [np.repeat(v[:, None], eng.n_l, 1) for v in (ahead[0][:, j, 1] - b_y, v_y[:, j])]
        rows += [np.repeat((np.abs(c[:, j, 1] - b_y) - p[:, j, 4] - half)[:, None], eng.n_l, 1) for c in ahead]
    lo, hi = eng.scenario.task_feature_bounds()
    return np.clip(np.stack(rows, -1), lo, hi)


@pytest.mark.parametrize("network", [None, {"jitter": (0.05, 0.15)}])
def test_moving_obstacles_task_block_forecasts_the_discs(network):
    """``moving_obstacles``' ``task`` block: per disc its lane's x, its y and velocity, and the room it leaves the
    team's band now and FORECAST s ahead on its bouncing path, at the reset's observation and after every step,
    at the env's time (under a jittered network too, where the time is the sum of the drawn periods)."""
    kw = {} if network is None else {"follower_law": "linear", "network": network}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", StabilityWarning)  # the jittered linear law's margin: not what is tested
        eng = Engine("moving_obstacles", observation=["position", "task"], **kw)
    sl = eng.observer.slices["task"]
    assert sl.stop - sl.start == 3 * 7
    s = eng.reset(np.random.default_rng(3), 6)
    np.testing.assert_allclose(eng.observe(s)[..., sl], _moving_task_by_hand(eng, s), atol=2e-4)
    rng = np.random.default_rng(0)
    bounced = False
    for _ in range(60):
        v_before = MovingCircle().velocity(s.params["moving_circles"], eng.time(s), eng.bounds)
        s, obs, *_ = eng.step(s, 0.3 * rng.uniform(-1, 1, (6, eng.n_l, eng.p)))
        bounced |= bool(
            (MovingCircle().velocity(s.params["moving_circles"], eng.time(s), eng.bounds) != v_before).any()
        )
        np.testing.assert_allclose(obs[..., sl], _moving_task_by_hand(eng, s), atol=2e-4)
    if network is not None:
        assert not np.allclose(eng.time(s), eng.dt * s.k)  # the drawn periods, not k T
    room = obs[..., sl].reshape(6, eng.n_l, 3, 7)[..., 3:]
    assert (room < 0).any() and (room > 0).any()  # discs in the band and out of it
    assert bounced or network is not None


def test_obstacle_field_route_goes_through_the_lane_the_team_takes():
    """``obstacle_field``'s ``route="lane"`` (2D): round a disc through the lane with the shorter routes for
    the whole team, never a lane narrower than LANE_WIDTH, continuous where an agent enters the field, straight
    once past it."""
    from formation_env.env.scenarios.obstacle_field import ROUTE_MARGIN, lane_route

    assert Engine("obstacle_field", route="lane").scenario.route_row is lane_route
    with pytest.raises(FormationError, match="obstacle_field: route must be 'straight', or 'lane' in 2D"):
        Engine("obstacle_field", framework="bipyramid_3d", route="lane")

    disc = np.array([0.0, 0.0, 1.0])  # one circle of radius 1 at the origin: lanes y < -1 and y > 1
    room = 1.0 + 0.1 + ROUTE_MARGIN  # the disc centres' room: |y| >= room

    def routes(ys, goal_ys=None, x=-4.0):
        out = np.zeros(len(ys))
        pos = np.stack([np.full(len(ys), x), ys], -1)
        lane_route(disc, 0.1, pos, np.stack([np.full(len(ys), 4.0), ys if goal_ys is None else goal_ys], -1), out)
        return out

    def via(dy):  # 3 m to the field, 2 m across, 3 m to the goal, offset dy to the room's edge
        return 2 * np.hypot(3.0, dy) + 2.0

    np.testing.assert_allclose(routes(np.array([0.0, 0.3])), [via(room), via(room - 0.3)])  # above
    np.testing.assert_allclose(routes(np.array([-0.5, 0.3])), [via(room - 0.5), via(room + 0.3)])  # below
    for ys in ([2.0], [0.0]):  # entering the field, on and off the lane
        before, inside = routes(np.array(ys), x=-1.0 - 1e-9)[0], routes(np.array(ys), x=-1.0 + 1e-9)[0]
        assert before == pytest.approx(inside, abs=1e-6)
    assert routes(np.array([2.0]), x=-1.0)[0] == pytest.approx(5.0)
    assert routes(np.array([0.0]), x=1.5)[0] == pytest.approx(2.5)  # past the field: straight
    disc = np.array([0.0, -0.95, 0.5, 0.0, 0.95, 0.5])  # a lane 0.9 m wide between two discs: too narrow
    assert routes(np.array([0.0]))[0] == pytest.approx(2 * np.hypot(3.5, 1.45 + 0.15) + 1.0)
    disc = np.array([[0.0, y, 1.0] for y in (-4.0, -2.0, 0.0, 2.0, 4.0)]).ravel()  # no lane in the world's height
    assert routes(np.array([0.5]), goal_ys=np.array([-1.0]))[0] == pytest.approx(np.hypot(8.0, 1.5))  # straight


def _windows_by_hand(eng, s, tau_step=1e-3):
    """``crossing_windows`` from the state: each disc's room on a 1 ms grid (MovingCircle's own capsules), the
    team's extent along x and its mean x-velocity (numpy)."""
    from formation_env.env.scenarios.moving_obstacles import WINDOW_HORIZON as H

    t, p, mc = eng.time(s), s.params["moving_circles"], MovingCircle()
    b_y = eng.affine.fit(s.pos)[1][:, 1]
    half = 0.5 * (s.pos[:, :, 1].max(1) - s.pos[:, :, 1].min(1)) + eng.agent_radius
    taus = np.arange(0.0, H + tau_step / 2, tau_step)
    ys = np.stack([mc.capsules(p, t + tau, eng.bounds).a[:, :, 1] for tau in taus], -1)  # (B, M, T)
    blocked = np.abs(ys - b_y[:, None, None]) - p[:, :, 4, None] - half[:, None, None] < 0
    front = s.pos[:, :, 0].max(1) + eng.agent_radius
    back = s.pos[:, :, 0].min(1) - eng.agent_radius
    vx = s.vel[:, :, 0].mean(1)
    x = mc.capsules(p, t, eng.bounds).a[:, :, 0]
    out = np.full(p.shape[:2] + (4,), H)
    for b in range(p.shape[0]):
        for j in range(p.shape[1]):
            inside = np.flatnonzero(blocked[b, j])
            if inside.size:
                out[b, j, 0] = taus[inside[0]]
                free = np.flatnonzero(~blocked[b, j, inside[0] :])
                out[b, j, 1] = taus[inside[0] + free[0]] if free.size else H
            lo, hi = x[b, j] - p[b, j, 4], x[b, j] + p[b, j, 4]
            if back[b] >= hi:
                out[b, j, 2:] = 0.0
            elif vx[b] <= 0.01:
                out[b, j, 2:] = (0.0 if front[b] >= lo else H), H
            else:
                out[b, j, 2:] = np.minimum([max(0.0, (lo - front[b]) / vx[b]), (hi - back[b]) / vx[b]], H)
    return out.reshape(p.shape[0], -1)


def test_moving_obstacles_crossing_windows_time_the_discs_and_the_team():
    """The ``crossing_windows`` block: when each disc next enters and leaves the team's band (to a few ms of a 1 ms
    scan of its bouncing path) and when the team, at its mean x-velocity, reaches and leaves the disc's strip,
    for every leader, along episodes that move the team, bounce the discs and pass lanes; other scenarios are
    refused by name."""
    from agents.planner import make_planner

    eng = Engine("moving_obstacles", observation=["position", "crossing_windows"])
    sl = eng.observer.slices["crossing_windows"]
    assert sl.stop - sl.start == 4 * 3
    s = eng.reset(np.random.default_rng(5), 8)
    planner = make_planner("moving_obstacles")
    seen = np.zeros(4, bool)  # a window found, a window closing within H, the team approaching, a lane passed
    for k in range(160):
        obs = eng.observe(s)[..., sl]
        want = _windows_by_hand(eng, s)
        for i in range(eng.n_l):
            np.testing.assert_allclose(obs[:, i], want, atol=5e-3, err_msg=f"step {k}, leader {i}")
        w = want.reshape(8, 3, 4)
        seen |= [(w[..., 0] < 6).any(), (w[..., 1] < 6).any(), ((w[..., 2] > 0) & (w[..., 2] < 6)).any(),
                 (w[..., 3] == 0).any()]  # fmt: skip
        s, *_ = eng.step(s, planner(eng, s))
    assert seen.all()
    with pytest.raises(
        FormationError, match="'crossing_windows' reads moving_obstacles' lanes of discs; the scenario is 'obstacle_fi"
    ):
        Engine("obstacle_field", observation=["position", "crossing_windows"])


def _wall_clearance_by_hand(s, radius: float, reach: float) -> np.ndarray:
    """Per env and agent (B, n, 3): the gap to the nearest of the passage's two wall segments and the unit direction
    toward it, from the episode's wall x, gap centre and width (the scenario docstring's geometry), not the engine's
    capsules; beyond ``reach``: reach and 0."""
    B, n = s.pos.shape[:2]
    out = np.zeros((B, n, 3))
    for b in range(B):
        xw, yc, w = (float(s.params[k][b]) for k in ("wall_x", "gap_center", "gap_width"))
        segs = [((xw, -5.0), (xw, yc - w / 2)), ((xw, yc + w / 2), (xw, 5.0))]
        for g in range(n):
            p = s.pos[b, g]
            best, vec = reach, np.zeros(2)
            for a0, a1 in segs:
                a0, a1 = np.array(a0), np.array(a1)
                t = np.clip(np.dot(p - a0, a1 - a0) / np.dot(a1 - a0, a1 - a0), 0.0, 1.0)
                c = a0 + t * (a1 - a0)
                gap = np.linalg.norm(c - p) - radius
                if gap < best:
                    best, vec = gap, (c - p) / np.linalg.norm(c - p)
            out[b, g] = [max(best, -radius), *vec]
    return out


def test_agent_clearance_block_is_each_agents_gap_to_the_nearest_wall():
    """The ``agent_clearance`` block, the same in every leader's row: each agent's gap to the nearest wall segment and
    the direction to it, against the passage's geometry worked by hand, along the planner's episodes (agents far from
    the wall, near its edges in the gap, and past it); in the commander's state after the global state; and with no
    obstacle (``hold``) every gap reads the sensing range."""
    from agents.planner import make_planner

    eng = Engine("narrow_passage", observation=["position", "agent_clearance"], state_blocks=["agent_clearance"])
    sl = eng.observer.slices["agent_clearance"]
    assert sl.stop - sl.start == eng.n * 3
    s = eng.reset(np.random.default_rng(3), 6)
    planner = make_planner("narrow_passage")
    reach = eng.obstacle_range
    closest = np.inf
    for k in range(120):
        want = _wall_clearance_by_hand(s, eng.agent_radius, reach).reshape(6, -1)
        obs = eng.observe(s)[..., sl]
        for i in range(eng.n_l):
            np.testing.assert_allclose(obs[:, i], want, atol=1e-5, err_msg=f"step {k}, leader {i}")
        np.testing.assert_allclose(eng.global_state(s)[:, -3 * eng.n :], want, atol=1e-5)
        closest = min(closest, want[:, 0::3].min())
        s, *_ = eng.step(s, planner(eng, s))
    assert closest < 0.1  # the planner's team passed within 10 cm of a wall edge
    far = Engine("hold", observation=["agent_clearance"])
    o = far.observe(far.reset(np.random.default_rng(0), 2))
    assert (
        np.all(o[..., 0::3] == np.float32(far.obstacle_range))
        and np.all(o[..., 1::3] == 0)
        and np.all(o[..., 2::3] == 0)
    )
