"""Training smoke runs: train -> save -> load -> evaluate, and same seed -> same weights."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from oracle import route_lengths

from agents.policy import LearnedPolicy, load_policy
from formation_env.core.errors import FormationError
from formation_env.env.engine import Engine
from formation_env.env.state import EngineState
from train.evaluate import METRIC_KEYS, evaluate, reset_paired
from train.leaders import train


def _weights(path: Path) -> list[np.ndarray]:
    pol = LearnedPolicy.load(path)
    return [p.detach().numpy().copy() for p in pol.model.policy.parameters()]


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["commander", "shared"])
def test_smoke_train_save_load_evaluate(tmp_path: Path, mode: str) -> None:
    cfg = train("ppo", mode, "narrow_passage", 512, seed=1, out=tmp_path, smoke=True, n_envs=2)
    stem = tmp_path / f"narrow_passage_{mode}"
    for suffix in (".zip", "_vecnormalize.pkl", "_config.json"):
        assert Path(f"{stem}{suffix}").exists()
    assert set(cfg["eval"]["metrics"]) == set(METRIC_KEYS)
    eng = Engine("narrow_passage")
    pol = load_policy(f"{stem}.zip", eng)
    assert isinstance(pol, LearnedPolicy) and pol.mode == mode
    state = reset_paired(eng, [0, 1])
    a = pol.act_engine(eng, state)
    assert a.shape == (2, eng.n_l, eng.p) and np.all(np.abs(a) <= 1.0)
    if mode == "commander":
        ac = pol.act(eng.global_state(state))
        assert ac.shape == (2, eng.n_l * eng.p)
    res = evaluate(f"{stem}.zip", "narrow_passage", 2, seed=0, generalisation=False)
    assert res["episodes"] == 2


@pytest.mark.slow
def test_end_of_training_evaluation_takes_the_env_kwargs_that_change_the_state(tmp_path: Path) -> None:
    """Trained on another framework (6 agents in 3D instead of the default 5 in 2D), the run's own evaluation and
    ``load_policy`` without an env act on that framework; a training-only argument (the reward) is not carried."""
    kw = {"framework": "bipyramid_3d", "reward_weights": {"distance": 0.2}}
    cfg = train("ppo", "commander", "hold", 256, seed=0, out=tmp_path, smoke=True, n_envs=2, env_kwargs=kw,
                eval_episodes=1, algo_kwargs={"n_steps": 32}, policy_kwargs={"net_arch": [8, 8]},
                reward_curriculum={"start": {"distance": 1.0}, "fraction": 0.5})  # fmt: skip
    assert cfg["eval"]["episodes"] == 1 and set(cfg["eval"]["metrics"]) == set(METRIC_KEYS)
    assert cfg["reward_curriculum"] == {"start": {"distance": 1.0}, "fraction": 0.5}
    pol = load_policy(tmp_path / "hold_commander.zip")
    assert pol.scenario == "hold" and pol.env_kwargs == {"framework": "bipyramid_3d"}
    assert (pol.engine.n, pol.engine.d) == (6, 3)
    res = evaluate(tmp_path / "hold_commander.zip", None, 1, seed=0)
    assert res["scenario"] == "hold" and res["episodes"] == 1


@pytest.mark.slow
def test_maneuver_commander_trains_and_evaluates(tmp_path: Path) -> None:
    """A pose-rate commander: trained on the batched env, it acts through its own commanded poses."""
    rates = {"pose_speed": 2.0, "rotation_rate": 1.5}
    cfg = train("ppo", "commander", "hold", 512, seed=1, out=tmp_path, smoke=True, n_envs=2, action_mode="maneuver",
                env_kwargs={"maneuver_kwargs": rates})  # fmt: skip
    assert cfg["action_mode"] == "maneuver"
    eng = Engine("hold")
    pol = load_policy(tmp_path / "hold_commander.zip", eng)
    assert isinstance(pol, LearnedPolicy) and pol.maneuver
    state = reset_paired(eng, [0, 1, 2])
    a = pol.act_engine(eng, state)
    assert a.shape == (3, eng.n_l, eng.p) and np.all(np.abs(a) <= 1.0)
    assert pol._pose is not None and pol._pose.b.shape == (3, eng.d)
    assert pol._command is not None and pol._command.rates[[0, 2]].tolist() == [2.0, 1.5]  # the training's rates
    assert pol.engine is eng and load_policy(tmp_path / "hold_commander.zip", None).engine.scenario_name == "hold"


def test_maneuver_actions_only_for_commanders() -> None:
    from formation_env.core.errors import FormationError
    from formation_env.env.vector import FormationVecEnv

    with pytest.raises(FormationError, match="action_mode"):
        FormationVecEnv("hold", num_envs=2, mode="shared", action_mode="maneuver")
    with pytest.raises(TypeError, match="maneuver_kwargs"):
        FormationVecEnv("hold", num_envs=2, mode="commander", maneuver_kwargs={"pose_speed": 2.0})


@pytest.mark.slow
def test_central_critic_actor_reads_only_the_leaders_observation(tmp_path: Path) -> None:
    """MAPPO's split: the critic reads [o_i, s], the actor only o_i; training is reproducible, and the loaded
    policy acts from the leader's own observation."""
    import torch

    from agents.central_critic import LocalActorPolicy

    kw = {"smoke": True, "n_envs": 2, "eval_episodes": 1, "central_critic": True}
    cfg = train("ppo", "shared", "narrow_passage", 256, seed=3, out=tmp_path / "a", **kw)
    train("ppo", "shared", "narrow_passage", 256, seed=3, out=tmp_path / "b", **kw)
    assert cfg["central_critic"] is True
    stem = tmp_path / "a" / "narrow_passage_shared.zip"
    for x, y in zip(_weights(stem), _weights(tmp_path / "b" / "narrow_passage_shared.zip"), strict=True):
        np.testing.assert_array_equal(x, y)
    eng = Engine("narrow_passage", **cfg["env_kwargs"])
    pol = load_policy(stem, eng)
    net = pol.model.policy
    assert isinstance(net, LocalActorPolicy) and net.actor_dim == eng.obs_dim
    obs = torch.as_tensor(np.random.default_rng(0).normal(size=(5, eng.obs_dim + eng.state_dim)), dtype=torch.float32)
    other = obs.clone()
    other[:, eng.obs_dim :] += 3.0  # another global state: same actions, other values
    with torch.no_grad():
        np.testing.assert_array_equal(net.get_distribution(obs).mode(), net.get_distribution(other).mode())
        assert not torch.equal(net.predict_values(obs), net.predict_values(other))
    a = pol.act_engine(eng, reset_paired(eng, [0, 1]))
    assert a.shape == (2, eng.n_l, eng.p) and np.all(np.abs(a) <= 1.0)
    with pytest.raises(ValueError, match="shared mode only"):
        train("ppo", "commander", "narrow_passage", 256, seed=3, out=tmp_path / "c", **kw)


@pytest.mark.slow
def test_same_seed_same_weights(tmp_path: Path) -> None:
    kw = {"smoke": True, "n_envs": 2, "residual": 0.5, "eval_episodes": 1}
    train("ppo", "commander", "narrow_passage", 256, seed=7, out=tmp_path / "a", **kw)
    train("ppo", "commander", "narrow_passage", 256, seed=7, out=tmp_path / "b", checkpoints=8, **kw)
    train("ppo", "commander", "narrow_passage", 256, seed=8, out=tmp_path / "c", **kw)
    wa = _weights(tmp_path / "a" / "narrow_passage_commander.zip")
    wb = _weights(tmp_path / "b" / "narrow_passage_commander.zip")
    wc = _weights(tmp_path / "c" / "narrow_passage_commander.zip")
    for x, y in zip(wa, wb, strict=True):
        np.testing.assert_array_equal(x, y)
    assert any(not np.array_equal(x, y) for x, y in zip(wa, wc, strict=True))
    # the checkpoints saved (4 by default, 8 in "b") do not change the weights
    assert len(list((tmp_path / "a" / "checkpoints").glob("*_steps.zip"))) == 4
    assert len(list((tmp_path / "b" / "checkpoints").glob("*_steps.zip"))) == 8


@pytest.mark.slow
def test_residual_policy_keeps_planner_performance(tmp_path: Path) -> None:
    """A residual policy at initialisation is the planner plus a small correction: it still solves episodes."""
    train(
        "ppo",
        "commander",
        "narrow_passage",
        256,
        seed=0,
        out=tmp_path,
        smoke=True,
        n_envs=2,
        residual=0.5,
        eval_episodes=1,
    )
    pol = load_policy(tmp_path / "narrow_passage_commander.zip", Engine("narrow_passage"))
    assert isinstance(pol, LearnedPolicy) and pol.residual == 0.5
    res = evaluate(pol, "narrow_passage", 3, seed=0, generalisation=False)
    assert res["metrics"]["collision_rate"] == 0.0


def test_tolerance_curriculum_shrinks_to_the_scenarios_test() -> None:
    from formation_env.env.engine import Engine
    from train.leaders import ToleranceCurriculum

    eng = Engine("hold")
    final = (eng.scenario.goal_tol, eng.scenario.formation_tol)
    cur = ToleranceCurriculum(eng, factor=4.0, fraction=0.5, total=1000)
    for t, scale in ((0, 4.0), (250, 2.5), (500, 1.0), (900, 1.0)):
        cur.num_timesteps = t
        cur._on_step()
        assert eng.scenario.goal_tol == pytest.approx(final[0] * scale)
        assert eng.scenario.formation_tol == pytest.approx(final[1] * scale)
    cur._on_training_end()
    assert (eng.scenario.goal_tol, eng.scenario.formation_tol) == final
    with pytest.raises(ValueError, match="FACTOR"):
        ToleranceCurriculum(eng, factor=0.5, fraction=0.5, total=10)


def test_tolerance_reward_term_pays_while_the_success_test_holds() -> None:
    import numpy as np

    from formation_env.env.engine import Engine

    eng = Engine("hold", reward_weights={"tolerance": 1.0, "progress": 0, "formation": 0, "effort": 0, "distance": 0})
    s = eng.reset(np.random.default_rng(0), 1)
    at_goal = s._replace(x=s.goal.copy() @ np.linalg.pinv(eng.dynamics.C).T, pos=s.goal.copy(), err=np.zeros(1))
    zero = np.zeros((1, eng.n_l, eng.p))
    _, _, r_goal, *_ = eng.step(at_goal, zero)
    _, _, r_start, *_ = eng.step(s, zero)
    np.testing.assert_allclose(r_goal, eng.dt)
    np.testing.assert_allclose(r_start, 0.0)


def _summed_rewards(eng: Engine, B: int, steps: int, seed: int):
    """A reset of B envs from ``seed`` and ``steps`` steps of uniform random actions (drawn from ``seed`` + 1): the
    reset's state, the last state and each leader's reward summed over the steps (B, n_l)."""
    s0 = s = eng.reset(np.random.default_rng(seed), B)
    rng = np.random.default_rng(seed + 1)
    total = np.zeros((B, eng.n_l))
    for _ in range(steps):
        s, _, r, *_ = eng.step(s, rng.uniform(-1, 1, (B, eng.n_l, eng.p)))
        total += r
    return s0, s, total


def test_approach_term_is_a_potential_difference_of_the_phase_space_distance() -> None:
    """Summed over steps it telescopes to the agents' mean of log(eps + s_start) - log(eps + s_end)."""
    from oracle import phase_distance

    from formation_env.env.rewards import EPS_APPROACH

    eng = Engine("hold", reward_weights={"approach": 1.0, "progress": 0, "formation": 0, "effort": 0, "distance": 0})
    s0, s, total = _summed_rewards(eng, 1, 20, seed=1)  # the team's term, the same for every leader
    expect = np.log(EPS_APPROACH + phase_distance(eng, s0)) - np.log(EPS_APPROACH + phase_distance(eng, s))
    np.testing.assert_allclose(total, np.broadcast_to(expect.mean(axis=1, keepdims=True), total.shape), rtol=1e-9)
    at_rest_on_goal = s0._replace(pos=s0.goal, vel=np.zeros_like(s0.vel))
    np.testing.assert_allclose(phase_distance(eng, at_rest_on_goal), 0.0)


def _rest_time_one(e: float, v: float, a: float) -> float:
    """Brute-force oracle of the least time (s) to stand on the goal from position error e = goal - x and velocity
    v, |u| <= a: every one-switch bang-bang (accelerate s a for t1, then -s a until at rest, s = +-1) that ends
    on the goal, from the roots of its quadratic in t1; the shortest wins."""
    x, best = -e, np.inf
    for sgn in (1.0, -1.0):
        sa = sgn * a  # x + v t1 + sa t1^2 / 2 + (v + sa t1)^2 / (2 sa) = 0
        for t1 in np.roots([sa, 2 * v, x + v * v / (2 * sa)]):
            if abs(t1.imag) > 1e-9 or t1.real < -1e-12:
                continue
            t2 = (v + sa * t1.real) / sa
            if t2 >= -1e-12:
                best = min(best, t1.real + t2)
    return best


_rest_time = np.vectorize(_rest_time_one)


def test_time_to_rest_is_the_bang_bang_time_and_falls_one_second_per_second_on_its_path() -> None:
    """Against the brute-force oracle on a grid; along the bang-bang path T falls at rate 1 and the agent stands
    on its goal when T reaches 0."""
    from formation_env.env.rewards import time_to_rest

    a = 1.5
    for e in np.linspace(-3, 3, 13):
        for v in np.linspace(-2.5, 2.5, 11):
            assert time_to_rest(e, v, a) == pytest.approx(float(_rest_time(e, v, a)), rel=1e-9, abs=1e-12)
    x0, v0 = -2.0, 1.7  # goal at 0 (error e = -x), moving towards it slower than it could: accelerate, then brake
    t0 = time_to_rest(-x0, v0, a)
    t1 = max(r.real for r in np.roots([a, 2 * v0, x0 + v0 * v0 / (2 * a)]) if abs(r.imag) < 1e-12)  # the switch
    x1, v1 = x0 + v0 * t1 + 0.5 * a * t1 * t1, v0 + a * t1
    assert t0 == pytest.approx(t1 + v1 / a, rel=1e-12)
    for t in np.linspace(0.0, t0, 41):
        if t <= t1:
            x, v = x0 + v0 * t + 0.5 * a * t * t, v0 + a * t
        else:
            x, v = x1 + v1 * (t - t1) - 0.5 * a * (t - t1) ** 2, v1 - a * (t - t1)
        assert time_to_rest(-x, v, a) == pytest.approx(t0 - t, abs=1e-6)
    assert abs(x) < 1e-9 and abs(v) < 1e-9


def test_time_to_go_term_is_a_potential_difference_of_the_teams_time_to_rest() -> None:
    """Summed over steps it telescopes to the agents' mean of T_start - T_end (the slowest axis of each, the error
    scaled to the route's length); it is refused for agents it does not model."""
    from formation_env.core.errors import FormationError

    off = {"progress": 0, "formation": 0, "effort": 0, "distance": 0, "collision": 0, "success": 0, "approach": 0}
    for name in ("hold", "narrow_passage"):
        eng = Engine(name, reward_weights={**off, "time_to_go": 1.0})
        s0, s, total = _summed_rewards(eng, 2, 12, seed=5)

        def team_time(st, eng=eng, pvec=s0.params["_pvec"]):
            g = route_lengths(eng.scenario.route_row, pvec, eng.agent_radius, st.pos, st.goal)
            err = st.goal - st.pos
            err = err * (g / np.linalg.norm(err, axis=-1))[..., None]
            return _rest_time(err, st.vel - st.goal_vel, eng.u_max).max(axis=-1).mean(axis=-1)

        expect = team_time(s0) - team_time(s)
        assert np.all(np.abs(expect) > 0.05)  # the team moved
        np.testing.assert_allclose(total, np.broadcast_to(expect[:, None], total.shape), rtol=1e-9)
    with pytest.raises(FormationError, match=r"time_to_go.*double_integrator"):
        Engine("hold", dynamics="single_integrator", reward_weights={"time_to_go": 1.0})


def _closing_oracle(eng: Engine, s: EngineState) -> np.ndarray:
    """-T max over agents and capsules of clip(1 - gap / (0.1 + 0.5 max(0, closing speed)), 0, 1) (B,), from the
    state after a step and the capsules at that sample and the one before, in numpy."""
    from formation_env.env.rewards import CLOSING_HORIZON, CLOSING_MARGIN

    cur, old = eng.capsules(s.params, s.k), eng.capsules(s.params, s.k - 1)
    a, e, r = cur.a[:, None], cur.e[:, None], cur.rad[:, None]  # (B, 1, m, ...)
    p, v = s.pos[:, :, None], s.vel[:, :, None]  # (B, n, 1, d)
    ee = np.sum(e * e, axis=-1)
    t = np.clip(np.sum((p - a) * e, axis=-1) / np.where(ee > 0, ee, 1.0), 0.0, 1.0)[..., None]  # a disc: t = 0
    toward = a + t * e - p
    dist = np.linalg.norm(toward, axis=-1)
    surf_v = (a + t * e - old.a[:, None] - t * old.e[:, None]) / eng.dt
    speed = np.sum((v - surf_v) * toward, axis=-1) / dist + (r - old.rad[:, None]) / eng.dt
    gap = dist - r - eng.agent_radius
    value = np.clip(1.0 - gap / (CLOSING_MARGIN + CLOSING_HORIZON * np.maximum(speed, 0.0)), 0.0, 1.0)
    return -eng.dt * value.max(axis=(1, 2))


def test_closing_term_warns_by_the_gap_against_the_approach_speed() -> None:
    """Step by step it is the numpy oracle's value (static walls, moving discs), the same for every leader, and it
    is paid somewhere in the run; a team sliding along a wall pays only within the margin, one running at it
    pays from the horizon."""
    from formation_env.env.rewards import TERMS

    off = {"progress": 0, "formation": 0, "effort": 0, "distance": 0, "collision": 0, "success": 0, "approach": 0}
    for name in ("narrow_passage", "moving_obstacles"):
        eng = Engine(name, reward_weights={**off, "closing": 1.0})
        s = eng.reset(np.random.default_rng(3), 64)
        rng = np.random.default_rng(4)
        paid = 0
        for _ in range(60):
            s, _, r, *_ = eng.step(s, rng.uniform(-1, 1, (64, eng.n_l, eng.p)))
            expect = _closing_oracle(eng, s)
            np.testing.assert_allclose(r, np.broadcast_to(expect[:, None], r.shape), rtol=1e-9, atol=1e-12)
            paid += int(np.count_nonzero(expect))
        assert paid >= 5, (name, paid)
    row = TERMS["closing"].row
    wall_a, wall_e, wall_r = np.zeros((1, 1, 2)), np.array([[[0.0, 2.0]]]), np.zeros((1, 1))

    def value(x: float, vel: tuple[float, float]) -> float:
        out = np.zeros(1)
        pos, v = np.array([[[x, 1.0]]]), np.array([[vel]])
        row(0, out, 1.0, 0.1, 0.1, pos, v, wall_a, wall_e, wall_r, wall_a, wall_e, wall_r)
        return -out[0] / 0.1

    assert value(-0.25, (0.0, 2.0)) == 0.0  # sliding 0.15 m from the wall
    assert value(-0.15, (0.0, 2.0)) == pytest.approx(0.5)  # sliding 0.05 m from it
    assert value(-0.85, (1.0, 0.0)) == 0.0  # 0.75 m away at 1 m/s: beyond 0.1 + 0.5 * 1 m
    assert value(-0.6, (2.0, 0.0)) == pytest.approx(1.0 - 0.5 / 1.1)  # 0.5 m away at 2 m/s
    assert value(-0.6, (-2.0, 0.0)) == 0.0  # leaving it


def test_route_progress_telescopes_to_each_leaders_route_length_gained() -> None:
    """Summed over steps, ``route_progress`` is each leader's route length at the start minus at the end (through
    the gap on ``narrow_passage``), and on a straight route it equals ``progress``."""
    off = {"progress": 0, "formation": 0, "effort": 0, "distance": 0, "collision": 0, "success": 0}
    for name in ("narrow_passage", "hold"):
        eng = Engine(name, reward_weights={**off, "route_progress": 1.0})
        s0, s, total = _summed_rewards(eng, 2, 15, seed=3)
        pvec = s0.params["_pvec"]

        def route(st, pvec=pvec, eng=eng):
            return route_lengths(eng.scenario.route_row, pvec, eng.agent_radius, st.pos, st.goal)[:, eng.leaders]

        np.testing.assert_allclose(total, route(s0) - route(s), rtol=1e-9, atol=1e-12)
        if name == "hold":
            straight = Engine(name, reward_weights={**off, "progress": 1.0})
            s = straight.reset(np.random.default_rng(3), 2)
            a = np.random.default_rng(4).uniform(-1, 1, (2, eng.n_l, eng.p))
            np.testing.assert_allclose(straight.step(s, a)[2], eng.step(s, a)[2], rtol=1e-12)
        else:
            assert not np.allclose(route(s0), np.linalg.norm(s0.goal - s0.pos, axis=-1)[:, eng.leaders])


def test_narrow_passage_route_goes_through_the_gap() -> None:
    """Before the wall the route bends through the gap (never shorter than the straight line); aligned with the
    gap or beyond the wall it is the straight line."""
    eng = Engine("narrow_passage")
    sc = eng.scenario
    pvec = np.array([[0.0, 1.0, 1.0]])  # wall_x, gap_center, gap_width
    goal = np.array([[[4.0, 1.0], [4.0, -2.0], [4.0, 1.0]]])
    pos = np.array([[[-4.0, 1.0], [-4.0, -2.0], [1.0, -3.0]]])
    d = route_lengths(sc.route_row, pvec, sc.agent_radius, pos, goal)
    straight = np.linalg.norm(goal - pos, axis=-1)
    np.testing.assert_allclose(d[0, [0, 2]], straight[0, [0, 2]])  # aligned with the gap; beyond the wall
    room = 0.5 - sc.agent_radius - 0.05
    via = np.hypot(4.0, 1.0 - room + 2.0) * 2  # down to the gap's lower usable edge and back, symmetric
    np.testing.assert_allclose(d[0, 1], via)
    assert d[0, 1] > straight[0, 1]


def test_hold_turn_route_goes_round_the_centroid() -> None:
    """``Hold(route="turn")``: zero at the goal, the arc for a turn of the goal formation about its centroid,
    straight for a translation; 2D only."""
    from formation_env.core.errors import FormationError

    eng = Engine("hold", route="turn")
    s = eng.reset(np.random.default_rng(0), 1)
    goal = s.goal

    def route(pos, goal, _params, row=eng.scenario.route_row):
        return route_lengths(row, np.zeros((1, 0)), eng.agent_radius, pos, goal)

    np.testing.assert_allclose(route(goal, goal, s.params), 0.0, atol=1e-12)
    c = goal.mean(axis=1, keepdims=True)
    for deg in (30.0, -120.0, 175.0):
        a = np.radians(deg)
        rot = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
        turned = c + (goal - c) @ rot.T
        np.testing.assert_allclose(route(turned, goal, s.params), np.linalg.norm(goal - c, axis=-1) * abs(a))
    np.testing.assert_allclose(route(goal + [1.0, -2.0], goal, s.params), np.sqrt(5.0))
    straight = route(goal + [1.0, -2.0], goal, s.params, Engine("hold").scenario.route_row)
    np.testing.assert_allclose(straight, np.sqrt(5.0))
    with pytest.raises(FormationError, match="route must be 'straight', or 'turn' in 2D"):
        Engine("hold", route="turn", framework="bipyramid_3d")


def test_hold_rotations_times_each_collision_and_its_rotation() -> None:
    from train.hold_rotations import collision_times, rotations

    eng, seeds = Engine("hold"), [0, 1, 2, 3]
    assert np.all(np.isnan(collision_times(eng, "zero", seeds)))  # standing still never collides
    when = collision_times(eng, "random", seeds)  # random leaders collide in every episode (the leaderboard's 1.00)
    assert np.all((when > 0) & (when <= eng.max_cycles * eng.dt))
    angle = rotations(eng, seeds)
    assert angle.shape == (4,) and np.all((angle >= 0) & (angle <= 180)) and np.ptp(angle) > 1


def test_failures_lists_each_collision_with_the_teams_place_and_shape(capsys: pytest.CaptureFixture[str]) -> None:
    from agents.rollout import ENDINGS
    from train.failures import failures, main

    seeds = [0, 1, 2, 3]
    rows = failures("random", seeds, "moving_obstacles")  # random leaders collide in every episode
    assert [r["seed"] for r in rows] == seeds
    eng = Engine("moving_obstacles")
    for r in rows:
        assert r["ending"] in ENDINGS and r["ending"] != "success" and 0 < r["time"] <= eng.max_cycles * eng.dt
        assert len(r["scales"]) == 2 and r["scales"][0] >= r["scales"][1] > 0 and -8 < r["x"] < 8
        assert len(r["scales_before"]) == 2 and r["scales_before"][0] >= r["scales_before"][1] > 0
        assert len(r["agents"]) == {"obstacle": 1, "agents": 2}.get(r["ending"], 0)
        assert r["leader"] == [a in eng.leaders for a in r["agents"]]
        assert r["r"] == [eng.fw.positions[a].tolist() for a in r["agents"]]
    assert any(r["ending"] == "obstacle" for r in rows)
    assert failures("analytic", [0, 1], "hold") == []  # the planner solves these
    main(["--policy", "random", "--scenario", "hold", "--episodes", "2"])
    out = capsys.readouterr().out.splitlines()
    assert out[0] == "collisions: 2 of 2" and len(out) == 4
    with pytest.raises(SystemExit):
        main(["--policy", "random", "--episodes", "0"])
    with pytest.raises(SystemExit):
        main(["--policy", "random", "--env-kwargs", "[1]"])


def test_failures_names_the_agents_in_contact() -> None:
    from agents.rollout import reset_paired
    from train.failures import failures, nearest_agent, nearest_pair

    eng = Engine("moving_obstacles")
    state = reset_paired(eng, [0, 1])
    discs = state.params["moving_circles"]  # (B, M, 5): centre, velocity, radius at k = 0
    for who in (0, 3):  # a leader, then a follower, 5 cm off disc 1's rim; the others 1 m further along its lane
        pos = state.pos.copy()
        for b in range(2):
            c, r = discs[b, 1, :2], discs[b, 1, 4]
            toward_middle = np.array([0.0, -1.0 if c[1] > 0 else 1.0])  # the other discs are >= 1.85 m away in x
            for a in range(eng.n):
                pos[b, a] = c + toward_middle * (r + (0.05 if a == who else 1.05 + 0.1 * a))
        moved = state._replace(pos=pos)
        assert nearest_agent(eng, moved, 0) == who and nearest_agent(eng, moved, 1) == who
    pos = np.stack([np.array([0.0, 3.0 * a]) for a in range(eng.n)])[None].repeat(2, 0)
    pos[1, 4] = pos[1, 1] + [0.15, 0.0]  # copy 1: agents 1 and 4 0.15 m apart, the rest 3 m
    assert ({1, 4} in [{i, j} for i, j in zip(eng.pair_i, eng.pair_j, strict=True)]) and nearest_pair(
        eng, state._replace(pos=pos), 1
    ) == (1, 4)
    # the passage planner with linear followers on a perfect network: some episodes end in two agents touching
    rows = failures("analytic", list(range(6)), "narrow_passage", {"follower_law": "linear"})
    touching = [r for r in rows if r["ending"] == "agents"]
    assert touching and all(len(r["agents"]) == 2 and r["agents"][0] < r["agents"][1] for r in touching)


def test_approach_profile_follows_the_team_to_its_goal(capsys: pytest.CaptureFixture[str]) -> None:
    from train.approach_profile import main, profile

    eng = Engine("hold")
    rows = profile(eng, "analytic", [0, 1, 2], every=1.0, horizon=6.0)
    assert rows.shape == (6, 3) and rows[:, 0].tolist() == pytest.approx([1, 2, 3, 4, 5, 6])
    assert rows[0, 1] > 1.0 > 0.15 > rows[-1, 1] and rows[0, 2] > 0.5  # moving at first, within goal_tol at the end
    assert np.all(np.diff(rows[:, 1]) <= 1e-9)  # the planner never backs off
    main(["--policy", "analytic", "--episodes", "2", "--every", "2", "--horizon", "4"])
    assert capsys.readouterr().out.count("\n") == 4  # header, rule, rows at 2 s and 4 s
    with pytest.raises(SystemExit):
        main(["--policy", "analytic", "--every", "0"])


def test_range_curriculum_moves_the_draws_to_the_scenarios_ranges() -> None:
    from train.leaders import RangeCurriculum

    eng = Engine("narrow_passage")
    final = eng.scenario.gap_width
    cur = RangeCurriculum(eng, {"gap_width": [2.4, 3.0]}, fraction=0.5, total=1000)
    for t, expect in ((0, (2.4, 3.0)), (250, (0.5 * (2.4 + final[0]), 0.5 * (3.0 + final[1]))), (600, final)):
        cur.num_timesteps = t
        cur._on_step()
        assert eng.scenario.gap_width == pytest.approx(expect)
        w = eng.reset(np.random.default_rng(t), 64).params["gap_width"]
        assert expect[0] <= w.min() and w.max() <= expect[1]
    cur.num_timesteps = 0
    cur._on_step()
    cur._on_training_end()
    assert eng.scenario.gap_width == final
    with pytest.raises(ValueError, match="not a"):
        RangeCurriculum(eng, {"nonsense": [1, 2]}, 0.5, 10)
    late = RangeCurriculum(eng, {"gap_width": [2.4, 3.0]}, fraction=0.5, total=1000, begin=0.2)
    for t, expect in ((0, (2.4, 3.0)), (200, (2.4, 3.0)), (350, (0.5 * (2.4 + final[0]), 0.5 * (3.0 + final[1])))):
        late.num_timesteps = t
        late._on_step()
        assert eng.scenario.gap_width == pytest.approx(expect)
    with pytest.raises(ValueError, match=r"begin must be in \[0, fraction\)"):
        RangeCurriculum(eng, {"gap_width": [2.4, 3.0]}, fraction=0.5, total=1000, begin=0.5)
    recipe = {"start": {"gap_width": [2.4, 3.0]}, "fraction": 0.5, "begin": 0.2}
    assert RangeCurriculum.from_recipe(eng, recipe, 1000).first == 200
    with pytest.raises(ValueError, match=r"give start, fraction and optionally begin, got \['fraction', 'strat'\]"):
        RangeCurriculum.from_recipe(eng, {"strat": {}, "fraction": 0.5}, 1000)


@pytest.mark.parametrize(
    "flag", ["--env-kwargs", "--algo-kwargs", "--policy-kwargs", "--range-curriculum", "--reward-curriculum"]
)
def test_json_flags_refuse_what_is_not_a_json_object(flag: str, capsys) -> None:
    from train.leaders import main as leaders_main

    for bad in ("{bad", "[1, 2]"):
        with pytest.raises(SystemExit) as exc:
            leaders_main([flag, bad, "--smoke"])
        assert exc.value.code == 2
        assert f"{flag} must be a JSON object" in capsys.readouterr().err


def test_linear_schedule_strings_become_schedules_and_others_are_refused() -> None:
    from train.leaders import LinearSchedule, schedules

    hp = schedules({"learning_rate": "lin_3e-4", "clip_range": 0.2, "n_steps": 256})
    lr = hp["learning_rate"]
    assert isinstance(lr, LinearSchedule)
    assert lr(1.0) == pytest.approx(3e-4) and lr(0.25) == pytest.approx(7.5e-5) and lr(0.0) == 0.0
    assert hp["clip_range"] == 0.2 and hp["n_steps"] == 256
    held = schedules({"learning_rate": "lin_3e-4_from_0.6"})["learning_rate"]
    assert held(1.0) == held(0.4) == 3e-4  # constant, bit for bit, over the first 60 % of training
    assert held(0.2) == pytest.approx(1.5e-4) and held(0.0) == 0.0
    assert all(schedules({"lr": "lin_3e-4_from_0"})["lr"](r) == lr(r) for r in np.linspace(0.0, 1.0, 101))
    for bad in ("exp_3e-4", "lin_fast", "3e-4", "lin_3e-4_from_1", "lin_3e-4_from_-0.1", "lin_3e-4_0.5"):
        with pytest.raises(ValueError, match="learning_rate"):
            schedules({"learning_rate": bad})


def test_checkpoint_count_is_checked_before_training(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="checkpoints must be an integer >= 1, got 0"):
        train("ppo", "shared", out=tmp_path, smoke=True, checkpoints=0)
    with pytest.raises(ValueError, match=r"checkpoints must be an integer >= 1, got 2\.5"):
        train("ppo", "shared", out=tmp_path, smoke=True, checkpoints=2.5)  # type: ignore[arg-type]
    assert not (tmp_path / "tb").exists()


def test_thread_count_is_checked_before_training(tmp_path: Path) -> None:
    for bad in (0, 1.5, True):
        with pytest.raises(ValueError, match=r"threads must be an integer >= 1, got " + str(bad).replace(".", r"\.")):
            train("ppo", "shared", out=tmp_path, smoke=True, threads=bad)  # type: ignore[arg-type]
    assert not (tmp_path / "tb").exists()


@pytest.mark.slow
def test_a_run_uses_its_threads_and_records_them_the_machine_and_its_command(tmp_path: Path) -> None:
    """``--threads`` reaches torch and numba, and the config says what the run's wall time was measured on and the
    command that made it; without the flag a run takes every usable core."""
    import json

    import numba
    import torch

    from train.leaders import parse_run, usable_cores

    argv = ["--mode", "shared", "--scenario", "hold", "--smoke", "--threads", "1", "--out", str(tmp_path)]
    run = parse_run(argv)
    assert run["threads"] == 1 and run["command"] == "python -m train.leaders " + " ".join(argv)
    cfg = train(**run)
    assert torch.get_num_threads() == 1 and numba.get_num_threads() == 1
    saved = json.loads((tmp_path / "hold_shared_config.json").read_text())
    assert saved["threads"] == cfg["threads"] == 1 and saved["command"] == run["command"]
    assert {"cpu", "cores", "python", "torch", "numpy", "numba", "stable_baselines3"} <= set(saved["machine"])
    assert saved["machine"]["cores"] == usable_cores()
    assert train("ppo", "shared", "hold", out=tmp_path / "all", smoke=True)["threads"] == usable_cores()
    assert torch.get_num_threads() == usable_cores()


def test_adaptive_learning_rate_follows_each_updates_kl(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``kl_<initial>_<target>``: divided by 1.5 after an update whose KL exceeds twice the target, multiplied by 1.5
    below half of it, within [1e-5, 1e-2]; a run feeds it SB3's ``approx_kl`` after every update."""
    from train.leaders import AdaptiveLR, main, schedules

    lr = schedules({"learning_rate": "kl_1e-3_0.01"})["learning_rate"]
    assert isinstance(lr, AdaptiveLR) and lr(1.0) == lr(0.0) == 1e-3
    lr.adapt(0.03)
    assert lr(0.5) == pytest.approx(1e-3 / 1.5)
    lr.adapt(0.01)  # within [target / 2, 2 target]: unchanged
    assert lr(0.5) == pytest.approx(1e-3 / 1.5)
    lr.adapt(0.001)
    assert lr(0.5) == pytest.approx(1e-3)
    for _ in range(40):
        lr.adapt(1.0)
    assert lr(0.5) == AdaptiveLR.low
    for bad in ("kl_1e-3", "kl_0_0.01", "kl_1e-3_-1", "kl_1e-3_0.01_from_0", "kl_1e-3_0.01_from_1.5"):
        with pytest.raises(ValueError, match=r"learning_rate|both must be > 0|f must be in"):
            schedules({"learning_rate": bad})
    late = schedules({"learning_rate": "kl_1e-3_0.01_from_0.75"})["learning_rate"]
    assert late(0.5) == 1e-3  # adapted over the first 75 % of training
    late.adapt(0.001)
    assert late(0.3) == pytest.approx(1.5e-3)
    assert late(0.125) == pytest.approx(0.75e-3) and late(0.0) == 0.0  # then linear to 0 from the rate reached
    late.adapt(1.0)  # no adaptation while annealing
    assert late(0.125) == pytest.approx(0.75e-3)
    # a target far below any update's KL: the rate falls by 1.5 after each update but the last
    argv = ["--mode", "commander", "--scenario", "hold", "--n-envs", "2", "--timesteps", "256", "--eval-episodes", "0",
            "--algo-kwargs", '{"n_steps": 32, "batch_size": 64, "n_epochs": 2, "learning_rate": "kl_1e-3_1e-9"}',
            "--out", str(tmp_path)]  # fmt: skip
    assert main(argv) == 0
    assert json.loads(capsys.readouterr().out)["name"] == "ppo_commander"  # no evaluation asked, none printed
    from stable_baselines3 import PPO

    model = PPO.load(tmp_path / "hold_commander.zip")
    assert model.learning_rate(0.0) == pytest.approx(1e-3 / 1.5**3)  # 4 updates, adapted after the first 3


def test_entropy_coefficient_schedule_sets_each_update_s_bonus(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``ent_coef: lin_<value>_from_<f>``: PPO's entropy bonus held over the fraction f of training, then linear to 0,
    set before each update from the fraction of training left after its rollout; refused for SAC."""
    from stable_baselines3 import PPO

    from train.leaders import EntropySchedule

    seen: list[float] = []

    class Spy(EntropySchedule):
        def _on_rollout_end(self) -> None:
            super()._on_rollout_end()
            seen.append(self.model.ent_coef)

    monkeypatch.setattr("train.leaders.EntropySchedule", Spy)
    train("ppo", "commander", "hold", timesteps=256, out=tmp_path, n_envs=2, eval_episodes=0,
          algo_kwargs={"n_steps": 32, "batch_size": 64, "n_epochs": 1, "ent_coef": "lin_0.02_from_0.5"})  # fmt: skip
    # 4 rollouts of 64 samples: 3/4, 1/2, 1/4 and 0 of training left after each
    assert seen == pytest.approx([0.02, 0.02, 0.01, 0.0])
    assert PPO.load(tmp_path / "hold_commander.zip").ent_coef == 0.0
    with pytest.raises(ValueError, match=r"algo_kwargs\['ent_coef'\]: a schedule is for ppo only"):
        train("sac", "commander", "hold", out=tmp_path / "sac", smoke=True, algo_kwargs={"ent_coef": "lin_0.1"})


def test_action_std_cap_bounds_each_rollout_s_deviation_falling_to_its_final_value(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``action_std_cap: <final>_from_<f>``: the policy's own deviation over the fraction f of training, then a bound
    falling geometrically from its largest deviation at f to ``final``, applied before each rollout and to the saved
    policy; malformed values and SAC are refused, naming the argument."""
    import math

    from stable_baselines3 import PPO

    from train.leaders import ActionStdCap

    seen: list[list[float]] = []

    class Spy(ActionStdCap):
        def _on_rollout_start(self) -> None:
            super()._on_rollout_start()
            seen.append(self.model.policy.log_std.detach().tolist())

    monkeypatch.setattr("train.leaders.ActionStdCap", Spy)
    train("ppo", "commander", "hold", timesteps=256, out=tmp_path, n_envs=2, eval_episodes=0,
          algo_kwargs={"n_steps": 32, "batch_size": 64, "n_epochs": 1, "action_std_cap": "0.1_from_0.5"},
          policy_kwargs={"log_std_init": 0.0})  # fmt: skip
    # 4 rollouts of 64 samples, starting at 0, 1/4, 1/2 and 3/4 of training
    assert len(seen) == 4
    free = seen[2]  # at 1/2 the bound starts at the policy's own largest deviation: nothing clamped yet
    assert max(abs(v) for v in seen[0] + seen[1] + free) < 0.1  # one update of 64 samples moves log_std a little
    half_way = max(free) + 0.5 * (math.log(0.1) - max(free))  # geometric: half way in log at 3/4
    assert seen[3] == pytest.approx([half_way] * len(free))  # every entry was above it
    model = PPO.load(tmp_path / "hold_commander.zip")
    assert model.policy.log_std.exp().detach().numpy() == pytest.approx(0.1)
    assert "action_std_cap" not in model.__dict__  # not an SB3 argument
    for bad in ("0.1", "0_from_0.5", "0.1_from_1"):
        with pytest.raises(ValueError, match=r"algo_kwargs\['action_std_cap'\] must be"):
            train("ppo", "commander", "hold", out=tmp_path / "bad", smoke=True, algo_kwargs={"action_std_cap": bad})
    with pytest.raises(ValueError, match=r"algo_kwargs\['action_std_cap'\] is for ppo only"):
        train(
            "sac", "commander", "hold", out=tmp_path / "sac", smoke=True, algo_kwargs={"action_std_cap": "0.1_from_0.5"}
        )


def test_fixed_statistics_map_the_bounds_onto_plus_minus_one_and_do_not_move() -> None:
    from agents.normalization import FixedMeanStd

    rms = FixedMeanStd(np.array([-4.0, 0.0, 2.0]), np.array([4.0, 1.0, 2.0]))
    before = (rms.mean.copy(), rms.var.copy())
    rms.update(np.random.default_rng(0).normal(50.0, 9.0, (1000, 3)))
    np.testing.assert_array_equal(rms.mean, before[0])
    np.testing.assert_array_equal(rms.var, before[1])
    np.testing.assert_allclose((np.array([4.0, 0.0, 2.0]) - rms.mean) / np.sqrt(rms.var + 1e-12), [1.0, -1.0, 0.0])
    with pytest.raises(ValueError, match="bounds: low and high must be finite"):
        FixedMeanStd(np.array([0.0, -np.inf]), np.array([1.0, 1.0]))
    with pytest.raises(ValueError, match="bounds: low and high must be finite"):
        FixedMeanStd(np.array([1.0]), np.array([0.0]))


@pytest.mark.slow
def test_bounds_normalisation_is_kept_through_training_saving_and_acting(tmp_path: Path) -> None:
    """``obs_norm="bounds"``: the saved statistics are the observation space's mid-points and half-ranges after
    training, the config records the choice, and the loaded policy normalises with them; a bad name is refused."""
    from agents.normalization import FixedMeanStd

    with pytest.raises(ValueError, match=r"obs_norm must be one of \('running', 'bounds'\), got 'fixed'"):
        train("ppo", "commander", "hold", out=tmp_path, smoke=True, obs_norm="fixed")
    cfg = train("ppo", "commander", "hold", 512, seed=0, out=tmp_path, smoke=True, n_envs=2, obs_norm="bounds",
                eval_episodes=1)  # fmt: skip
    assert cfg["obs_norm"] == "bounds"
    pol = load_policy(tmp_path / "hold_commander.zip")
    assert isinstance(pol, LearnedPolicy) and isinstance(pol.vecnorm.obs_rms, FixedMeanStd)
    eng = Engine("hold")
    np.testing.assert_allclose(pol.vecnorm.obs_rms.mean, 0.5 * (eng.state_low + eng.state_high), rtol=1e-6)
    obs = eng.global_state(reset_paired(eng, [0]))
    want = np.clip((obs - pol.vecnorm.obs_rms.mean) / np.sqrt(pol.vecnorm.obs_rms.var + 1e-8), -10, 10)
    np.testing.assert_allclose(pol._norm(obs), want, rtol=1e-5, atol=1e-6)


@pytest.mark.slow
def test_noise_gap_reports_the_noise_and_both_ways_of_acting(tmp_path: Path) -> None:
    """``python -m train.noise_gap``: the policy's Gaussian deviation per action entry, its deterministic rates equal
    the evaluation's, and the sampled ones are reproducible for a seed."""
    from train.noise_gap import noise_gap

    train("ppo", "commander", "hold", 512, seed=0, out=tmp_path, smoke=True, n_envs=2, eval_episodes=0,
          policy_kwargs={"log_std_init": 0.5})  # fmt: skip
    path = str(tmp_path / "hold_commander.zip")
    gap = noise_gap(path, 3, seed=5)
    assert {"success_rate", "collision_rate", "time_to_goal"} == set(gap["deterministic"]) == set(gap["sampled"])
    std = np.exp(LearnedPolicy.load(path).model.policy.log_std.detach().numpy())
    np.testing.assert_allclose(gap["noise"], std, atol=1e-3)
    m = evaluate(path, None, 3, seed=5, generalisation=False)["metrics"]
    keys = ("success_rate", "collision_rate", "time_to_goal")
    np.testing.assert_equal([gap["deterministic"][k] for k in keys], [m[k] for k in keys])  # NaN: no success
    again = noise_gap(path, 3, seed=5)["sampled"]
    np.testing.assert_equal([again[k] for k in keys], [gap["sampled"][k] for k in keys])


def test_reward_curriculum_moves_the_compiled_steps_weights() -> None:
    """A weight set during training pays exactly what an engine built with it pays, with no recompilation."""
    from train.leaders import RewardCurriculum

    def rewards(eng: Engine) -> np.ndarray:
        state = eng.reset(np.random.default_rng(3), 8)
        a = np.random.default_rng(4).uniform(-1.0, 1.0, (8, eng.n_l, eng.p))
        return eng.advance(state, a)[2]

    weights = {"distance": 2.0, "collision": 40.0}
    eng = Engine("hold", reward_weights=weights)
    module = eng._compose()[1]
    cur = RewardCurriculum(eng, {"distance": 0.5}, fraction=0.5, total=1000, begin=0.2)
    assert eng.reward_weights["distance"] == 0.5  # from the first step of training
    for t, w in ((0, 0.5), (200, 0.5), (350, 1.25), (500, 2.0), (900, 2.0)):
        cur.num_timesteps = t
        cur._on_step()
        assert eng.reward_weights["distance"] == pytest.approx(w)
        built = Engine("hold", reward_weights={**weights, "distance": w})
        np.testing.assert_allclose(rewards(eng), rewards(built), rtol=1e-12, atol=1e-12)
    assert eng._compose()[1] is module  # the same compiled step throughout
    cur.num_timesteps = 0
    cur._on_step()
    cur._on_training_end()
    assert eng.reward_weights["distance"] == 2.0
    with pytest.raises(FormationError, match=r"\['proximity'\] had weight 0 at construction"):
        RewardCurriculum(eng, {"proximity": 1.0}, 0.5, 10)
    with pytest.raises(FormationError, match=r"^weights\['collision'\] must be finite"):
        RewardCurriculum(eng, {"collision": float("nan"), "distance": 1.0}, 0.5, 10)
    assert eng.reward_weights["distance"] == 2.0  # a refused curriculum changes nothing
    with pytest.raises(ValueError, match="give start, fraction"):
        RewardCurriculum.from_recipe(eng, {"start": {"collision": 10.0}}, 10)
    from train.leaders import parse_run

    flag = '{"start": {"collision": 50.0}, "fraction": 0.5}'
    assert parse_run(["--reward-curriculum", flag])["reward_curriculum"] == {
        "start": {"collision": 50.0},
        "fraction": 0.5,
    }
    with pytest.raises(FormationError, match="had weight 0 at construction"):
        eng.set_reward_weights({"proximity": 1.0})
    with pytest.raises(TypeError, match="unknown reward term 'colision'"):
        eng.set_reward_weights({"colision": 1.0})
