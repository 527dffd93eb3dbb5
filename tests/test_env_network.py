"""Communication networks inside the env's compiled step (formation_env.env.network, docs/networks.md "In the env"):
the step against the numpy oracle (the core's NetworkLoop with Network.draw) under every model, against
core.simulate(network=, seed=), its generator against numpy's, its ZOH against scipy, and the refusals."""

from __future__ import annotations

import functools
import warnings

import numpy as np
import pytest
import scipy.linalg
from test_env_engine import run_against_oracle

from formation_env import formation_v0
from formation_env.core import simulate
from formation_env.core.dynamics import LinearDynamics, c2d_zoh
from formation_env.core.errors import FormationError
from formation_env.core.network import Network, network_links
from formation_env.env import kernel
from formation_env.env.engine import Engine
from formation_env.env.network import (
    ZOH_EXPM,
    generator_of,
    network_seeds,
    pcg64_double,
    pcg64_next,
    pcg64_state,
    words_of,
    zoh_at,
)
from formation_env.env.vector import FormationVecEnv

#: One network per model, and a combination.
NETWORKS: dict[str, Network] = {
    "delay_neighbours": Network(delay=2),
    "delay_input": Network(delay=1, delayed="input"),
    "loss_hold": Network(loss=0.3),
    "loss_drop": Network(loss=0.3, loss_model="drop"),
    "jitter": Network(jitter=(0.05, 0.15)),
    "quantise_uniform": Network(quantise=("uniform", 0.05)),
    "quantise_log": Network(quantise=("log", 0.9)),
    "combination": Network(delay=1, loss=0.2, jitter=(0.08, 0.12), quantise=("uniform", 0.02)),
}
#: (dynamics, law) pairs a network applies to.
LAWS = [("double_integrator", "linear"), ("single_integrator", "stationary")]


def _engine(scenario: str, dynamics: str, law: str, net: Network | dict | None, **kw) -> Engine:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a delayed stationary law at its fastest gain may be unstable: still tested
        return Engine(scenario, dynamics, law, network=net, **kw)


# ---------------------------------------------------------------------------- the generator and the ZOH
@pytest.mark.parametrize("seed", [0, 1, 12345, 2**62 + 7])
def test_pcg64_is_numpys_generator(seed):
    st = pcg64_state(seed)
    gen = np.random.default_rng(seed)
    got = [pcg64_double(st) for _ in range(2000)]
    np.testing.assert_array_equal(got, gen.random(2000))
    np.testing.assert_array_equal(st, words_of(gen))
    ref = np.random.default_rng(seed)
    st = pcg64_state(seed)
    assert int(pcg64_next(st)) == int(ref.bit_generator.random_raw())
    np.testing.assert_array_equal(generator_of(st).random(5), ref.random(5))


def test_network_seeds_of_a_batch_equal_those_of_single_resets():
    one = [network_seeds(np.random.default_rng(s), 1)[0] for s in range(4)]
    each = network_seeds([np.random.default_rng(s) for s in range(4)], 4)
    np.testing.assert_array_equal(one, each)


@pytest.mark.parametrize("case", ["double_integrator", "random", "damped_3d"])
@pytest.mark.parametrize("T", [1e-3, 0.1, 2.5])
def test_zoh_at_a_period_matches_scipy(case, T):
    rng = np.random.default_rng(3)
    if case == "double_integrator":
        dyn = LinearDynamics.double_integrator(2)
        A, B = dyn.A, dyn.B
    elif case == "random":
        A, B = rng.normal(size=(4, 4)), rng.normal(size=(4, 2))
    else:
        A, B = -np.diag([0.5, 1.0, 2.0]) + 0.3 * rng.normal(size=(3, 3)), rng.normal(size=(3, 3))
    a_d, b_d = zoh_at(T, ZOH_EXPM, np.zeros((0, 0)), np.zeros((0, 0)), A, B)
    ref_a, ref_b = c2d_zoh(A, B, T)
    scale = 1e-12 * max(1.0, float(np.abs(ref_a).max()), float(np.abs(ref_b).max()))  # relative to the matrix
    np.testing.assert_allclose(a_d, ref_a, rtol=0, atol=scale)
    np.testing.assert_allclose(b_d, ref_b, rtol=0, atol=scale)
    aug = scipy.linalg.expm(np.block([[A, B], [np.zeros((B.shape[1], A.shape[0] + B.shape[1]))]]) * T)
    np.testing.assert_allclose(a_d, aug[: A.shape[0], : A.shape[0]], rtol=0, atol=scale)


# ---------------------------------------------------------------------------- the step against the oracle
@pytest.mark.parametrize("scenario", ["hold", "moving_obstacles"])
@pytest.mark.parametrize(("dynamics", "law"), LAWS)
@pytest.mark.parametrize("name", list(NETWORKS))
def test_step_matches_the_oracle_under_each_model(name, dynamics, law, scenario):
    """B = 3 copies through resets: every buffer, every generator state and the lost counts equal the oracle's
    (the core's NetworkLoop.step with Network.draw on each copy's generator)."""
    eng = _engine(scenario, dynamics, law, NETWORKS[name], max_cycles=12)
    run_against_oracle(eng, 20, 3, seed=2, amplitude=1.0)


def test_general_linear_dynamics_under_jitter_match_the_oracle():
    """A damped oscillator per axis (A != 0, not an integrator): the ZOH at each drawn period is the compiled expm."""
    eye = np.eye(2)
    A, B = np.kron([[0.0, 1.0], [-0.5, -0.8]], eye), np.kron([[0.0], [1.0]], eye)
    dyn = LinearDynamics(A=A, B=B, C=np.kron([[1.0, 0.0]], eye))
    eng = _engine("hold", dyn, "linear", Network(jitter=(0.05, 0.2), loss=0.1))
    run_against_oracle(eng, 15, 2, seed=4)


def test_an_ideal_network_is_the_nominal_law():
    for dynamics, law in LAWS:
        nominal, ideal = Engine("hold", dynamics, law), Engine("hold", dynamics, law, network={})
        s0, s1 = nominal.reset(np.random.default_rng(5), 2), ideal.reset(np.random.default_rng(5), 2)
        act = np.random.default_rng(6)
        for _ in range(30):
            a = act.uniform(-1, 1, (2, nominal.n_l, nominal.p))
            s0, *_ = nominal.step(s0, a)
            s1, _, _, _, _, info = ideal.step(s1, a)
            np.testing.assert_allclose(s1.x, s0.x, atol=1e-10)
        np.testing.assert_array_equal(info["lost_fraction"], 0.0)


@pytest.mark.parametrize(("dynamics", "law"), LAWS)
@pytest.mark.parametrize("name", ["delay_neighbours", "delay_input", "loss_hold", "loss_drop", "jitter", "combination"])
def test_followers_follow_core_simulate_with_the_same_seed(name, dynamics, law):
    """Leaders still (zero actions): the env's trajectory is core.simulate(..., network=, seed=s_b) from the same
    start, s_b = params["_net_seed"][b] (the copy's generator)."""
    net = NETWORKS[name]
    eng = _engine("hold", dynamics, law, net, max_cycles=200)
    s = eng.reset(np.random.default_rng(8), 2)
    steps = 60
    xs = [s.x]
    for _ in range(steps):
        s, *_ = eng.step(s, np.zeros((2, eng.n_l, eng.p)))
        xs.append(s.x)
    xs = np.stack(xs, axis=1)
    for b in range(2):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            ref = simulate(eng.omega, eng.fw.leaders, xs[b, 0], dt=eng.dt, steps=steps, law=law,
                           dynamics=eng.dynamics, network=net, seed=int(s.params["_net_seed"][b]),
                           return_result=True, **eng.law_params)  # fmt: skip
        np.testing.assert_allclose(xs[b], ref.states, atol=1e-9)
        assert s.net_lost[b] == int(np.sum(~ref.delivered))


def test_lost_fraction_counts_the_lost_link_samples():
    eng = _engine("hold", "double_integrator", "linear", {"loss": 0.4, "loss_model": "drop"})
    s = eng.reset(np.random.default_rng(0), 4)
    m = network_links(eng.law.part)[0].size
    for k in range(1, 151):
        s, _, _, _, _, info = eng.step(s, np.zeros((4, eng.n_l, eng.p)))
        np.testing.assert_allclose(info["lost_fraction"], s.net_lost / (k * m))
    assert np.all(np.abs(info["lost_fraction"] - 0.4) < 0.1)  # 150 m samples of Bernoulli(0.4) per copy
    assert len(set(s.net_lost.tolist())) > 1  # the copies draw their own losses


def test_the_same_seed_gives_the_same_losses_and_seeds_differ():
    kw = {"scenario": "hold", "follower_law": "linear", "network": {"loss": 0.3, "jitter": [0.08, 0.12]}}
    runs = []
    for seed in (3, 3, 4):
        env = formation_v0.parallel_env(**kw)
        env.reset(seed=seed)
        traj = []
        for _ in range(25):
            _, _, _, _, infos = env.step({a: np.full(env.engine.p, 0.3) for a in env.agents})
            traj.append((env.state().copy(), infos["leader_0"]["lost_fraction"]))
        runs.append(traj)
    for (x, f), (y, g) in zip(runs[0], runs[1], strict=True):
        np.testing.assert_array_equal(x, y)
        assert f == g
    assert any(f != g for (_, f), (_, g) in zip(runs[0], runs[2], strict=True))


def test_vec_env_copies_equal_single_envs_with_a_network():
    """FormationVecEnv (B = 3) with a network: slot b replays the PettingZoo env reset with seed + b."""
    kw = {"follower_law": "linear", "network": NETWORKS["combination"], "max_cycles": 30}
    venv = FormationVecEnv("moving_obstacles", num_envs=3, mode="shared", **kw)
    venv.seed(21)
    venv.reset()
    singles = [formation_v0.parallel_env(scenario="moving_obstacles", **kw) for _ in range(3)]
    for b, env in enumerate(singles):
        env.reset(seed=21 + b)
    nl = venv.n_l
    rng = np.random.default_rng(0)
    for _ in range(40):
        act = rng.uniform(-1, 1, (3 * nl, venv.p))
        obs, rew, _, infos = venv.step(act)
        for b, env in enumerate(singles):
            o, r, te, tr, inf = env.step({a: act[b * nl + i] for i, a in enumerate(env.possible_agents)})
            agents = env.possible_agents
            np.testing.assert_allclose(rew[b * nl : (b + 1) * nl], [r[a] for a in agents], atol=1e-5)
            if te[agents[0]] or tr[agents[0]]:
                assert infos[b * nl]["lost_fraction"] == inf[agents[0]]["lost_fraction"]
                o, _ = env.reset()
            np.testing.assert_allclose(obs[b * nl : (b + 1) * nl], np.stack([o[a] for a in agents]), atol=1e-5)
    venv.close()


# ---------------------------------------------------------------------------- the composition and the refusals
def test_without_a_network_the_step_has_no_network_part():
    nominal, networked = Engine("hold"), Engine("hold", follower_law="linear", network={"loss": 0.1})
    src = [open(eng._compose()[1].__file__).read() for eng in (nominal, networked)]
    assert "network_row" not in src[0] and "move_row" in src[0]
    assert not any(name in src[0] for name in ("sent0", "rng0", "nc.", "lost"))  # nor its arguments or outputs
    assert "network_row" in src[1] and "move_row" not in src[1]
    assert kernel._left_out(False) == {"network"} and kernel._left_out(True) == {"law"}


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"network": {"loss": 0.2}}, FormationError, r"not for law 'dynamic'.*follower_law='linear'"),
        ({"network": {"delay": 1}, "follower_law": "dynamic_distributed"}, FormationError, r"Jacobi rounds"),
        ({"network": 5, "follower_law": "linear"}, TypeError, r"network: network must be None, a Network"),
        ({"network": {"loss": 1.5}, "follower_law": "linear"}, FormationError, r"network: loss"),
        ({"network": {"lag": 1}, "follower_law": "linear"}, TypeError, r"network: network got unknown key"),
        ({"network": {"jitter": (0.2, 0.1)}, "follower_law": "linear"}, FormationError, r"network: jitter"),
    ],
)
def test_bad_networks_are_refused_naming_network(kwargs, error, match):
    with pytest.raises(error, match=match):
        Engine("hold", **kwargs)
    with pytest.raises(error, match=match):
        formation_v0.parallel_env(scenario="hold", **kwargs)


def test_checkers_accept_a_network():
    """The PettingZoo parallel API test on a networked env (the full checker sweep: tests/test_env_api.py)."""
    from pettingzoo.test import parallel_api_test

    net = NETWORKS["combination"]
    make = functools.partial(formation_v0.parallel_env, scenario="hold", follower_law="linear", network=net)
    parallel_api_test(make(), num_cycles=50)


def test_a_sparse_stress_runs_the_same_network(monkeypatch):
    """Above config.MAX_AGENTS the stress is CSR and the engine keeps no law map; the network part needs none:
    the same draws and states as the dense path, and every info key."""
    from formation_env.core.frameworks import trilateration
    from formation_env.env import config

    fw = trilateration(60, 2, seed=0)
    runs = {}
    for sparse in (False, True):
        monkeypatch.setattr(config, "MAX_AGENTS", 30 if sparse else 256)
        eng = _engine("hold", "double_integrator", "linear", NETWORKS["combination"], framework=fw, agent_radius=0.01)
        assert eng.sparse == sparse and (eng._M is None) == sparse
        s = eng.reset(np.random.default_rng(2), 2)
        rng = np.random.default_rng(5)
        out = []
        for _ in range(10):
            s, _, _, _, _, info = eng.step(s, rng.uniform(-1, 1, (2, eng.n_l, eng.p)))
            out.append((s.x, s.net_lost, info))
        runs[sparse] = out
    for dense, sp_ in zip(runs[False], runs[True], strict=True):
        np.testing.assert_allclose(dense[0], sp_[0], atol=1e-8)
        np.testing.assert_array_equal(dense[1], sp_[1])
        for key, val in dense[2].items():
            np.testing.assert_allclose(val, sp_[2][key], atol=1e-8, err_msg=key)


def test_a_networked_step_is_pure():
    """The generators' states are state arrays: stepping the same state twice draws the same losses and periods,
    and leaves the state as it was."""
    eng = _engine("moving_obstacles", "double_integrator", "linear", NETWORKS["combination"])
    s = eng.reset(np.random.default_rng(3), 2)
    before = {f: np.copy(getattr(s, f)) for f in s._fields if f != "params" and getattr(s, f) is not None}
    a = np.full((2, eng.n_l, eng.p), 0.4)
    one, two = eng.step(s, a), eng.step(s, a)
    for f, val in before.items():
        np.testing.assert_array_equal(getattr(s, f), val, err_msg=f)
    for f in ("x", "net_rng", "net_lost", "net_time"):
        np.testing.assert_array_equal(getattr(one[0], f), getattr(two[0], f), err_msg=f)
    assert not np.array_equal(one[0].net_rng, s.net_rng)
