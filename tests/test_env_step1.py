"""The single-env step ``Engine.step1`` (compiled fast path) against the batched numpy step, its reference; and the
other compiled kernels (batched step, global state, reset) against their numpy code."""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np
import pytest
from conftest import crowded_followers

from formation_env.core.errors import ControlDimension, FormationError
from formation_env.env import _kernel
from formation_env.env.engine import Engine, EngineState, offered_combinations
from formation_env.env.scenarios import REGISTRY


def _batched(state: EngineState) -> EngineState:
    """The same state without the B = 1 packed episode arrays, so that ``step`` takes the batched code."""
    return state._replace(params={k: v for k, v in state.params.items() if k != "_ep1"})


def _compare(eng: Engine, seed: int, steps: int) -> int:
    """Step ``step1`` and the batched step side by side with the same actions (some far out of range, so that
    agents go fast and leave the box); return how many steps took the fast path."""
    rng = np.random.default_rng(seed)
    fast = eng.reset(np.random.default_rng(seed), 1)
    ref = _batched(fast)
    used = 0
    for t in range(steps):
        scale = 30.0 if t % 7 == 0 else 1.2
        a = rng.uniform(-scale, scale, (1, eng.n_l, eng.p))
        used += "_ep1" in fast.params
        s1, o1, r1, te1, tr1, i1 = eng.step1(fast, a[0])
        s2, o2, r2, te2, tr2, i2 = eng.step(ref, a)
        np.testing.assert_allclose(o1, o2[0], rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(r1, r2[0], rtol=1e-9, atol=1e-9)
        assert (te1, tr1) == (bool(te2[0]), bool(tr2[0]))
        assert set(i1) == set(i2)
        for key, val in i2.items():
            np.testing.assert_allclose(i1[key], val[0], rtol=1e-9, atol=1e-9, err_msg=key)
            assert np.asarray(i1[key]).dtype.kind == val.dtype.kind or key in ("time",), key
        for f in ("x", "pos", "vel", "memory", "k", "ref", "goal_dist", "err", "streak"):
            if getattr(s2, f) is not None:
                np.testing.assert_allclose(getattr(s1, f), getattr(s2, f), rtol=1e-9, atol=1e-9, err_msg=f)
                assert getattr(s1, f).shape == getattr(s2, f).shape, f
        fast, ref = s1, s2
        if te1 or tr1:
            fast = eng.reset(rng, 1)
            ref = _batched(fast)
    return used


@pytest.mark.parametrize(("scenario", "dynamics", "law"), offered_combinations())
def test_step1_equals_the_batched_step(scenario, dynamics, law):
    eng = Engine(scenario, dynamics, law, max_cycles=40)
    used = _compare(eng, seed=3, steps=90)
    expect_fast = _kernel.AVAILABLE and not eng.scenario.moving_goal
    assert eng._fast1 == expect_fast
    assert (used == 90) == expect_fast and (used == 0) == (not expect_fast)


def test_step1_follows_a_new_max_cycles():
    """Setting ``max_cycles`` after construction rebuilds step1's packed constants: it truncates at the new count,
    and the time entries of its observations and global states are those of the batched step."""
    eng = Engine("hold", max_cycles=400)
    eng.max_cycles = 6
    fast = eng.reset(np.random.default_rng(0), 1)
    ref = _batched(fast)
    a = np.zeros((eng.n_l, eng.p))
    for t in range(6):
        g1 = eng.step1_global(fast, a)[1]
        s1, o1, _, te1, tr1, _ = eng.step1(fast, a)
        s2, o2, _, te2, tr2, _ = eng.step(ref, a[None])
        assert (te1, tr1) == (bool(te2[0]), bool(tr2[0])) == (False, t == 5)
        np.testing.assert_allclose(o1, o2[0], rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(g1, eng.global_state(s2)[0], rtol=1e-6, atol=1e-6)
        assert o1[:, eng.obs_blocks["time"]] == pytest.approx((t + 1) / 6)
        fast, ref = s1, s2


def test_step1_without_the_kernel_takes_the_batched_step(monkeypatch):
    monkeypatch.setattr(_kernel, "AVAILABLE", False)
    eng = Engine("narrow_passage", max_cycles=30)
    assert not eng._fast1
    assert "_ep1" not in eng.reset(np.random.default_rng(0), 1).params
    assert _compare(eng, seed=1, steps=40) == 0


def test_step_at_b1_uses_step1_and_matches_its_arrays():
    eng = Engine("narrow_passage")
    s = eng.reset(np.random.default_rng(2), 1)
    a = np.full((1, eng.n_l, eng.p), 0.3)
    new, obs, rew, term, trunc, info = eng.step(s, a)
    new1, obs1, *_ = eng.step1(s, a[0])
    assert obs.shape == (1, eng.n_l, eng.obs_dim) and obs.dtype == np.float32
    np.testing.assert_array_equal(obs[0], obs1)
    assert rew.shape == (1, eng.n_l) and term.shape == trunc.shape == (1,)
    assert info["control_effort"].shape == (1, eng.n_l) and info["success"].dtype == bool
    np.testing.assert_array_equal(new.x, new1.x)


def test_step1_without_observation_skips_only_the_observation():
    eng = Engine("obstacle_field", "single_integrator", "stationary")
    s = eng.reset(np.random.default_rng(4), 1)
    a = np.full((eng.n_l, eng.p), 0.5)
    full = eng.step1(s, a)
    bare = eng.step1(s, a, observe=False)
    assert bare[1] is None and full[1] is not None
    assert full[2:5] == bare[2:5] and full[5] == bare[5]
    np.testing.assert_array_equal(full[0].x, bare[0].x)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_step1_refuses_nan_and_inf_naming_the_leader(bad):
    eng = Engine("narrow_passage")
    s = eng.reset(np.random.default_rng(0), 1)
    before = s.x.copy()
    a = np.zeros((eng.n_l, eng.p))
    a[1, 0] = bad
    with pytest.raises(ValueError, match="leader_1"):
        eng.step1(s, a)
    np.testing.assert_array_equal(s.x, before)


def test_step1_clips_huge_finite_actions_and_checks_the_shape():
    eng = Engine("hold", "single_integrator", "stationary")
    s = eng.reset(np.random.default_rng(0), 1)
    huge = eng.step1(s, np.full((eng.n_l, eng.p), 1e300))
    one = eng.step1(s, np.ones((eng.n_l, eng.p)))
    np.testing.assert_array_equal(huge[0].x, one[0].x)
    assert huge[5]["control_effort"] == one[5]["control_effort"]
    with pytest.raises(ControlDimension, match="shape"):
        eng.step1(s, np.zeros((eng.n_l + 1, eng.p)))


@pytest.mark.parametrize(("scenario", "dynamics", "law"), offered_combinations())
def test_compiled_batch_step_equals_the_numpy_step(scenario, dynamics, law):
    """``_step_batch`` (compiled per env) against the folded numpy step, B = 4, through resets, fast agents and
    agents leaving the box."""
    if not _kernel.AVAILABLE:
        pytest.skip("numba is not installed")
    eng = Engine(scenario, dynamics, law, max_cycles=40)
    rng = np.random.default_rng(1)
    fast = ref = eng.reset(np.random.default_rng(5), 4)
    guarded = 0
    for t in range(90):
        scale = 30.0 if t % 7 == 0 else 1.2
        a = rng.uniform(-scale, scale, (4, eng.n_l, eng.p))
        eng._kbatch = True
        s1, o1, r1, te1, tr1, i1 = eng.step(fast, a)
        eng._kbatch = False
        s2, o2, r2, te2, tr2, i2 = eng.step(ref, a)
        np.testing.assert_allclose(o1, o2, rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(r1, r2, rtol=1e-9, atol=1e-9)
        np.testing.assert_array_equal(te1, te2)
        np.testing.assert_array_equal(tr1, tr2)
        for key, val in i2.items():
            np.testing.assert_allclose(i1[key], val, rtol=1e-9, atol=1e-9, err_msg=key)
            assert i1[key].dtype.kind == val.dtype.kind, key
        for f in ("x", "pos", "vel", "memory", "k", "ref", "goal_dist", "err", "streak"):
            if getattr(s2, f) is not None:
                np.testing.assert_allclose(getattr(s1, f), getattr(s2, f), rtol=1e-9, atol=1e-9, err_msg=f)
        guarded += bool(i2["out_of_bounds"].any() or i2["collision"].any())
        fast, ref = s1, s2
        if (te1 | tr1).any():
            fast = ref = eng.reset(rng, 4)
    if scenario in ("narrow_passage", "obstacle_field"):
        assert guarded > 0  # contacts or the world box were exercised


def test_compiled_steps_keep_one_signature_each():
    """Every scenario, B = 1 and B = 4, with and without law memory, calls each kernel with the same argument
    types and layouts: one compiled version each (a second would cost a compile of several seconds)."""
    if not _kernel.AVAILABLE:
        pytest.skip("numba is not installed")
    for scenario, dynamics, law in [
        ("narrow_passage", "double_integrator", "dynamic_distributed"),
        ("obstacle_field", "single_integrator", "stationary"),
        ("maneuver_3d", "double_integrator", "linear"),
        ("hold", "single_integrator", "dynamic"),
    ]:
        eng = Engine(scenario, dynamics, law)
        for B in (1, 4):
            s = eng.reset(np.random.default_rng(0), B)
            for _ in range(3):
                s = eng.step(s, np.full((B, eng.n_l, eng.p), 0.2))[0]
            sub = eng.select(s, [0])  # a sub-batch of one, without the packed episode arrays
            eng.step(sub, np.zeros((1, eng.n_l, eng.p)))
    for kernel in (_kernel.step1, _kernel.step_end_rows, _kernel.linear_rows, _kernel.measure_rows):
        assert len(kernel.signatures) == 1, kernel
    assert len(_kernel.step_rows.signatures) <= 1  # (called alone only for a scenario's own success test)


@pytest.mark.parametrize("scenario", ["narrow_passage", "obstacle_field", "hold"])
def test_batched_step_is_the_same_on_any_number_of_threads(scenario):
    """B = 300 envs split over 1, 2 and 3 threads (chunks of >= 128 rows: 1, 2 and 2 chunks) give the same
    bits, with walls, circles (sensing in numpy) and no obstacles."""
    if not _kernel.AVAILABLE:
        pytest.skip("numba is not installed")
    results = []
    for threads in (1, 2, 3):
        eng = Engine(scenario, "double_integrator", "dynamic", max_cycles=30, num_threads=threads)
        rng = np.random.default_rng(2)
        s = eng.reset(np.random.default_rng(9), 300)
        outs = [eng.observe(s)]
        for _ in range(12):
            s, o, r, te, tr, info = eng.step(s, rng.uniform(-1.5, 1.5, (300, eng.n_l, eng.p)))
            outs += [o, r, te, tr, s.x, s.pos, s.vel, s.memory, info["min_clearance"], info["out_of_bounds"]]
        results.append(outs)
    for other in results[1:]:
        for a, b in zip(results[0], other, strict=True):
            np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("from_x", [True, False])
@pytest.mark.parametrize("law", ["dynamic", "dynamic_distributed"])
def test_linear_rows_has_the_bits_of_the_dense_product(law, from_x):
    """``linear_rows`` (Mc's nonzeros over blocks of envs) gives the same bits as the dense product z Mc summed
    row by row in z's order, then gathered by ``_take``; on rows [3, 197) of 200 (blocks cut mid-way), with
    and without the law's memory, with pos' and vel' copied from x' (``_pv``) and read from the block."""
    if not _kernel.AVAILABLE:
        pytest.skip("numba is not installed")
    eng = Engine("narrow_passage", "double_integrator", law)
    B, rng = 200, np.random.default_rng(4)
    x = rng.normal(size=(B, eng.n * eng.q))
    a = rng.uniform(-1, 1, (B, eng.n_l * eng.p))
    mem = rng.normal(size=(B, eng.mem_dim))
    ref = rng.normal(size=(B, 2 * eng.n * eng.d + 2))
    k = rng.integers(0, 400, B)
    outs = [
        np.zeros((B, eng.n * eng.q)),
        np.zeros((B, eng.mem_dim)),
        np.zeros((B, eng.n, eng.d)),
        np.zeros((B, eng.n, eng.d)),
    ]
    ref_o = np.zeros_like(ref)
    assert eng._pv.size == 2 * eng.n * eng.d  # the integrators: pos' and vel' are columns of x'
    pv = eng._pv if from_x else eng._pv[:0]
    _kernel.linear_rows(3, 197, x, a, mem, ref, k, *eng._Mc_csc, eng._take, pv, *outs[:2], ref_o, *outs[2:])
    z = np.hstack([x, a, mem, ref])[:, : eng._Mc.shape[0]]
    y = np.zeros((B, eng._Mc.shape[1]))
    for i in range(z.shape[1]):  # each column summed from zero in z's order, as a dense loop does
        y = y + z[:, i : i + 1] * eng._Mc[i]
    want = y[:, eng._take]
    got = np.hstack([o.reshape(B, -1) for o in outs])
    assert np.array_equal(got[3:197], want[3:197])
    assert not got[:3].any() and not got[197:].any()
    assert np.array_equal(ref_o[3:197, :-1], ref[3:197, :-1]) and np.array_equal(ref_o[3:197, -1], k[3:197])
    assert not ref_o[:3].any() and not ref_o[197:].any()
    assert np.count_nonzero(eng._Mc) == eng._Mc_csc[2].size < eng._Mc.size / 2  # most of Mc is zero: skipped


def test_rows_kernels_split_into_contiguous_chunks(monkeypatch):
    """``run_rows`` covers [0, B) once, in at most ``threads`` chunks of at least MIN_ROWS_PER_THREAD rows."""
    seen: list[tuple[int, int]] = []
    m = _kernel.MIN_ROWS_PER_THREAD
    for B, threads, chunks in ((1, 4, 1), (2 * m - 1, 2, 1), (2 * m, 2, 2), (5 * m, 3, 3), (5 * m + 7, 8, 5)):
        seen.clear()
        _kernel.run_rows(lambda b0, b1: seen.append((b0, b1)), B, threads)
        spans = sorted(seen)
        assert len(spans) == chunks
        assert spans[0][0] == 0 and spans[-1][1] == B
        assert all(a[1] == b[0] for a, b in itertools.pairwise(spans))
        assert min(b1 - b0 for b0, b1 in spans) >= min(m, B)


@pytest.mark.parametrize("bad", [0, -1, 1.5])
def test_num_threads_must_be_a_positive_integer(bad):
    with pytest.raises(FormationError, match="num_threads"):
        Engine("hold", num_threads=bad)


@pytest.mark.parametrize("scenario", ["narrow_passage", "obstacle_field", "maneuver_3d"])
def test_compiled_global_state_equals_numpy(scenario, monkeypatch):
    eng = Engine(scenario, "double_integrator", "dynamic")
    for B in (1, 5):
        s = eng.reset(np.random.default_rng(0), B)
        for t in range(20):
            s = eng.step(s, np.random.default_rng(t).uniform(-1, 1, (B, eng.n_l, eng.p)))[0]
            fast = eng.global_state(s)
            with monkeypatch.context() as m:
                m.setattr(_kernel, "AVAILABLE", False)
                ref = eng.global_state(s)
            assert fast.dtype == ref.dtype == np.float32 and fast.shape == (B, eng.state_dim)
            np.testing.assert_allclose(fast, ref, rtol=1e-6, atol=1e-6)
            assert np.all(fast >= eng.state_low) and np.all(fast <= eng.state_high)


def test_step_infos_are_scalar_and_copy_cheaply():
    """The commander's and the PettingZoo env's infos hold immutable scalars only, so that their deepcopy (SB3's
    DummyVecEnv makes one per step) can be a plain copy."""
    import copy

    import gymnasium as gym

    import formation_env  # noqa: F401  (registers the commander)
    from formation_env import formation_v0
    from formation_env.env.engine import StepInfo

    cmd = gym.make("formation_env/FormationCommander-v0")
    cmd.reset(seed=0)
    info = cmd.step(cmd.action_space.sample())[4]
    pz = formation_v0.parallel_env()
    pz.reset(seed=0)
    infos = pz.step({a: pz.action_space(a).sample() for a in pz.agents})[4]
    for inf in [info, *infos.values()]:
        assert isinstance(inf, StepInfo)
        assert all(isinstance(v, bool | int | float) for v in inf.values()), inf
        dup = copy.deepcopy(inf)
        assert dup == inf and dup is not inf and type(dup) is StepInfo
        dup["success"] = "changed"
        assert inf["success"] != "changed"


@pytest.mark.parametrize(("scenario", "dynamics", "law"), offered_combinations()[::2])
def test_compiled_observe_and_reset_equal_numpy(scenario, dynamics, law):
    """``observe`` and the reset's goal distances and formation error, compiled against numpy."""
    if not _kernel.AVAILABLE:
        pytest.skip("numba is not installed")
    eng = Engine(scenario, dynamics, law)
    eng._kbatch = False
    ref = eng.reset(np.random.default_rng(7), 3)
    eng._kbatch = True
    fast = eng.reset(np.random.default_rng(7), 3)
    np.testing.assert_allclose(fast.goal_dist, ref.goal_dist, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(fast.err, ref.err, rtol=1e-9, atol=1e-12)
    s = fast
    for t in range(5):
        s = eng.step(s, np.random.default_rng(t).uniform(-1, 1, (3, eng.n_l, eng.p)))[0]
        got = eng.observe(s)
        eng._kbatch = False
        want = eng.observe(s)
        eng._kbatch = True
        assert got.dtype == want.dtype == np.float32
        np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("where", ["worker", "caller"])
def test_run_rows_raises_a_chunks_error_and_goes_on(where):
    """An error in any chunk (a worker's or this thread's) reaches the caller once every chunk has stopped, and
    the worker threads serve the next call."""
    m = _kernel.MIN_ROWS_PER_THREAD

    def fn(b0: int, b1: int, out: np.ndarray) -> None:
        if (b0 > 0) == (where == "worker"):
            raise ZeroDivisionError(f"rows {b0}-{b1}")
        out[b0:b1] = 1.0

    out = np.zeros(2 * m)
    with pytest.raises(ZeroDivisionError, match="rows"):
        _kernel.run_rows(fn, 2 * m, 2, out)
    assert out.sum() == m  # the other chunk ran to its end
    _kernel.run_rows(lambda b0, b1, o: o.__setitem__(slice(b0, b1), 2.0), 2 * m, 2, out)
    assert np.all(out == 2.0)


def _step_large_batch(queue) -> None:  # in a forked child: the parent's worker threads do not exist here
    eng = Engine("narrow_passage", num_threads=2)
    s = eng.reset(np.random.default_rng(0), 2 * _kernel.MIN_ROWS_PER_THREAD)
    queue.put(float(eng.step(s, np.zeros((s.x.shape[0], eng.n_l, eng.p)))[1].sum()))


def test_threaded_step_works_in_a_forked_child():
    """The worker threads are made again in a child forked after the parent used them (else: a hang)."""
    import multiprocessing as mp

    if not _kernel.AVAILABLE or "fork" not in mp.get_all_start_methods():
        pytest.skip("numba or the fork start method is missing")
    eng = Engine("narrow_passage", num_threads=2)
    s = eng.reset(np.random.default_rng(0), 2 * _kernel.MIN_ROWS_PER_THREAD)
    expect = float(eng.step(s, np.zeros((s.x.shape[0], eng.n_l, eng.p)))[1].sum())  # the pool exists now
    ctx = mp.get_context("fork")
    queue = ctx.Queue()
    child = ctx.Process(target=_step_large_batch, args=(queue,))
    child.start()
    child.join(timeout=60)
    if child.is_alive():
        child.kill()
        pytest.fail("the threaded step hung in a forked child")
    assert child.exitcode == 0
    assert queue.get(timeout=5) == expect


# ---------------------------------------------------------------------------- the reset's compiled parts
def _start_engine(scenario: str, kwargs: dict) -> Engine:
    """The engine of a ``START_CASES`` entry (framework "crowded": ``crowded_followers``)."""
    if kwargs.get("framework") == "crowded":
        kwargs = {**kwargs, "framework": crowded_followers()}
    return Engine(scenario, **kwargs)


START_CASES = [
    ("hold", {}),
    ("hold", {"framework": "bipyramid_3d"}),
    ("hold", {"framework": "crowded"}),
    ("maneuver", {}),
    ("maneuver_3d", {}),
    ("narrow_passage", {}),
    ("obstacle_field", {}),
    ("obstacle_field", {"framework": "bipyramid_3d"}),
]


@pytest.mark.parametrize(("scenario", "kwargs"), START_CASES)
def test_compiled_start_test_equals_numpy(scenario, kwargs, monkeypatch):
    """``_kernel.noisy_starts`` against the numpy ``Scenario._noisy``: the same positions and verdicts, exactly
    (a verdict decides whether a generator draws again)."""
    if not _kernel.AVAILABLE:
        pytest.skip("numba is not installed")
    from formation_env.env.scenarios._base import affine_batch

    sc = _start_engine(scenario, kwargs).scenario
    B = 400
    pose = sc.build(sc._plan.draw(np.random.default_rng(1), B))[1]
    base = affine_batch(sc.r, *pose)
    todo = np.flatnonzero(np.random.default_rng(2).random(B) < 0.7)  # a subset of the episodes
    noise = sc._noise_plan.draw(np.random.default_rng(3), todo.size)
    for spread in (0.3, 1.5):  # a ball wide enough that some starts are too crowded
        got = base.copy()
        got_ok = sc._noisy(got, base, todo, noise, spread)
        want = base.copy()
        with monkeypatch.context() as m:
            m.setattr(_kernel, "AVAILABLE", False)
            want_ok = sc._noisy(want, base, todo, noise, spread)
        np.testing.assert_array_equal(got_ok, want_ok)
        np.testing.assert_array_equal(got, want)
    assert 0 < want_ok.sum() < todo.size  # both verdicts exercised


def test_compiled_wall_maps_equal_numpy(monkeypatch):
    """``_kernel.wall_maps`` against the numpy ``Engine._wall_maps`` on random walls, with walls along x and y
    (rays parallel to them) among them."""
    if not _kernel.AVAILABLE:
        pytest.skip("numba is not installed")
    eng = Engine("narrow_passage")
    seg = np.random.default_rng(0).uniform(-5.0, 5.0, (200, 3, 2, 2))
    seg[0, 0, 1] = seg[0, 0, 0] + [3.0, 0.0]
    seg[1, 2, 1] = seg[1, 2, 0] + [0.0, -2.0]
    got = eng._wall_maps(seg)
    monkeypatch.setattr(_kernel, "AVAILABLE", False)
    want = eng._wall_maps(seg)
    for g, w in zip(got, want, strict=True):
        assert g.shape == w.shape
        np.testing.assert_allclose(g, w, rtol=1e-14, atol=1e-14)


@pytest.mark.parametrize("scenario", sorted(REGISTRY))
def test_compiled_resets_equal_numpy(scenario, monkeypatch):
    """``reset`` and ``reset_each`` with the reset's compiled parts (start test, wall and ray maps) against numpy:
    the same episodes, and every generator left in the same state."""

    def resets(eng: Engine) -> tuple[EngineState, EngineState, list[Any]]:
        rngs = [np.random.default_rng(s) for s in range(24)]
        each = eng.reset_each(rngs)
        return each, eng.reset(np.random.default_rng(5), 7), [g.bit_generator.state for g in rngs]

    if not _kernel.AVAILABLE:
        pytest.skip("numba is not installed")
    eng = Engine(scenario)
    fast = resets(eng)
    monkeypatch.setattr(_kernel, "AVAILABLE", False)
    ref = resets(eng)
    assert fast[2] == ref[2]
    for got, want in zip(fast[:2], ref[:2], strict=True):
        for f in ("x", "pos", "vel", "k", "ref", "goal_dist", "err", "streak"):
            np.testing.assert_array_equal(getattr(got, f), getattr(want, f), err_msg=f)
        assert set(got.params) == set(want.params)
        for key, arr in want.params.items():
            np.testing.assert_allclose(got.params[key], arr, rtol=1e-14, atol=1e-14, err_msg=key)


def test_reset_kernels_keep_one_signature_each():
    """Every scenario, batched and per-generator resets, B = 1 and B > 1: one compiled version of each reset
    kernel."""
    if not _kernel.AVAILABLE:
        pytest.skip("numba is not installed")
    for scenario, kwargs in START_CASES:
        eng = _start_engine(scenario, kwargs)
        for B in (1, 3):
            eng.reset(np.random.default_rng(0), B)
            eng.reset_each([np.random.default_rng(s) for s in range(B)])
    assert len(_kernel.noisy_starts.signatures) == 1
    assert len(_kernel.wall_maps.signatures) == 1


@pytest.mark.parametrize("scenario", ["narrow_passage", "obstacle_field"])
def test_swept_rows_equal_the_numpy_swept_checks(scenario):
    """``_kernel.swept_rows`` (the batched step's tunnelling checks) marks the same envs and lowers the clearance
    as ``Engine._swept`` does, in the envs flagged fast only, with walls and with circles."""
    if not _kernel.AVAILABLE:
        pytest.skip("numba is not installed")
    eng = Engine(scenario, "double_integrator", "dynamic")
    B, rng = 64, np.random.default_rng(5)
    s = eng.reset(np.random.default_rng(1), B)
    prev = np.ascontiguousarray(s.pos)
    pos = prev + rng.normal(scale=3.0, size=prev.shape)  # long moves: many cross a wall or graze a circle
    flags = np.zeros((B, 2), dtype=bool)
    flags[:, 1] = rng.random(B) < 0.7
    dist = rng.normal(size=(B, eng.n_l + 4))
    want_clear, want_hit = dist[:, eng.n_l + 2].copy(), np.zeros(B, dtype=bool)
    eng._swept(prev, pos, s.params, want_clear, want_hit, flags[:, 1])
    hit = eng._swept_compiled(flags, prev, pos, s.params, dist, eng.n_l + 2)  # _kernel.swept_rows
    np.testing.assert_array_equal(hit, want_hit)
    np.testing.assert_allclose(dist[:, eng.n_l + 2], want_clear, rtol=0, atol=1e-12)
    assert want_hit.any() and not want_hit[~flags[:, 1]].any()


@pytest.mark.parametrize("B", [9, 300])
def test_one_root_for_a_shared_threshold_has_the_bits_of_one_root_per_pair(B):
    """With one threshold row for every env, ``measure_rows`` takes one square root per env for the agent pairs
    and one for the agent-wall rows (min sqrt(d2) - t = sqrt(min d2) - t); with the same thresholds given per env
    it takes one per pair and per wall: the results have the same bits (9 envs: a block of its own size)."""
    if not _kernel.AVAILABLE:
        pytest.skip("numba is not installed")
    eng = Engine("narrow_passage")
    rng = np.random.default_rng(5)
    st = eng.reset(rng, B)
    spread = np.linspace(0.0, 2.0, B)[:, None, None]  # from the start pose to agents in contact
    pos = st.pos + spread * rng.normal(size=st.pos.shape)
    pos[1, 1] = pos[1, 0]  # a pair in contact
    pos[2, 0] = st.params["segments"][2, 0, 1]  # an agent on a wall's end
    params = dict(st.params)
    shared = eng._measure_compiled(pos, st.vel, st.ref, params)
    assert eng._thresholds(params).shape[0] == 1
    params["_thr"] = np.repeat(eng._thresholds(params), B, axis=0)
    each = eng._measure_compiled(pos, st.vel, st.ref, params)
    for a, b in zip(shared, each, strict=True):
        assert np.array_equal(a, b)
    clear = shared[1][:, eng.n_l + 2]
    assert clear[1] == -2 * eng.agent_radius and clear[2] == -eng.agent_radius and (clear > 0).any()


@pytest.mark.parametrize("scenario", ["narrow_passage", "obstacle_field", "hold", "maneuver", "maneuver_3d"])
def test_step1_global_gives_the_global_state_of_the_next_state(scenario):
    """``step1_global`` (the compiled step computing the global state in the same call, or ``step`` where the
    goal moves) returns ``global_state`` of the state it returns, to the bit, and the same step as ``step1``."""
    eng = Engine(scenario)
    s = eng.reset(np.random.default_rng(2), 1)
    rng = np.random.default_rng(3)
    for _ in range(5):
        a = rng.uniform(-1, 1, (eng.n_l, eng.p))
        new, g, *rest = eng.step1_global(s, a)
        ref = eng.step1(s, a, observe=False)
        assert g.dtype == np.float32 and g.shape == (eng.state_dim,)
        assert np.array_equal(g, eng.global_state(new)[0])
        assert rest == list(ref[2:]) and np.array_equal(new.x, ref[0].x)
        s = new


@pytest.mark.parametrize("vx", [10.0, 0.05])
def test_step1_catches_an_agent_tunnelling_through_the_wall(vx):
    """The team moved (as it is) so that its front agent is 0.15 m before the middle of the wall's lower part, that
    agent at 10 m/s across the wall: within one sample it lands beyond the wall, and the compiled step1 (its
    in-call swept check) reports the collision, as the batched step does; at 0.05 m/s neither does."""
    eng = Engine("narrow_passage", "double_integrator", "dynamic")
    s = eng.reset(np.random.default_rng(0), 1)
    seg = s.params["segments"][0, 0]  # the lower wall: (x_w, y_low) to (x_w, y_gap_low)
    d = eng.d
    i = int(np.argmax(s.pos[0, :, 0]))  # the front agent
    x = s.x.copy()
    x[0, :, :d] += np.array([seg[0, 0] - 0.15, 0.5 * (seg[0, 1] + seg[1, 1])]) - s.pos[0, i]
    x[0, i, d:] = (vx, 0.0)
    s = s._replace(x=x, pos=x[..., :d].copy(), vel=x[..., d:].copy())
    a = np.zeros((eng.n_l, eng.p))
    one = eng.step1(s, a)
    ref = eng.step(_batched(s), a[None])
    assert one[0].pos[0, i, 0] > seg[0, 0] + eng.agent_radius if vx > 1 else one[0].pos[0, i, 0] < seg[0, 0]
    assert one[5]["collision"] == bool(ref[5]["collision"][0]) == (vx > 1)
    assert one[3] == bool(ref[3][0]) == (vx > 1)
    assert not one[5]["out_of_bounds"] and not ref[5]["out_of_bounds"][0]  # the swept check, not the world box
    np.testing.assert_allclose(one[5]["min_clearance"], ref[5]["min_clearance"][0], rtol=1e-12, atol=1e-12)
