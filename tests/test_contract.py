"""The step's declared contract: each trap a component author could fall into gives the right result or an error
when the Engine is built (docs/architecture.md, "The step's arrays")."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from components import BarsAndDiscs, SpinningBars, bar_capsules
from oracle import capsule_distance, route_lengths
from test_env_engine import run_against_oracle

from formation_env.env.engine import Engine
from formation_env.env.kernel import jit
from formation_env.env.observations import OBS_BLOCKS, ObsBlock, register_block
from formation_env.env.rewards import TERMS, reward_term
from formation_env.env.scenarios import REGISTRY

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture
def registries(monkeypatch):
    """The test scenarios registered, and whatever blocks and terms a test adds taken out again afterwards."""
    for cls in (SpinningBars, BarsAndDiscs):
        monkeypatch.setitem(REGISTRY, cls.name, cls)
    blocks, terms = set(OBS_BLOCKS), set(TERMS)
    yield
    for name in set(OBS_BLOCKS) - blocks:
        del OBS_BLOCKS[name]
    for name in set(TERMS) - terms:
        del TERMS[name]


def _run_against_oracle(eng: Engine, steps: int = 20, B: int = 3, seed: int = 1) -> None:
    """The engine against the numpy oracle. (The oracle marches rays in 1 mm steps and counts a thin wall within
    half a step as hit: seed 0 has a ray that passes 0.16 mm beside a bar's end, a hit for it, a miss exactly.)"""
    run_against_oracle(eng, steps, B, seed)


def test_a_rotating_bar_matches_the_oracle(registries):
    """Trap 1: the step's capsules of a type whose axis turns are those at the step's own time (the rays see them)."""
    eng = Engine("spinning_bars_test", "double_integrator", "dynamic", max_cycles=30)
    _run_against_oracle(eng)


def test_two_moving_obstacle_types_both_collide(registries):
    """Trap 4: every moving type of a scenario is in the step (its capsules collide and are sensed)."""
    eng = Engine("bars_and_discs_test", "double_integrator", "dynamic", max_cycles=30)
    _run_against_oracle(eng)
    s = eng.reset(np.random.default_rng(1), 1)
    bars = s.params["spinning_bars"].copy()
    lead = int(eng.leaders[0])
    bars[0, 0, :2] = s.pos[0, lead]  # the first bar spins about the first leader: a contact at once
    params = {**s.params, "spinning_bars": bars}
    info = eng.step(s._replace(params=params), np.zeros((1, eng.n_l, eng.p)))[5]
    assert info["collision"][0] and info["min_clearance"][0] < 0.0
    gs = eng.global_state(s)  # both types' obstacles, the bars as their capsules
    assert gs.shape == (1, eng.state_dim) and np.all(np.isfinite(gs))


def test_a_term_that_reads_the_route_gets_it(registries):
    """Trap 2: a new term naming ``route0`` / ``route1`` gets the scenario's route lengths, with no list to edit."""

    @reward_term("route_probe", 1.0, "test: the leaders' route approach (m)")
    def route_probe(b, out, w, leaders, route0, route1):  # pragma: no cover
        for i in range(out.shape[0]):
            out[i] += w * (route0[b, leaders[i]] - route1[b, leaders[i]])

    weights = {name: 0.0 for name in TERMS} | {"route_probe": 1.0}
    eng = Engine("narrow_passage", reward_weights=weights)
    s = eng.reset(np.random.default_rng(3), 4)
    a = np.random.default_rng(4).uniform(-1, 1, (4, eng.n_l, eng.p))
    new, _, rew, *_ = eng.step(s, a)
    route = eng.scenario.route_row
    r0 = route_lengths(route, s.params["_pvec"], eng.agent_radius, s.pos, s.goal)[:, eng.leaders]
    r1 = route_lengths(route, s.params["_pvec"], eng.agent_radius, new.pos, new.goal)[:, eng.leaders]
    np.testing.assert_allclose(rew, r0 - r1, atol=1e-12)


def test_observe_runs_the_parts_its_blocks_read(registries):
    """Trap 3: a block that reads the contacts (``clear``) or the judgement (``gmax``) gets the true value at the
    reset, not what an unset array holds."""

    @jit
    def gaps(b, out, lo, clear, gmax):  # pragma: no cover
        for i in range(out.shape[0]):
            out[i, lo] = clear[b]
            out[i, lo + 1] = gmax[b]

    bounds = (np.full(2, -100.0), np.full(2, 100.0))
    meaning = "test: clearance and largest goal distance (m)"
    register_block(ObsBlock("gaps_probe", "2", lambda e: 2, lambda e: bounds, gaps, meaning, "+-100"))
    eng = Engine("narrow_passage", observation=["position", "gaps_probe"])
    s = eng.reset(np.random.default_rng(5), 4)
    obs = eng.observe(s)[:, 0, eng.obs_blocks["gaps_probe"]]
    pos = s.pos
    iu, ju = np.triu_indices(eng.n, 1)
    pairs = np.linalg.norm(pos[:, iu] - pos[:, ju], axis=-1).min(axis=1) - 2 * eng.agent_radius
    walls = capsule_distance(pos, eng.capsules(s.params, s.k)).min(axis=(1, 2)) - eng.agent_radius
    np.testing.assert_allclose(obs[:, 0], np.minimum(pairs, walls), atol=1e-5)
    np.testing.assert_allclose(obs[:, 1], np.linalg.norm(s.goal - pos, axis=-1).max(axis=1), atol=1e-5)


def test_an_unknown_array_name_is_refused_when_the_engine_is_built(registries):
    """A component naming an array the step does not have fails at construction, naming the component, the array
    and the arrays that exist."""

    @jit
    def typo(b, out, lo, clearance):  # pragma: no cover
        out[0, lo] = clearance[b]

    register_block(
        ObsBlock("typo_probe", "1", lambda e: 1, lambda e: (np.zeros(1), np.ones(1)), typo, "test", "[0, 1]")
    )
    with pytest.raises(TypeError, match=r"typo.*'clearance'.*clear"):
        Engine("hold", observation=["position", "typo_probe"])

    @reward_term("typo_term", 1.0, "test")
    def typo_term(b, out, w, gdist1):  # pragma: no cover
        out[0] += w * gdist1[b, 0]

    with pytest.raises(TypeError, match=r"typo_term.*'gdist1'.*gdist0"):
        Engine("hold")
    del TERMS["typo_term"]

    @jit
    def last_effort(b, out, lo, effort):  # pragma: no cover
        out[0, lo] = effort[b, 0]

    register_block(ObsBlock("effort_probe", "1", lambda e: 1, lambda e: (np.zeros(1), np.ones(1)), last_effort, "", ""))
    with pytest.raises(TypeError, match=r"'effort_probe'.*reads 'effort', which the reset's observation"):
        Engine("hold", observation=["position", "effort_probe"])


def test_the_docs_spinning_bar_matches_its_geometry(registries):
    """The analytic bars are what the step collides with: the clearance after a step at rest is the distance to the
    bars at t = k T (or to the other agents)."""
    eng = Engine("spinning_bars_test", "double_integrator", "dynamic", follower_noise=0.0)
    s = eng.reset(np.random.default_rng(2), 16)
    for _ in range(6):
        s, _, _, _, _, info = eng.step(s, np.zeros((16, eng.n_l, eng.p)))
    caps = bar_capsules(s.params["spinning_bars"], s.k * eng.dt)
    bar_gap = capsule_distance(s.pos, caps).min(axis=(1, 2)) - eng.agent_radius
    iu, ju = np.triu_indices(eng.n, 1)
    pairs = np.linalg.norm(s.pos[:, iu] - s.pos[:, ju], axis=-1).min(axis=1) - 2 * eng.agent_radius
    assert np.mean(bar_gap < pairs) > 0.25  # the bars are what binds in many episodes
    np.testing.assert_allclose(info["min_clearance"], np.minimum(bar_gap, pairs), atol=1e-9)


_HELPER = "from formation_env.env.kernel import jit\n\n\n@jit\ndef bonus():\n    return {value}\n"
_TERM = """
from formation_env.env.rewards import reward_term

from .helper import bonus


@reward_term("cache_probe", 1.0, "test: a constant from another module")
def cache_probe(b, out, w):
    for i in range(out.shape[0]):
        out[i] += w * bonus()
"""
_RUN = """
import numpy as np
import {pkg}.term
from formation_env.env.engine import Engine
from formation_env.env.rewards import TERMS

eng = Engine("hold", reward_weights={{name: 0.0 for name in TERMS}} | {{"cache_probe": 1.0}})
s = eng.reset(np.random.default_rng(0), 1)
print(float(eng.step(s, np.zeros((1, eng.n_l, eng.p)))[2][0, 0]))
"""


def test_an_edited_component_changes_the_next_process_step(tmp_path):
    """Trap 5: the compiled step covers the source of every module it compiles (here a helper the term calls)."""
    pkg = f"cache_probe_{os.getpid()}_{abs(hash(str(tmp_path))) % 10**6}"
    folder = tmp_path / pkg
    folder.mkdir()
    (folder / "__init__.py").write_text("")
    (folder / "term.py").write_text(textwrap.dedent(_TERM))
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path), str(ROOT)]),
           "FORMATION_ENV_CACHE": str(tmp_path / "steps")}  # fmt: skip
    got = []
    for value in ("1.5", "2.5"):
        (folder / "helper.py").write_text(_HELPER.format(value=value))
        res = subprocess.run([sys.executable, "-c", _RUN.format(pkg=pkg)], capture_output=True, text=True, env=env,
                             timeout=600, cwd=tmp_path)  # fmt: skip
        assert res.returncode == 0, res.stderr[-3000:]
        got.append(float(res.stdout.split()[-1]))
    assert got == [1.5, 2.5]


def test_the_docs_array_table_is_the_declaration():
    """docs/architecture.md holds kernel.array_table() between its markers, row for row."""
    from formation_env.env.kernel import ARRAYS, array_table

    text = (ROOT / "docs" / "architecture.md").read_text()
    start = text.index("<!-- array table: kernel.array_table() -->\n") + len(
        "<!-- array table: kernel.array_table() -->\n"
    )
    end = text.index("\n<!-- end of the array table -->")
    assert text[start:end] == array_table()
    assert len(array_table().splitlines()) == len(ARRAYS) + 2


def test_each_array_has_one_writer_per_phase(monkeypatch):
    """The declaration itself has one writer of each array (each column of flags) in the step and in observe; a
    second part writing one is refused."""
    from formation_env.env import kernel

    for networked in (False, True):  # the network part takes the law's place: one of them is composed
        parts = [p for p in kernel.PART_NAMES if p not in kernel._left_out(networked)]
        for observe in (False, True):
            kernel._check_writers(parts, observe, "declaration")
    with pytest.raises(RuntimeError, match="'act' is written by parts 'law' and 'network'"):
        kernel._check_writers(kernel.PART_NAMES, False, "step")
    relay = kernel.Part("relay", ("pos", "flags:collision"), None, "a part that writes what the law writes")
    monkeypatch.setattr(kernel, "PARTS", (*kernel.PARTS, relay))
    with pytest.raises(RuntimeError, match="'pos' is written by parts 'law' and 'relay'"):
        kernel._check_writers(["law", "relay"], False, "step")
