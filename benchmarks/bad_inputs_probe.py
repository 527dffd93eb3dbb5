"""Throw bad and edge inputs at the public API and classify what happens to each (issue 21).

Every case is one call of a public function, env method or CLI command, with what it should do:

* an **invalid** input must be refused. The outcome is ``clear`` (``FormationError``, ``ValueError`` or
  ``TypeError`` whose message names the argument), ``obscure`` (another exception type, or a message that
  does not name the argument) or ``silent`` (no error at all; for a doubtful input that is legal, a warning
  naming it counts as clear);
* a **valid** edge input must work: ``fine``, or ``refused`` (an error) or ``silent`` (it ran, but its result
  failed the case's own check: silently wrong).

CLI cases run ``formation_env.cli.main`` in-process: ``clear`` is exit code 2 with one line on stderr that
names the flag (argparse's usage line allowed) and no traceback.

Run: ``python -m benchmarks.bad_inputs_probe [--json out.json] [--only core env cli] [-v]`` (about 15 s).
It prints a table of counts per group and class and, with ``-v``, every case that is not clear or fine.
"""

from __future__ import annotations

import argparse
import contextlib
import copy
import io
import json
import os
import pickle
import re
import sys
import tempfile
import time
import traceback
import warnings
from collections.abc import Callable, Iterator
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("SDL_VIDEODRIVER", "dummy")

import numpy as np
import scipy.sparse as sp

CLEAR, OBSCURE, SILENT, FINE, REFUSED = "clear", "obscure", "silent", "fine", "refused"
CLASSES = (CLEAR, OBSCURE, SILENT, FINE, REFUSED)
NAN, INF = float("nan"), float("inf")


@dataclass
class Case:
    """One probe: ``call()`` with the argument(s) its error must name, or a valid edge input (``valid``).

    ``check`` verifies a valid call's result (an AssertionError marks it silently wrong); ``warns`` is the
    warning a legal but doubtful input must raise (naming ``arg``) when it is not refused; ``errors`` are
    other exception types a protocol prescribes (SB3's ``VecEnv.get_attr`` raises ``AttributeError``, on
    which its ``has_attr`` relies).
    """

    group: str
    name: str
    call: Callable[[], Any]
    arg: str | tuple[str, ...] = ()
    valid: bool = False
    check: Callable[[Any], Any] | None = None
    warns: type[Warning] | None = None
    errors: tuple[type[BaseException], ...] = ()


@dataclass
class Outcome:
    """The class of one case and what was seen."""

    group: str
    name: str
    cls: str
    detail: str


@dataclass
class CliRun:
    """Exit code and stderr of one in-process CLI run."""

    rc: int
    err: str


def names(msg: str, arg: str | tuple[str, ...]) -> bool:
    """Whether ``msg`` names one of ``arg`` (a whole word; case-sensitive for names of one or two letters)."""
    for a in (arg,) if isinstance(arg, str) else arg:
        flags = 0 if len(a) <= 2 else re.IGNORECASE
        if re.search(rf"(?<![A-Za-z0-9_]){re.escape(a)}(?![A-Za-z0-9_])", msg, flags):
            return True
    return False


def last_line(text: str) -> str:
    """The last non-blank line of ``text`` (where an error message ends up), cut to 160 characters."""
    return (text.strip().splitlines() or [""])[-1][:160]


def classify(case: Case) -> Outcome:
    """Run one case and classify it."""
    err: BaseException | None = None
    result: Any = None
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            result = case.call()
        except Exception as exc:
            err = exc
    warned = [w for w in caught if case.warns is not None and issubclass(w.category, case.warns)]
    out = lambda cls, detail: Outcome(case.group, case.name, cls, detail)  # noqa: E731
    if isinstance(result, CliRun):
        return _classify_cli(case, result, out)
    if case.valid:
        if err is not None:
            return out(REFUSED, f"{type(err).__name__}: {last_line(str(err))}")
        if case.warns is not None and not warned:
            return out(SILENT, f"no {case.warns.__name__}")
        if case.check is not None:
            try:
                case.check(result)
            except AssertionError as exc:
                return out(SILENT, f"wrong result: {exc}")
        return out(FINE, "")
    if err is None:
        if warned and any(names(str(w.message), case.arg) for w in warned):
            return out(CLEAR, f"warned {warned[0].category.__name__}: {last_line(str(warned[0].message))}")
        return out(SILENT, f"accepted, returned {type(result).__name__}")
    msg = f"{type(err).__name__}: {last_line(str(err))}"
    if isinstance(err, (ValueError, TypeError, *case.errors)) and names(str(err), case.arg):
        return out(CLEAR, msg)
    return out(OBSCURE, msg)


def _classify_cli(case: Case, run: CliRun, out: Callable[[str, str], Outcome]) -> Outcome:
    # argparse's usage block (a "usage:" line and its indented continuations) comes before its one error line
    lines = [ln for ln in run.err.strip().splitlines() if ln.strip() and not ln.startswith(("usage:", " "))]
    if case.valid:
        return out(FINE if run.rc == 0 else REFUSED, f"rc {run.rc}: {last_line(run.err)}")
    if run.rc == 0:
        return out(SILENT, "exit 0")
    last = lines[-1] if lines else ""
    ok = run.rc == 2 and "Traceback" not in run.err and len(lines) == 1 and names(last, case.arg)
    return out(CLEAR if ok else OBSCURE, f"rc {run.rc}, {len(lines)} line(s): {last[:140]}")


def cli(*argv: str) -> CliRun:
    """``formation-env argv`` in-process: exit code and stderr (an exception escaping main: rc -1, traceback)."""
    from formation_env.cli import main

    err, sink = io.StringIO(), io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(sink):
        try:
            rc = main(list(argv))
        except SystemExit as exc:
            rc = exc.code if isinstance(exc.code, int) else 1
        except Exception:
            traceback.print_exc(file=err)
            rc = -1
    return CliRun(int(rc), err.getvalue())


# ---------------------------------------------------------------------------- helpers for the cases
def expect(cond: bool, what: str) -> None:
    """A valid case's check: raise AssertionError(``what``) unless ``cond``."""
    if not cond:
        raise AssertionError(what)


# ---------------------------------------------------------------------------- core cases
def core_cases() -> Iterator[Case]:
    from formation_env.core import (
        AffineImage,
        Framework,
        LawAssumptionWarning,
        LinearDynamics,
        Partition,
        ReachabilityWarning,
        affine_targets,
        c2d_zoh,
        check_stress,
        condition_number,
        dare,
        design_stress,
        dlqr,
        equilibrium_stress_basis,
        extreme_eigenvalues,
        follower_targets,
        hold,
        make_law,
        paper_example,
        paper_omega,
        project_stress,
        riccati_gain,
        rotate,
        rotation,
        scale,
        scaling,
        shear,
        shear_matrix,
        simulate,
        stability_report,
        stress_from_weights,
        translate,
    )
    from formation_env.core import frameworks as lib

    om, fw = paper_omega(), paper_example()
    L = [0, 1, 2]
    x0 = np.array([[1.0, 0.0], [0.0, 1.0], [0.0, -1.0], [-0.3, 0.4], [-1.7, -0.2]])
    si, di = LinearDynamics.single_integrator(2), LinearDynamics.double_integrator(2)
    part = Partition(om, L)
    g = "core"
    asym = om.copy()
    asym[3, 4] += 3
    small_asym = om.copy()
    small_asym[3, 4] += 1e-4
    cplx = om.astype(complex)
    cplx[0, 0] += 1e-3j
    nan_om = om.copy()
    nan_om[0, 0] = NAN
    edges = list(fw.edges)

    def C(name: str, call: Callable[[], Any], arg: str | tuple[str, ...], **kw: Any) -> Case:
        return Case(g, name, call, arg, **kw)

    # --- the worst cases
    yield C("stability_report(omega with [3,4] += 3)", lambda: stability_report(asym, L, 1.0), "omega")
    yield C("simulate(omega with [3,4] += 3)", lambda: simulate(asym, L, x0, 1.0, 180), "omega")
    yield C("follower_targets(omega, small asymmetry)", lambda: follower_targets(small_asym, L, x0[:3]), "omega")
    yield C("simulate(omega, small asymmetry)", lambda: simulate(small_asym, L, x0, 1.0, 50), "omega")
    yield C("follower_targets(zeros)", lambda: follower_targets(np.zeros((5, 5)), L, x0[:3]), "omega")
    yield C("stability_report(zeros)", lambda: stability_report(np.zeros((5, 5)), L, 1.0), "omega")
    yield C("follower_targets(sparse asymmetric)", lambda: follower_targets(sp.csr_matrix(asym), L, x0[:3]), "omega")

    # --- omega in general
    for fn_name, fn in (
        ("follower_targets", lambda o: follower_targets(o, L, x0[:3])),
        ("stability_report", lambda o: stability_report(o, L, 1.0)),
        ("simulate", lambda o: simulate(o, L, x0, 1.0, 5)),
        ("check_stress", lambda o: check_stress(o, fw)),
    ):
        for label, bad in (
            ("None", None),
            ("'abc'", "abc"),
            ("NaN entry", nan_om),
            ("complex", cplx),
            ("(5, 4)", om[:, :4]),
            ("(4, 4)", om[:4, :4]),
            ("1-D", om[0]),
        ):
            yield C(f"{fn_name}(omega={label})", lambda fn=fn, bad=bad: fn(bad), "omega")
    yield C("check_stress(asymmetric)", lambda: check_stress(asym, fw), "omega")
    yield C("check_stress(row sums off)", lambda: check_stress(om + np.eye(5) * 0.1, fw), ("omega", "row"))
    yield C("check_stress(fw=None)", lambda: check_stress(om, None), "fw")
    yield C("check_stress(fw='paper')", lambda: check_stress(om, "paper"), "fw")
    for r in (NAN, -1.0, 2.0, "1e-3", None, 1j):
        yield C(f"check_stress(rtol={r!r})", lambda r=r: check_stress(om, fw, rtol=r), "rtol")
    yield C("check_stress(check_graph='yes')", lambda: check_stress(om, fw, check_graph="yes"), "check_graph")
    yield C(
        "check_stress(printed omega, its tolerance)",
        lambda: check_stress(paper_omega(exact=False), fw, 2e-3),
        (),
        valid=True,
    )

    # --- leaders and indices
    for fn_name, fn in (
        ("follower_targets", lambda ld: follower_targets(om, ld, x0[:3])),
        ("stability_report", lambda ld: stability_report(om, ld, 1.0)),
        ("simulate", lambda ld: simulate(om, ld, x0, 1.0, 5)),
        ("Partition", lambda ld: Partition(om, ld)),
        ("condition_number", lambda ld: condition_number(om, ld)),
    ):
        for label, bad in (
            ("None", None),
            ("(0.7, 3.9)", (0.7, 3.9)),
            ("[0, 1, 9]", [0, 1, 9]),
            ("[0, 0, 1]", [0, 0, 1]),
            ("'012'", "012"),
            ("[-1, 1, 2]", [-1, 1, 2]),
            ("3 (int)", 3),
            ("all agents", [0, 1, 2, 3, 4]),
        ):
            yield C(f"{fn_name}(leaders={label})", lambda fn=fn, bad=bad: fn(bad), "leaders")
    yield C(
        "follower_targets(leaders=np.array([0, 1, 2]))",
        lambda: follower_targets(om, np.arange(3), x0[:3]),
        (),
        valid=True,
    )
    yield C(
        "follower_targets(leaders=(0.0, 1.0, 2.0))", lambda: follower_targets(om, (0.0, 1.0, 2.0), x0[:3]), "leaders"
    )

    # --- x_leaders
    for label, bad in (
        ("None", None),
        ("(2, 2)", x0[:2]),
        ("NaN", x0[:3] * NAN),
        ("complex", x0[:3] + 1j),
        ("1-D", x0[0]),
        ("'x'", "x"),
    ):
        yield C(f"follower_targets(x_leaders={label})", lambda bad=bad: follower_targets(om, L, bad), "x_leaders")
    yield C("follower_targets(check='no')", lambda: follower_targets(om, L, x0[:3], check="no"), "check")
    yield C(
        "follower_targets(batched (4, 3, 2))",
        lambda: follower_targets(om, L, np.zeros((4, 3, 2))),
        (),
        valid=True,
        check=lambda r: expect(r.shape == (4, 2, 2), f"shape {r.shape}"),
    )

    # --- Framework
    for label, bad in (
        ("None", None),
        ("'abc'", "abc"),
        ("NaN", fw.positions * NAN),
        ("complex", fw.positions + 1j),
        ("1-D", fw.positions[:, 0]),
        ("ragged", [[0, 1], [2]]),
        ("(5, 0)", np.zeros((5, 0))),
        ("3 agents in 2D", fw.positions[:3]),
    ):
        yield C(f"Framework(positions={label})", lambda bad=bad: Framework(bad, edges, L), "positions")
    for label, bad in (
        ("None", None),
        ("'01'", "01"),
        ("[(0, 0.7)]", [(0, 0.7)]),
        ("[(0, 9)]", [(0, 9)]),
        ("[(0,)]", [(0,)]),
        ("[(1, 1)]", [(1, 1)]),
        ("5", 5),
        ("[(0, -1)]", [(0, -1)]),
    ):
        yield C(f"Framework(edges={label})", lambda bad=bad: Framework(fw.positions, bad, L), "edges")
    for label, bad in (
        ("None", None),
        ("(0.7, 3.9)", (0.7, 3.9)),
        ("[0, 1, 9]", [0, 1, 9]),
        ("[0, 0, 1]", [0, 0, 1]),
        ("[0, 1] (no span)", [0, 1]),
        ("all", range(5)),
    ):
        yield C(f"Framework(leaders={label})", lambda bad=bad: Framework(fw.positions, edges, bad), "leaders")
    line = [[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [0.0, 1.0], [1.0, 1.0]]
    yield C("Framework(leaders collinear)", lambda: Framework(line, edges, L), "leaders")
    yield C("Framework(name=5)", lambda: Framework(fw.positions, edges, L, name=5), "name")
    yield C("Framework(cliques=(2, 2))", lambda: Framework(fw.positions, edges, L, cliques=[[0, 1], [2, 3]]), "cliques")
    yield C(
        "Framework(edges=np.int32 array)", lambda: Framework(fw.positions, np.array(edges, np.int32), L), (), valid=True
    )

    # --- design_stress
    yield C("design_stress(fw=None)", lambda: design_stress(None), "fw")
    yield C("design_stress(fw='paper')", lambda: design_stress("paper"), "fw")
    yield C("design_stress(method='bogus')", lambda: design_stress(fw, "bogus"), "method")
    yield C("design_stress(method=None)", lambda: design_stress(fw, None), "method")
    yield C("design_stress(rtol=nan)", lambda: design_stress(fw, "sdp", rtol=NAN), "rtol")
    yield C("design_stress(rtol=-1)", lambda: design_stress(fw, "sdp", rtol=-1.0), "rtol")
    yield C("design_stress(sparse='yes')", lambda: design_stress(fw, "sdp", sparse="yes"), "sparse")
    yield C("design_stress(verbose='x')", lambda: design_stress(fw, "sdp", verbose="x"), "verbose")
    yield C("design_stress(solver='NOPE')", lambda: design_stress(fw, "sdp", solver="NOPE"), "solver")
    yield C(
        "design_stress(constructive, no cliques)",
        lambda: design_stress(lib.hexagon(), "constructive"),
        ("cliques", "trilateration"),
    )
    yield C(
        "design_stress(cliques wrong shape)", lambda: design_stress(fw, "constructive", cliques=[[0, 1]]), "cliques"
    )
    yield C(
        "design_stress(paper, sdp)",
        lambda: design_stress(fw, "sdp"),
        (),
        valid=True,
        check=lambda o: check_stress(o, fw),
    )

    # --- stress_from_weights
    w1 = [1.0] * len(edges)
    for label, bad in (("None", None), ("0", 0), ("2.5", 2.5), ("'5'", "5"), ("True", True), ("-3", -3)):
        yield C(f"stress_from_weights(n={label})", lambda bad=bad: stress_from_weights(bad, edges, w1), "n")
    for label, bad in (
        ("[(0, 9)]", [(0, 9)]),
        ("[(0.7, 3.9)]", [(0.7, 3.9)]),
        ("[(2, 2)]", [(2, 2)]),
        ("None", None),
        ("[(0, 1, 2)]", [(0, 1, 2)]),
        ("'01'", "01"),
    ):
        yield C(f"stress_from_weights(edges={label})", lambda bad=bad: stress_from_weights(5, bad, [1.0]), "edges")
    for label, bad in (
        ("None", None),
        ("NaN", [NAN] * len(edges)),
        ("too short", [1.0]),
        ("complex", [1j] * len(edges)),
        ("'abc'", "abc"),
        ("2-D", np.ones((len(edges), 1))),
    ):
        yield C(f"stress_from_weights(weights={label})", lambda bad=bad: stress_from_weights(5, edges, bad), "weights")
    yield C("stress_from_weights(sparse='x')", lambda: stress_from_weights(5, edges, w1, sparse="x"), "sparse")
    yield C(
        "stress_from_weights(no edges)",
        lambda: stress_from_weights(5, np.zeros((0, 2), int), []),
        (),
        valid=True,
        check=lambda m: expect(m.shape == (5, 5) and not m.any(), "not a zero 5x5"),
    )

    # --- stability_report
    for label, bad in (
        ("'0.1'", "0.1"),
        ("nan", NAN),
        ("-1", -1.0),
        ("0", 0.0),
        ("inf", INF),
        ("None", None),
        ("1j", 1j),
        ("[0.1]", [0.1]),
        ("True", True),
    ):
        yield C(f"stability_report(dt={label})", lambda bad=bad: stability_report(om, L, bad), "dt")
    for label, bad in (("'bogus'", "bogus"), ("None", None), ("5", 5)):
        yield C(f"stability_report(law={label})", lambda bad=bad: stability_report(om, L, 1.0, bad), "law")
    yield C(
        "stability_report(dynamics in 3D)",
        lambda: stability_report(om, L, 0.5, "dynamic", LinearDynamics.single_integrator(3)),
        (),
        valid=True,
    )
    for label, bad in (("'double'", "double"), ("5", 5)):
        yield C(
            f"stability_report(dynamics={label})",
            lambda bad=bad: stability_report(om, L, 1.0, "dynamic", bad),
            "dynamics",
        )
    for label, bad in (("nan", NAN), ("-1", -1.0), ("'x'", "x")):
        yield C(f"stability_report(rtol={label})", lambda bad=bad: stability_report(om, L, 1.0, rtol=bad), "rtol")
    for label, bad in (
        ("(1, 0.1)", (1.0, 0.1)),
        ("(-1, 1)", (-1.0, 1.0)),
        ("'x'", "x"),
        ("(0.1,)", (0.1,)),
        ("(0.1, nan)", (0.1, NAN)),
    ):
        yield C(
            f"stability_report(dt_search={label})",
            lambda bad=bad: stability_report(om, L, 1.0, dt_search=bad),
            "dt_search",
        )
    yield C("stability_report(check='x')", lambda: stability_report(om, L, 1.0, check="x"), "check")
    yield C("stability_report(foo=1)", lambda: stability_report(om, L, 1.0, foo=1), "foo")
    yield C("stability_report(gain=-1)", lambda: stability_report(om, L, 1.0, gain=-1.0), "gain")
    yield C(
        "stability_report(dynamic, di, gain=nan)", lambda: stability_report(om, L, 0.1, "dynamic", di, gain=NAN), "gain"
    )
    yield C(
        "stability_report(rounds=0)", lambda: stability_report(om, L, 0.1, "dynamic_distributed", rounds=0), "rounds"
    )
    yield C(
        "stability_report(rounds=1.5)",
        lambda: stability_report(om, L, 0.1, "dynamic_distributed", rounds=1.5),
        "rounds",
    )
    osc = oscillator()
    yield C(
        "stability_report(dynamic_distributed, oscillator, dt=0.05): windows",
        lambda: stability_report(om, L, 0.05, "dynamic_distributed", osc),
        (),
        valid=True,
        check=lambda r: expect(
            bool(r.windows) and abs(r.windows[0][0] - 2.178) < 5e-3 and abs(r.windows[0][1] - 4.307) < 5e-3,
            f"windows {r.windows}",
        ),
    )
    yield C(
        "stability_report(stationary): T_opt",
        lambda: stability_report(om, L, 0.5),
        (),
        valid=True,
        check=lambda r: expect(r.dt_opt is not None and r.rho_opt < 1, f"dt_opt {r.dt_opt}"),
    )
    yield C("stability_report(sparse omega)", lambda: stability_report(sp.csr_matrix(om), L, 0.5), (), valid=True)

    # --- simulate
    for label, bad in (
        ("None", None),
        ("(4, 2)", x0[:4]),
        ("NaN", x0 * NAN),
        ("complex", x0 + 1j),
        ("'abc'", "abc"),
        ("(5, 3) with double integrators in 2D", np.zeros((5, 3))),
    ):
        yield C(f"simulate(x0={label})", lambda bad=bad: simulate(om, L, bad, 0.1, 5, "dynamic", None, di), "x0")
    yield C(
        "simulate(x0 (5, 3): 3D single integrators)",
        lambda: simulate(om, L, np.ones((5, 3)), 0.5, 5),
        (),
        valid=True,
        check=lambda t: expect(t.shape == (6, 5, 3), f"shape {t.shape}"),
    )
    for label, bad in (("'1.0'", "1.0"), ("nan", NAN), ("0", 0.0), ("-0.1", -0.1), ("None", None), ("inf", INF)):
        yield C(f"simulate(dt={label})", lambda bad=bad: simulate(om, L, x0, bad, 5), "dt")
    for label, bad in (
        ("nan", NAN),
        ("inf", INF),
        ("-1", -1),
        ("1.5", 1.5),
        ("None", None),
        ("'10'", "10"),
        ("10.0", 10.0),
    ):
        yield C(f"simulate(steps={label})", lambda bad=bad: simulate(om, L, x0, 1.0, bad), "steps")
    yield C(
        "simulate(steps=0)",
        lambda: simulate(om, L, x0, 1.0, 0),
        (),
        valid=True,
        check=lambda t: expect(t.shape == (1, 5, 2) and np.array_equal(t[0], x0), f"shape {t.shape}"),
    )
    yield C("simulate(law='bogus')", lambda: simulate(om, L, x0, 1.0, 5, "bogus"), "law")
    yield C("simulate(leader_path=5)", lambda: simulate(om, L, x0, 1.0, 5, "stationary", 5), "leader_path")
    yield C(
        "simulate(leader_path -> (2, 2))",
        lambda: simulate(om, L, x0, 1.0, 5, "stationary", lambda k: x0[:2]),
        "leader_path",
    )
    yield C(
        "simulate(leader_path -> NaN)",
        lambda: simulate(om, L, x0, 1.0, 5, "stationary", lambda k: x0[:3] * NAN),
        "leader_path",
    )
    yield C("simulate(dynamics='double')", lambda: simulate(om, L, x0, 1.0, 5, "dynamic", None, "double"), "dynamics")
    yield C(
        "simulate(require_stable_law='x')",
        lambda: simulate(om, L, x0, 1.0, 5, require_stable_law="x"),
        "require_stable_law",
    )
    yield C("simulate(return_result='x')", lambda: simulate(om, L, x0, 1.0, 5, return_result="x"), "return_result")
    yield C("simulate(foo=1)", lambda: simulate(om, L, x0, 1.0, 5, foo=1), "foo")
    yield C(
        "simulate(dt=5, require_stable_law)", lambda: simulate(om, L, x0, 5.0, 5, require_stable_law=True), ("dt", "T")
    )
    yield C(
        "simulate(stationary, di)",
        lambda: simulate(om, L, np.zeros((5, 4)), 0.1, 5, "stationary", None, di),
        ("stationary", "law"),
    )
    inter = interleaved_double_integrator()
    path = lambda k: fw.positions[:3] + 0.05 * k * np.array([1.0, 0.5])  # noqa: E731

    def on_path(res: Any) -> None:
        off = max(float(np.abs(res.positions[k, :3] - path(k)).max()) for k in range(21))
        expect(off < 1e-9, f"leaders {off:.3g} m off the path")

    yield C(
        "simulate(state [px, vx, py, vy], position path): leaders on path",
        lambda: simulate(om, L, x0, 0.1, 20, "dynamic", path, inter, return_result=True),
        (),
        valid=True,
        check=on_path,
    )
    wobble = lambda k: fw.positions[:3] * (1 + 0.1 * np.sin(0.3 * k))  # noqa: E731
    yield C(
        "simulate(di, unreachable position path)",
        lambda: simulate(om, L, x0, 0.1, 30, "dynamic", wobble, di),
        "leader_path",
        warns=ReachabilityWarning,
    )
    held = lambda k: fw.positions[:3]  # noqa: E731
    yield C(
        "simulate(linear, oscillator, leaders held)",
        lambda: simulate(om, L, x0, 0.1, 10, "linear", held, osc),
        ("leaders", "linear"),
        warns=LawAssumptionWarning,
    )

    # --- LinearDynamics
    for label, bad in (
        ("None", None),
        ("(2, 3)", np.zeros((2, 3))),
        ("NaN", np.full((2, 2), NAN)),
        ("complex", np.eye(2) * 1j),
        ("(0, 0)", np.zeros((0, 0))),
        ("'abc'", "abc"),
    ):
        yield C(f"LinearDynamics(A={label})", lambda bad=bad: LinearDynamics(bad, np.eye(2)), "A")
    for label, bad in (
        ("(3, 2)", np.eye(3)[:, :2]),
        ("(2, 0)", np.zeros((2, 0))),
        ("rank 1", np.ones((2, 2))),
        ("None", None),
        ("inf", np.full((2, 2), INF)),
    ):
        yield C(f"LinearDynamics(B={label})", lambda bad=bad: LinearDynamics(np.zeros((2, 2)), bad), "B")
    for label, bad in (
        ("(1, 3)", np.ones((1, 3))),
        ("rank 1", np.ones((2, 2))),
        ("(0, 2)", np.zeros((0, 2))),
        ("'abc'", "abc"),
    ):
        yield C(f"LinearDynamics(C={label})", lambda bad=bad: LinearDynamics(np.zeros((2, 2)), np.eye(2), bad), "C")
    yield C("LinearDynamics(discrete='yes')", lambda: LinearDynamics(np.eye(2), np.eye(2), discrete="yes"), "discrete")
    yield C("LinearDynamics(name=5)", lambda: LinearDynamics(np.eye(2), np.eye(2), name=5), "name")
    for ctor in ("single_integrator", "double_integrator"):
        for label, bad in (
            ("0", 0),
            ("-1", -1),
            ("1.5", 1.5),
            ("'2'", "2"),
            ("None", None),
            ("True", True),
            ("2.0", 2.0),
        ):
            yield C(f"LinearDynamics.{ctor}(d={label})", lambda c=ctor, bad=bad: getattr(LinearDynamics, c)(bad), "d")
    yield C(
        "LinearDynamics.double_integrator(d=np.int64(3))",
        lambda: LinearDynamics.double_integrator(np.int64(3)),
        (),
        valid=True,
        check=lambda dy: expect(dy.q == 6, f"q {dy.q}"),
    )
    for label, bad in (("0", 0.0), ("nan", NAN), ("'x'", "x")):
        yield C(f"LinearDynamics.zoh(dt={label})", lambda bad=bad: di.zoh(bad), "dt")
    yield C(
        "LinearDynamics.state_from_position((4, 2))",
        lambda: di.state_from_position(np.zeros((4, 3))),
        ("pos", "position"),
    )

    # --- c2d_zoh, dare, dlqr, riccati_gain
    A2, B2 = np.array([[0.0, 1.0], [0.0, 0.0]]), np.array([[0.0], [1.0]])
    for label, bad in (("0", 0.0), ("-1", -1.0), ("nan", NAN), ("'0.1'", "0.1"), ("None", None), ("inf", INF)):
        yield C(f"c2d_zoh(dt={label})", lambda bad=bad: c2d_zoh(A2, B2, bad), "dt")
    yield C("c2d_zoh(A=(2, 3))", lambda: c2d_zoh(np.zeros((2, 3)), B2, 0.1), "A")
    yield C("c2d_zoh(A=None)", lambda: c2d_zoh(None, B2, 0.1), "A")
    yield C("c2d_zoh(B=(3, 1))", lambda: c2d_zoh(A2, np.ones((3, 1)), 0.1), "B")
    yield C("c2d_zoh(B complex)", lambda: c2d_zoh(A2, B2 * 1j, 0.1), "B")
    Ad, Bd = c2d_zoh(A2, B2, 0.1)
    yield C("dlqr(R=None)", lambda: dlqr(Ad, Bd, np.eye(2), None), "R")
    yield C("dlqr(Q=None)", lambda: dlqr(Ad, Bd, None, np.eye(1)), "Q")
    yield C("dlqr(R=(2, 2))", lambda: dlqr(Ad, Bd, np.eye(2), np.eye(2)), "R")
    yield C("dlqr(R=-1)", lambda: dlqr(Ad, Bd, np.eye(2), -np.eye(1)), "R")
    yield C("dlqr(Q indefinite)", lambda: dlqr(Ad, Bd, np.diag([1.0, -1.0]), np.eye(1)), "Q")
    yield C("dlqr(Q asymmetric)", lambda: dlqr(Ad, Bd, np.array([[1.0, 0.5], [0.0, 1.0]]), np.eye(1)), "Q")
    yield C("dlqr(A NaN)", lambda: dlqr(Ad * NAN, Bd, np.eye(2), np.eye(1)), "A")
    yield C("dlqr(Q='I')", lambda: dlqr(Ad, Bd, "abc", np.eye(1)), "Q")
    yield C("dare(Q=(3, 3))", lambda: dare(Ad, Bd, np.eye(3)), "Q")
    yield C("dare(B rank 0)", lambda: dare(Ad, np.zeros((2, 1))), "B")
    yield C("dare(A=None)", lambda: dare(None, Bd), "A")
    yield C(
        "dare(not stabilisable)",
        lambda: dare(np.diag([2.0, 0.5]), np.array([[0.0], [1.0]]), None, np.eye(1)),
        ("A, B", "stabilis"),
    )
    yield C("riccati_gain(A='x')", lambda: riccati_gain("x", Bd), "A")
    yield C("riccati_gain(R=nan)", lambda: riccati_gain(Ad, Bd, None, [[NAN]]), "R")
    yield C(
        "dlqr(double integrator)",
        lambda: dlqr(Ad, Bd, np.eye(2), np.eye(1)),
        (),
        valid=True,
        check=lambda r: expect(np.all(np.abs(r[2]) < 1), "closed loop not stable"),
    )

    # --- make_law and Partition
    for label, kw in (("gain=-1", {"gain": -1.0}), ("gain=nan", {"gain": NAN}), ("gain='1'", {"gain": "1"})):
        for law in ("dynamic", "dynamic_distributed"):
            yield C(
                f"make_law({law}, double integrators, {label})",
                lambda law=law, kw=kw: make_law(law, part, di, 0.1, **kw),
                "gain",
            )
    yield C("make_law(stationary, gain=0)", lambda: make_law("stationary", part, si, 0.1, gain=0.0), "gain")
    yield C("make_law(linear, eps=0)", lambda: make_law("linear", part, di, 0.1, eps=0.0), "eps")
    yield C("make_law(linear, eps=inf)", lambda: make_law("linear", part, di, 0.1, eps=INF), "eps")
    yield C(
        "make_law(dynamic_distributed, rounds=0)",
        lambda: make_law("dynamic_distributed", part, di, 0.1, rounds=0),
        "rounds",
    )
    yield C("make_law(dynamic, K=(2, 2))", lambda: make_law("dynamic", part, di, 0.1, K=np.eye(2)), "K")
    yield C("make_law(linear, Q=(2, 2))", lambda: make_law("linear", part, di, 0.1, Q=np.eye(2)), "Q")
    yield C("make_law(stationary, eps=1)", lambda: make_law("stationary", part, si, 0.1, eps=1.0), "eps")
    yield C("make_law(law=None)", lambda: make_law(None, part, si, 0.1), "law")
    yield C("make_law(law='bogus')", lambda: make_law("bogus", part, si, 0.1), "law")
    yield C("make_law(part=omega)", lambda: make_law("stationary", om, si, 0.1), "part")
    yield C("make_law(dynamics=None)", lambda: make_law("stationary", part, None, 0.1), "dynamics")
    yield C("make_law(dt='0.1')", lambda: make_law("stationary", part, si, "0.1"), "dt")
    yield C("Partition(omega=None)", lambda: Partition(None, L), "omega")

    # --- trilateration and the other frameworks
    for label, kw, arg in (
        ("n=3", {"n": 3}, "n"),
        ("n=None", {"n": None}, "n"),
        ("n=1.5", {"n": 1.5}, "n"),
        ("n='100'", {"n": "100"}, "n"),
        ("d=0", {"d": 0}, "d"),
        ("d=2.0", {"d": 2.0}, "d"),
        ("seed=-1", {"seed": -1}, "seed"),
        ("seed=1.5", {"seed": 1.5}, "seed"),
        ("seed='x'", {"seed": "x"}, "seed"),
        ("seed=None", {"seed": None}, "seed"),
        ("n_leaders=2", {"n_leaders": 2}, "n_leaders"),
        ("n_leaders=30", {"n_leaders": 30}, "n_leaders"),
        ("n_leaders=3.5", {"n_leaders": 3.5}, "n_leaders"),
        ("n_leaders=-1", {"n_leaders": -1}, "n_leaders"),
    ):
        yield C(f"trilateration({label})", lambda kw=kw: lib.trilateration(**{"n": 30, "d": 2, **kw}), arg)

    def cond_ok(fw10k: Any) -> None:
        om10k = design_stress(fw10k, "constructive")
        lo, hi = extreme_eigenvalues(Partition(om10k, fw10k.leaders))
        expect(hi / lo <= 1e3, f"cond {hi / lo:.0f} > 1e3")

    yield C(
        "trilateration(10000, 2, n_leaders=100): cond <= 1e3",
        lambda: lib.trilateration(10_000, 2, n_leaders=100),
        (),
        valid=True,
        check=cond_ok,
    )
    for fn_name, kw, arg in (
        ("hexagon", {"radius": 0.0}, "radius"),
        ("hexagon", {"radius": -1.0}, "radius"),
        ("hexagon", {"radius": NAN}, "radius"),
        ("hexagon", {"radius": "1"}, "radius"),
        ("square_grid", {"rows": 1}, "rows"),
        ("square_grid", {"rows": 2.5}, "rows"),
        ("square_grid", {"spacing": 0.0}, "spacing"),
        ("square_grid", {"cols": None}, "cols"),
        ("triangle_formation", {"rows": 1}, "rows"),
        ("triangle_formation", {"spacing": -1.0}, "spacing"),
        ("bipyramid", {"k": 2}, "k"),
        ("bipyramid", {"radius": 0.0}, "radius"),
        ("bipyramid", {"height": INF}, "height"),
        ("octahedron", {"radius": NAN}, "radius"),
        ("cube_with_center", {"side": 0.0}, "side"),
        ("helix", {"n": 2}, "n"),
        ("helix", {"per_turn": 0.0}, "per_turn"),
        ("helix", {"pitch": NAN}, "pitch"),
        ("random_knn", {"n": 3}, "n"),
        ("random_knn", {"k": 0}, "k"),
        ("random_knn", {"seed": -1}, "seed"),
        ("random_knn", {"d": 0}, "d"),
    ):
        yield C(
            f"{fn_name}({', '.join(f'{k}={v!r}' for k, v in kw.items())})",
            lambda fn_name=fn_name, kw=kw: getattr(lib, fn_name)(**kw),
            arg,
        )
    yield C("get_framework('nope')", lambda: lib.get_framework("nope"), ("name", "nope"))
    yield C("get_framework('hexagon', foo=1)", lambda: lib.get_framework("hexagon", foo=1), "foo")
    yield C("farthest_point_leaders(count=0)", lambda: lib.farthest_point_leaders(fw.positions, 0), "count")
    yield C("farthest_point_leaders(count=1.5)", lambda: lib.farthest_point_leaders(fw.positions, 1.5), "count")
    yield C("farthest_point_leaders(fixed=[9])", lambda: lib.farthest_point_leaders(fw.positions, 3, [9]), "fixed")
    yield C("spread_leaders(count=1)", lambda: lib.spread_leaders(fw.positions, 1), "count")
    yield C("equilibrium_stress_basis(fw=None)", lambda: equilibrium_stress_basis(None), "fw")
    yield C("equilibrium_stress_basis(rtol=-1)", lambda: equilibrium_stress_basis(fw, -1.0), "rtol")
    yield C("project_stress(omega (4, 4))", lambda: project_stress(om[:4, :4], fw), "omega")
    yield C("project_stress(rtol=nan)", lambda: project_stress(om, fw, NAN), "rtol")
    yield C("extreme_eigenvalues(part=omega)", lambda: extreme_eigenvalues(om), "part")
    yield C("condition_number(omega=None)", lambda: condition_number(None, L), "omega")

    # --- affine helpers
    r = fw.positions
    for label, th, b, arg in (
        ("theta (3, 3)", np.eye(3), np.zeros(2), "theta"),
        ("b (3,)", np.eye(2), np.zeros(3), "b"),
        ("theta NaN", np.eye(2) * NAN, np.zeros(2), "theta"),
        ("b None", np.eye(2), None, "b"),
        ("theta complex", np.eye(2) * 1j, np.zeros(2), "theta"),
    ):
        yield C(f"affine_targets({label})", lambda th=th, b=b: affine_targets(r, th, b), arg)
    yield C("affine_targets(r=None)", lambda: affine_targets(None, np.eye(2), np.zeros(2)), "r")
    yield C("rotation(angle=nan)", lambda: rotation(NAN), "angle")
    yield C("rotation(angle='x')", lambda: rotation("x"), "angle")
    yield C("rotation(angle=None)", lambda: rotation(None), "angle")
    yield C("rotation(axis=[0, 0, 0])", lambda: rotation(0.1, [0.0, 0.0, 0.0]), "axis")
    yield C("rotation(axis=[1, 0])", lambda: rotation(0.1, [1.0, 0.0]), "axis")
    yield C("scaling(0)", lambda: scaling(1.0, 0.0), ("factors", "scaling"))
    yield C("scaling(nan)", lambda: scaling(NAN, 1.0), ("factors", "scaling"))
    yield C("scaling()", lambda: scaling(), ("factors", "scaling"))
    yield C("shear_matrix(nan)", lambda: shear_matrix(NAN), "amount")
    yield C("shear_matrix(i=j)", lambda: shear_matrix(0.5, 2, 0, 0), ("i", "j", "axes"))
    yield C("shear_matrix(d=1.5)", lambda: shear_matrix(0.5, 1.5), "d")
    yield C("translate([nan, 0])", lambda: translate([NAN, 0.0]), "offset")
    yield C("translate(stop=nan)", lambda: translate([1.0, 0.0], 0.0, NAN), "stop")
    yield C("translate(start='0')", lambda: translate([1.0, 0.0], "0"), "start")
    yield C("rotate(angle=nan)", lambda: rotate(NAN), "angle")
    yield C("rotate(angle=inf)", lambda: rotate(INF), "angle")
    yield C("scale(0)", lambda: scale(0.0), "factors")
    yield C("scale(nan)", lambda: scale(NAN), "factors")
    yield C("scale(-1)", lambda: scale(-1.0), "factors")
    yield C("scale(d=0)", lambda: scale(2.0, d=0), "d")
    yield C("shear(i=j)", lambda: shear(0.5, i=1, j=1), ("i", "j", "axes"))
    yield C("shear(amount=nan)", lambda: shear(NAN), "amount")
    yield C("hold(d=0)", lambda: hold(0), "d")
    yield C("hold(theta=(3, 3), d=2)", lambda: hold(2, np.eye(3)), "theta")
    yield C("hold(b NaN)", lambda: hold(2, None, [NAN, 0.0]), "b")
    yield C("AffineImage(r=None)", lambda: AffineImage(None), "r")
    yield C("AffineImage(r collinear)", lambda: AffineImage([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]]), "r")
    yield C("Maneuver.leader_path(dt=0)", lambda: translate([1.0, 0.0]).leader_path(r[:3], 0.0), "dt")
    yield C(
        "scale(2.0)(t=0.5)",
        lambda: scale(2.0, 0.0, 1.0)(0.5),
        (),
        valid=True,
        check=lambda tb: expect(np.allclose(np.diag(tb[0]), 1.5), f"{tb[0]}"),
    )


def oscillator(c: float = 0.2) -> Any:
    """Damped oscillator per axis, state [px, py, vx, vy]: pdd = -p - c pd + u."""
    from formation_env.core import LinearDynamics

    return LinearDynamics(
        np.kron([[0, 1], [-1, -c]], np.eye(2)), np.kron([[0], [1]], np.eye(2)), np.kron([[1, 0]], np.eye(2))
    )


def interleaved_double_integrator() -> Any:
    """Double integrator with state [px, vx, py, vy]; C picks the positions."""
    from formation_env.core import LinearDynamics

    a = np.kron(np.eye(2), [[0, 1], [0, 0]])
    b = np.kron(np.eye(2), [[0], [1]])
    return LinearDynamics(a, b, np.kron(np.eye(2), [[1, 0]]))


# ---------------------------------------------------------------------------- env cases
def env_cases() -> Iterator[Case]:
    import gymnasium as gym

    import formation_env
    from formation_env import formation_v0, formation_v1
    from formation_env.core import Framework, LinearDynamics, paper_omega
    from formation_env.core.frameworks import octahedron
    from formation_env.env.commander import FormationCommanderEnv
    from formation_env.env.engine import Engine
    from formation_env.env.vector import FormationVecEnv, GymnasiumFormationVecEnv

    g = "env"

    def C(name: str, call: Callable[[], Any], arg: str | tuple[str, ...], **kw: Any) -> Case:
        return Case(g, name, call, arg, **kw)

    # --- Engine arguments (each also reaches parallel_env, the commander and the vec env through **kwargs)
    bad_args: list[tuple[str, Any, str | tuple[str, ...]]] = [
        ("scenario", "maze", "scenario"),
        ("scenario", None, "scenario"),
        ("scenario", 5, "scenario"),
        ("dynamics", "triple_integrator", "dynamics"),
        ("dynamics", None, "dynamics"),
        ("dynamics", 5, "dynamics"),
        ("dynamics", LinearDynamics.single_integrator(3), "dynamics"),
        ("follower_law", "bogus", "follower_law"),
        ("follower_law", None, "follower_law"),
        ("follower_law", "linear_paper", "follower_law"),
        ("follower_law", "stationary", "follower_law"),
        ("dt", "0.1", "dt"),
        ("dt", NAN, "dt"),
        ("dt", 0.0, "dt"),
        ("dt", -0.1, "dt"),
        ("dt", INF, "dt"),
        ("dt", None, "dt"),
        ("dt", [0.1], "dt"),
        ("max_cycles", None, "max_cycles"),
        ("max_cycles", 0, "max_cycles"),
        ("max_cycles", 1.5, "max_cycles"),
        ("max_cycles", -5, "max_cycles"),
        ("max_cycles", "400", "max_cycles"),
        ("max_cycles", 400.0, "max_cycles"),
        ("framework", "nope", "framework"),
        ("framework", 5, "framework"),
        ("framework", "_paper", "framework"),
        ("omega", np.eye(3), "omega"),
        ("omega", "abc", "omega"),
        ("law_params", {"gain": -1}, "gain"),
        ("law_params", {"gain": NAN}, "gain"),
        ("law_params", {"foo": 1}, "foo"),
        ("law_params", "gain", "law_params"),
        ("law_params", {"rounds": 0}, "rounds"),
        ("law_params", {"K": np.eye(2)}, "K"),
        ("u_max", 0.0, "u_max"),
        ("u_max", NAN, "u_max"),
        ("u_max", "1", "u_max"),
        ("u_max", -1.0, "u_max"),
        ("agent_radius", -0.1, "agent_radius"),
        ("agent_radius", NAN, "agent_radius"),
        ("agent_radius", None, "agent_radius"),
        ("n_rays", -1, "n_rays"),
        ("n_rays", 1.5, "n_rays"),
        ("n_rays", None, "n_rays"),
        ("n_nearest", -1, "n_nearest"),
        ("n_nearest", "2", "n_nearest"),
        ("sensor_range", 0.0, "sensor_range"),
        ("sensor_range", INF, "sensor_range"),
        ("max_speed", -1.0, "max_speed"),
        ("max_speed", NAN, "max_speed"),
        ("reward_weights", {"progress": NAN}, "progress"),
        ("reward_weights", {"nope": 1.0}, "nope"),
        ("reward_weights", "x", "reward_weights"),
        ("reward_weights", {"progress": "1"}, "progress"),
        ("reward_weights", {"progress": INF}, "progress"),
        ("observation", ["nope"], ("nope", "observation")),
        ("observation", "position", "observation"),
        ("observation", [], "observation"),
        ("observation", 5, "observation"),
        ("observation", ["position", "position"], ("position", "observation")),
        ("k_nearest", -1, "k_nearest"),
        ("k_nearest", 2.5, "k_nearest"),
        ("sense_radius", 0.0, "sense_radius"),
        ("sense_radius", NAN, "sense_radius"),
        ("sense_radius", "far", "sense_radius"),
        ("obs_noise", -0.1, "obs_noise"),
        ("obs_noise", NAN, "obs_noise"),
        ("obs_noise", "0", "obs_noise"),
        ("gap_width", (-1.0, -0.5), "gap_width"),
        ("gap_width", (2.0, 1.0), "gap_width"),
        ("gap_width", NAN, "gap_width"),
        ("gap_width", (1.0, NAN), "gap_width"),
        ("gap_width", "wide", "gap_width"),
        ("gap_width", (0.0, 1.0), "gap_width"),
        ("gap_width", (1.0, 2.0, 3.0), "gap_width"),
        ("wall_x", (INF, 1.0), "wall_x"),
        ("follower_noise", -1.0, "follower_noise"),
        ("follower_noise", NAN, "follower_noise"),
        ("follower_noise", "x", "follower_noise"),
        ("follower_noise", None, "follower_noise"),
        ("goal_tol", 0.0, "goal_tol"),
        ("goal_tol", NAN, "goal_tol"),
        ("formation_tol", -1.0, "formation_tol"),
        ("hold_steps", 0, "hold_steps"),
        ("hold_steps", 1.5, "hold_steps"),
        ("follower_law", np.zeros(3), "follower_law"),
        ("dynamics", np.eye(2), "dynamics"),
        ("observation", [["position"]], "observation"),
        ("omega", np.full((5, 5), NAN), "omega"),
        ("foo", 1, "foo"),
    ]
    for key, val, arg in bad_args:
        yield C(f"Engine({key}={val!r})", lambda key=key, val=val: Engine(**{key: val}), arg)
    scen_args: list[tuple[str, str, Any, str]] = [
        ("obstacle_field", "n_obstacles", -1, "n_obstacles"),
        ("obstacle_field", "n_obstacles", 1.5, "n_obstacles"),
        ("obstacle_field", "n_obstacles", None, "n_obstacles"),
        ("obstacle_field", "obstacle_radius", (-0.5, 0.2), "obstacle_radius"),
        ("moving_obstacles", "n_moving", 0, "n_moving"),
        ("moving_obstacles", "moving_speed", (0.5, 99.0), "moving_speed"),
        ("hold", "start", "nowhere", "start"),
        ("hold", "start", 5, "start"),
        ("hold", "goal_scale", (-1.0, 0.5), "goal_scale"),
        ("hold", "goal_scale", (0.0, 1.0), "goal_scale"),
        ("maneuver", "scale", (-1.0, 0.5), "scale"),
        ("maneuver_3d", "follower_noise", -0.5, "follower_noise"),
    ]
    for scen, key, val, arg in scen_args:
        yield C(f"Engine({scen!r}, {key}={val!r})", lambda s=scen, k=key, v=val: Engine(s, **{k: v}), arg)
    fw3 = octahedron()
    yield C("Engine(narrow_passage, 3D framework)", lambda: Engine("narrow_passage", framework=fw3), ("framework", "d"))
    asym = paper_omega().copy()
    asym[3, 4] += 3
    yield C("Engine(omega asymmetric)", lambda: Engine("hold", framework="paper", omega=asym), "omega")
    yield C(
        "Engine(framework=Framework, omega=None): designed",
        lambda: Engine("hold", framework=Framework(paper_example_positions(), paper_edges(), [0, 1, 2])),
        (),
        valid=True,
    )
    yield C("Engine(agent_radius=0)", lambda: Engine("hold", agent_radius=0.0), (), valid=True)
    yield C("Engine(n_rays=0)", lambda: Engine("hold", n_rays=0), "n_rays")
    yield C("Engine(max_cycles=np.int64(5))", lambda: Engine("hold", max_cycles=np.int64(5)), (), valid=True)
    yield C("Engine(dt=np.float32(0.1))", lambda: Engine("hold", dt=np.float32(0.1)), (), valid=True)
    yield C("Engine(gap_width=(1.2, 1.2))", lambda: Engine(gap_width=(1.2, 1.2)), (), valid=True)
    yield C(
        "Engine(dt=3.0, stationary): unstable",
        lambda: Engine("hold", "single_integrator", "stationary", 3.0, law_params={"gain": 1.0}),
        ("dt", "stable"),
        warns=Warning,
    )
    eng = Engine("hold")
    st = eng.reset(np.random.default_rng(0), 2)
    yield C("Engine.reset(B=0)", lambda: eng.reset(np.random.default_rng(0), 0), "B")
    yield C("Engine.reset(B=1.5)", lambda: eng.reset(np.random.default_rng(0), 1.5), "B")
    yield C("Engine.reset(rng=0)", lambda: eng.reset(0, 1), "rng")
    yield C("Engine.reset(rng=None)", lambda: eng.reset(None, 1), "rng")
    yield C("Engine.step(actions (1, 3, 2) for B=2)", lambda: eng.step(st, np.zeros((1, 3, 2))), "actions")
    yield C("Engine.step(actions NaN)", lambda: eng.step(st, np.full((2, 3, 2), NAN)), ("action", "actions"))
    yield C("Engine.step(actions 'x')", lambda: eng.step(st, "x"), "actions")
    yield C("Engine.step(state=None)", lambda: eng.step(None, np.zeros((2, 3, 2))), "state")
    yield C(
        "Engine.step(actions beyond [-1, 1]) clipped", lambda: eng.step(st, np.full((2, 3, 2), 5.0)), (), valid=True
    )

    # --- parallel env: construction, reset, step
    yield C("parallel_env(render_mode='bogus')", lambda: formation_v0.parallel_env(render_mode="bogus"), "render_mode")
    yield C("parallel_env(max_cycles=None)", lambda: formation_v0.parallel_env(max_cycles=None), "max_cycles")
    yield C("formation_v1.parallel_env(dt='x')", lambda: formation_v1.parallel_env(dt="x"), "dt")
    yield C(
        "formation_v1.parallel_env(reward_weights=5)",
        lambda: formation_v1.parallel_env(reward_weights=5),
        "reward_weights",
    )

    def pz(**kw: Any) -> Any:
        env = formation_v0.parallel_env(scenario="hold", **kw)
        env.reset(seed=0)
        return env

    def zeros(env: Any) -> dict[str, Any]:
        return {a: np.zeros(2, np.float32) for a in env.agents}

    for label, seed in (("-1", -1), ("1.5", 1.5), ("'x'", "x"), ("True", True), ("nan", NAN), ("[1, 2]", [1, 2])):
        yield C(f"parallel_env.reset(seed={label})", lambda seed=seed: pz().reset(seed=seed), "seed")
    for label, opt in (("'x'", "x"), ("5", 5), ("[1]", [1])):
        yield C(f"parallel_env.reset(options={label})", lambda opt=opt: pz().reset(seed=0, options=opt), "options")
    yield C("parallel_env.reset(seed=np.int64(3))", lambda: pz().reset(seed=np.int64(3)), (), valid=True)
    yield C("parallel_env.reset(seed=2**70)", lambda: pz().reset(seed=2**70), (), valid=True)
    yield C("parallel_env.reset(options={})", lambda: pz().reset(options={}), (), valid=True)
    yield C(
        "parallel_env.reset(options={'options': 1}) (PettingZoo's checker)",
        lambda: pz().reset(options={"options": 1}),
        (),
        valid=True,
    )
    fresh = lambda: formation_v0.parallel_env(scenario="hold")  # noqa: E731
    yield C("parallel_env.step({}) before reset", lambda: fresh().step({}), ("reset", "step"))
    yield C(
        "parallel_env.step(actions) before reset", lambda: fresh().step({"leader_0": np.zeros(2)}), ("reset", "step")
    )
    yield C("parallel_env.state() before reset", lambda: fresh().state(), ("reset", "state"))
    yield C(
        "parallel_env.step(extra agent)",
        lambda: (lambda e: e.step({**zeros(e), "leader_9": np.zeros(2)}))(pz()),
        ("agents", "leader_9"),
    )
    yield C("parallel_env.step(missing agent)", lambda: (lambda e: e.step({"leader_0": np.zeros(2)}))(pz()), "agents")
    yield C("parallel_env.step({}) mid-episode", lambda: pz().step({}), "agents")
    yield C("parallel_env.step(list of actions)", lambda: pz().step([np.zeros(2)] * 3), "actions")
    yield C("parallel_env.step(None)", lambda: pz().step(None), "actions")
    yield C(
        "parallel_env.step(action shape (3,))",
        lambda: (lambda e: e.step({a: np.zeros(3) for a in e.agents}))(pz()),
        "action",
    )
    yield C(
        "parallel_env.step(action NaN)",
        lambda: (lambda e: e.step({a: np.full(2, NAN) for a in e.agents}))(pz()),
        ("action", "leader_0"),
    )
    yield C(
        "parallel_env.step(action 'x')",
        lambda: (lambda e: e.step({a: "x" for a in e.agents}))(pz()),
        ("action", "actions"),
    )
    yield C(
        "parallel_env.step(action complex)",
        lambda: (lambda e: e.step({a: np.ones(2) * 1j for a in e.agents}))(pz()),
        ("action", "actions"),
    )
    yield C(
        "parallel_env.step(action as list)",
        lambda: (lambda e: e.step({a: [0.0, 0.0] for a in e.agents}))(pz()),
        (),
        valid=True,
    )

    def after_end(empty: bool) -> Any:
        env = pz(max_cycles=1)
        env.step(zeros(env))
        return env.step({} if empty else {"leader_0": np.zeros(2)})

    yield C("parallel_env.step(actions) after the end", lambda: after_end(False), ("reset", "over"))
    yield C("parallel_env.step({}) after the end (PettingZoo loop)", lambda: after_end(True), (), valid=True)
    yield C("parallel_env.observation_space('leader_9')", lambda: pz().observation_space("leader_9"), "agent")
    yield C("parallel_env.action_space(None)", lambda: pz().action_space(None), "agent")

    # --- AEC
    def aec() -> Any:
        e = formation_v0.env(scenario="hold")
        e.reset(seed=0)
        return e

    yield C("env().step(NaN action)", lambda: aec().step(np.full(2, NAN)), ("action", "leader_0"))
    yield C("env().step(shape (5,))", lambda: aec().step(np.zeros(5)), "action")

    def aec_done_agent() -> Any:
        e = formation_v0.env(scenario="hold", max_cycles=1)
        e.reset(seed=0)
        for _ in range(3):
            e.step(np.zeros(2, np.float32))
        return e.step(np.zeros(2, np.float32))  # the episode is over: a done agent's action must be None

    yield C("env().step(action) for a done agent", aec_done_agent, ("action", "None"))
    yield C("env().reset(seed=-1)", lambda: aec().reset(seed=-1), "seed")

    # --- commander env
    def cmd(**kw: Any) -> Any:
        e = FormationCommanderEnv("hold", **kw)
        e.reset(seed=0)
        return e

    yield C("commander(action_mode='bogus')", lambda: FormationCommanderEnv(action_mode="bogus"), "action_mode")
    yield C("commander(render_mode='bogus')", lambda: FormationCommanderEnv(render_mode="bogus"), "render_mode")
    yield C(
        "commander(pose_speed=0)", lambda: FormationCommanderEnv(action_mode="maneuver", pose_speed=0.0), "pose_speed"
    )
    yield C(
        "commander(scale_rate=nan)", lambda: FormationCommanderEnv(action_mode="maneuver", scale_rate=NAN), "scale_rate"
    )
    yield C(
        "commander(scale_range=(2, 0.5))",
        lambda: FormationCommanderEnv(action_mode="maneuver", scale_range=(2.0, 0.5)),
        "scale_range",
    )
    yield C(
        "commander(scale_range=5)", lambda: FormationCommanderEnv(action_mode="maneuver", scale_range=5), "scale_range"
    )
    yield C("commander(leaders mode, pose_speed=2)", lambda: FormationCommanderEnv(pose_speed=2.0), "pose_speed")
    yield C("commander.step before reset", lambda: FormationCommanderEnv("hold").step(np.zeros(6)), ("reset", "step"))
    yield C("commander.step((2, 3))", lambda: cmd().step(np.zeros((2, 3))), "action")
    yield C("commander.step((5,))", lambda: cmd().step(np.zeros(5)), "action")
    yield C("commander.step(NaN)", lambda: cmd().step(np.full(6, NAN)), ("action", "leader_0"))
    yield C("commander.step('x')", lambda: cmd().step("x"), "action")
    yield C("commander.step(None)", lambda: cmd().step(None), "action")
    yield C("commander.step(list of 6)", lambda: cmd().step([0.0] * 6), (), valid=True)
    yield C("commander(maneuver).step(NaN)", lambda: cmd(action_mode="maneuver").step(np.full(6, NAN)), "action")

    def past_truncation() -> Any:
        e = cmd(max_cycles=1)
        e.step(np.zeros(6))
        return e.step(np.zeros(6))

    yield C("commander.step after truncation", lambda: past_truncation(), ("reset", "over"))
    for label, seed in (("-1", -1), ("1.5", 1.5), ("'x'", "x")):
        yield C(f"commander.reset(seed={label})", lambda seed=seed: cmd().reset(seed=seed), "seed")
    yield C("commander.reset(options='x')", lambda: cmd().reset(options="x"), "options")

    # --- gym.make ids
    ids = formation_env.SCENARIO_IDS
    yield C("gym.make('formation_env/Nope-v0')", lambda: gym.make("formation_env/Nope-v0"), ("Nope", "env"))
    yield C(
        "gym.make(COMMANDER_ID, scenario='maze')",
        lambda: gym.make(formation_env.COMMANDER_ID, scenario="maze"),
        "scenario",
    )
    yield C("gym.make(Hold-v0, dt=-1)", lambda: gym.make(ids["hold"], dt=-1.0), "dt")
    yield C("gym.make(Hold-v0, num_envs='x')", lambda: gym.make(ids["hold"], num_envs="x"), "num_envs")
    yield C(
        "gym.make(Hold-v1).reset(seed=-1)",
        lambda: gym.make(formation_env.SCENARIO_IDS_V1["hold"]).reset(seed=-1),
        "seed",
    )
    yield C(
        "gym.make(Hold-v0).step(NaN)",
        lambda: (lambda e: (e.reset(seed=0), e.step(np.full(6, NAN))))(gym.make(ids["hold"])),
        ("action", "leader_0"),
    )
    yield C("gym.make(Hold-v0)", lambda: gym.make(ids["hold"]), (), valid=True)

    # --- vectorised env
    V = FormationVecEnv
    for label, kw, arg in (
        ("num_envs=None", {"num_envs": None}, "num_envs"),
        ("num_envs=0", {"num_envs": 0}, "num_envs"),
        ("num_envs=1.5", {"num_envs": 1.5}, "num_envs"),
        ("num_envs='8'", {"num_envs": "8"}, "num_envs"),
        ("num_envs=-2", {"num_envs": -2}, "num_envs"),
        ("mode='bogus'", {"mode": "bogus"}, "mode"),
        ("seed=-1", {"seed": -1}, "seed"),
        ("seed=1.5", {"seed": 1.5}, "seed"),
        ("seed='x'", {"seed": "x"}, "seed"),
        ("engine=5", {"engine": 5}, "engine"),
        ("render_mode='human'", {"render_mode": "human"}, "render_mode"),
        ("action_mode='maneuver' shared", {"action_mode": "maneuver"}, "action_mode"),
        ("maneuver_kwargs, leaders", {"maneuver_kwargs": {"pose_speed": 2.0}}, "maneuver_kwargs"),
        (
            "maneuver_kwargs={'nope': 1}",
            {"mode": "commander", "action_mode": "maneuver", "maneuver_kwargs": {"nope": 1}},
            "nope",
        ),
        ("dt=-1", {"dt": -1.0}, "dt"),
        ("max_cycles=None", {"max_cycles": None}, "max_cycles"),
        ("scenario=None", {"scenario": None}, "scenario"),
    ):
        yield C(f"FormationVecEnv({label})", lambda kw=kw: V(**{"scenario": "hold", "num_envs": 2, **kw}), arg)
    yield C("FormationVecEnv(engine=..., dt=0.1)", lambda: V(engine=Engine("hold"), dt=0.1), ("engine", "dt"))

    def venv(**kw: Any) -> Any:
        v = V("hold", num_envs=2, seed=0, **kw)
        v.reset()
        return v

    yield C("FormationVecEnv.step before reset", lambda: V("hold", num_envs=2).step(np.zeros((6, 2))), "reset")
    for label, a in (
        ("(6, 3)", np.zeros((6, 3))),
        ("(2, 3, 2)", np.zeros((2, 3, 2))),
        ("NaN", np.full((6, 2), NAN)),
        ("'x'", "x"),
        ("None", None),
        ("ragged list", [[0.0, 0.0], [0.0]]),
        ("complex", np.ones((6, 2)) * 1j),
    ):
        yield C(f"FormationVecEnv.step(actions={label})", lambda a=a: venv().step(a), ("actions", "action"))
    yield C("FormationVecEnv.step(list of lists)", lambda: venv().step([[0.0, 0.0]] * 6), (), valid=True)

    def failed_then_wait() -> Any:
        v = V("hold", num_envs=2, seed=0)
        with contextlib.suppress(Exception):
            v.step_async(np.zeros((6, 2)))  # before reset: refused
        v.reset()
        return v.step_wait()

    yield C("FormationVecEnv: failed step_async, then step_wait", failed_then_wait, ("step_async", "step_wait"))
    for label, s in (("-1", -1), ("1.5", 1.5), ("'x'", "x")):
        yield C(f"FormationVecEnv.seed({label})", lambda s=s: V("hold", num_envs=2).seed(s), "seed")
    yield C("FormationVecEnv.get_attr('nope')", lambda: venv().get_attr("nope"), "nope", errors=(AttributeError,))
    yield C("FormationVecEnv.env_method('nope')", lambda: venv().env_method("nope"), "nope", errors=(AttributeError,))
    G = lambda: GymnasiumFormationVecEnv(V("hold", num_envs=2, seed=0))  # noqa: E731
    for label, s in (("-1", -1), ("1.5", 1.5), ("'x'", "x")):
        yield C(f"GymnasiumFormationVecEnv.reset(seed={label})", lambda s=s: G().reset(seed=s), "seed")
    yield C("GymnasiumFormationVecEnv.reset(options=5)", lambda: G().reset(options=5), "options")
    yield C("GymnasiumFormationVecEnv(venv=None)", lambda: GymnasiumFormationVecEnv(None), "venv")

    def gstep(a: Any) -> Any:
        e = G()
        e.reset(seed=0)
        return e.step(a)

    yield C("GymnasiumFormationVecEnv.step((6, 3))", lambda: gstep(np.zeros((6, 3))), "actions")
    yield C("GymnasiumFormationVecEnv.step(NaN)", lambda: gstep(np.full((6, 2), NAN)), ("action", "actions"))
    yield C("GymnasiumFormationVecEnv.step before reset", lambda: G().step(np.zeros((6, 2))), "reset")

    # --- copies mid-episode continue bit-identically (valid inputs with a check)
    pick = lambda e: pickle.loads(pickle.dumps(e))  # noqa: E731
    for how, clone in (("pickle", pick), ("deepcopy", copy.deepcopy)):
        yield C(
            f"parallel_env {how} mid-episode continues",
            lambda clone=clone: same_pz(clone),
            (),
            valid=True,
            check=lambda r: expect(r, "the copy diverged"),
        )
        yield C(
            f"AEC env {how} mid-episode continues",
            lambda clone=clone: same_aec(clone),
            (),
            valid=True,
            check=lambda r: expect(r, "the copy diverged"),
        )
        yield C(
            f"commander {how} mid-episode continues",
            lambda clone=clone: same_cmd(clone),
            (),
            valid=True,
            check=lambda r: expect(r, "the copy diverged"),
        )
        yield C(
            f"FormationVecEnv {how} continues across auto-resets",
            lambda clone=clone: same_vec(clone, False),
            (),
            valid=True,
            check=lambda r: expect(r, "the copy diverged"),
        )
        yield C(
            f"Gymnasium vec view {how} continues across auto-resets",
            lambda clone=clone: same_vec(clone, True),
            (),
            valid=True,
            check=lambda r: expect(r, "the copy diverged"),
        )


def paper_example_positions() -> Any:
    from formation_env.core import paper_example

    return paper_example().positions


def paper_edges() -> Any:
    from formation_env.core import paper_example

    return paper_example().edges


def same_pz(clone: Callable[[Any], Any]) -> bool:
    from formation_env import formation_v0

    env = formation_v0.parallel_env(scenario="moving_obstacles", obs_noise=0.01, max_cycles=12)
    env.reset(seed=3)
    acts = {a: np.full(2, 0.3, np.float32) for a in env.agents}
    for _ in range(4):
        env.step(acts)
    twin = clone(env)
    for _ in range(10):
        if not env.agents:
            return not twin.agents
        o1, r1, *_ = env.step(acts)
        o2, r2, *_ = twin.step(acts)
        if r1 != r2 or not all(np.array_equal(o1[a], o2[a]) for a in o1):
            return False
    return True


def same_aec(clone: Callable[[Any], Any]) -> bool:
    from formation_env import formation_v0

    env = formation_v0.env(scenario="hold", obs_noise=0.01)
    env.reset(seed=1)
    for _ in range(5):
        env.step(np.full(2, 0.2, np.float32))
    twin = clone(env)
    for _ in range(6):
        env.step(np.full(2, 0.2, np.float32))
        twin.step(np.full(2, 0.2, np.float32))
        if env.agent_selection != twin.agent_selection:
            return False
        if not np.array_equal(env.observe(env.agent_selection), twin.observe(twin.agent_selection)):
            return False
    return True


def same_cmd(clone: Callable[[Any], Any]) -> bool:
    from formation_env.env.commander import FormationCommanderEnv

    cmd = FormationCommanderEnv("narrow_passage", action_mode="maneuver", obs_noise=0.01)
    cmd.reset(seed=1)
    cmd.step(np.full(6, 0.1))
    twin = clone(cmd)
    return all(np.array_equal(cmd.step(np.full(6, 0.2))[0], twin.step(np.full(6, 0.2))[0]) for _ in range(4))


def same_vec(clone: Callable[[Any], Any], gymnasium_view: bool) -> bool:
    from formation_env.env.vector import FormationVecEnv

    venv = FormationVecEnv("narrow_passage", num_envs=3, seed=0, max_cycles=4)
    env: Any = venv.to_gymnasium() if gymnasium_view else venv
    if gymnasium_view:
        env.reset(seed=0)
    else:
        env.reset()
    zero = np.zeros((venv.num_envs, venv.p))
    env.step(zero)
    twin = clone(env)
    for _ in range(7):  # across auto-resets (every env ends at step 4)
        a, b = env.step(zero), twin.step(zero)
        if not (np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])):
            return False
    inner = twin.venv if gymnasium_view else twin
    return bool(np.array_equal(inner.state.params["_pvec"], venv.state.params["_pvec"]))


# ---------------------------------------------------------------------------- CLI cases
def cli_cases(tmp: Path) -> Iterator[Case]:
    g = "cli"
    corrupt = tmp / "corrupt.zip"
    corrupt.write_bytes(b"not a zip file")
    a_file = tmp / "a_file"
    a_file.write_text("x")
    unwritable = str(a_file / "sub" / "out.gif")  # a path under a file: cannot be created
    gif = str(tmp / "r.gif")

    def C(name: str, argv: list[str], arg: str | tuple[str, ...], valid: bool = False) -> Case:
        return Case(g, name, lambda: cli(*argv), arg, valid=valid)

    rollout = ["rollout", "--scenario", "hold", "--out", gif]
    for flag, val in (
        ("--steps", "-1"),
        ("--steps", "0"),
        ("--steps", "abc"),
        ("--steps", "1.5"),
        ("--fps", "0"),
        ("--fps", "-5"),
        ("--seed", "-1"),
        ("--seed", "x"),
    ):
        yield C(f"rollout {flag} {val}", [*rollout, flag, val], flag)
    yield C("rollout --scenario maze", ["rollout", "--scenario", "maze", "--out", gif], "--scenario")
    for label, kw in (
        ("'{bad'", "{bad"),
        ("'[1, 2]'", "[1, 2]"),
        ("'{\"dt\": -1}'", '{"dt": -1}'),
        ("'{\"nope\": 1}'", '{"nope": 1}'),
        ("'null'", "null"),
        ("'5'", "5"),
        ("'{\"gap_width\": [2, 1]}'", '{"gap_width": [2, 1]}'),
    ):
        arg = ("--env-kwargs", "dt", "nope", "gap_width")
        yield C(f"rollout --env-kwargs {label}", [*rollout, "--env-kwargs", kw], arg)
    yield C("rollout --policy nope.zip", [*rollout, "--policy", str(tmp / "nope.zip")], ("--policy", "nope.zip"))
    yield C("rollout --policy corrupt.zip", [*rollout, "--policy", str(corrupt)], ("--policy", "corrupt.zip"))
    yield C(
        "rollout --out under a file",
        ["rollout", "--scenario", "hold", "--steps", "2", "--out", unwritable],
        ("--out", "out.gif", "a_file"),
    )
    yield C(
        "rollout --out x.txt",
        ["rollout", "--scenario", "hold", "--steps", "2", "--out", str(tmp / "x.txt")],
        ("--out", "x.txt", ".txt"),
    )
    yield C("rollout --steps 2 (valid)", [*rollout, "--steps", "2"], (), valid=True)

    ev = ["evaluate", "--scenario", "hold"]
    for flag, val in (
        ("--episodes", "0"),
        ("--episodes", "-3"),
        ("--episodes", "x"),
        ("--seed", "-1"),
        ("--seed", "1.5"),
    ):
        yield C(f"evaluate {flag} {val}", [*ev, flag, val], flag)
    for label, kw in (
        ("'{bad'", "{bad"),
        ("'[]'", "[]"),
        ("'{\"gap_width\": [2, 1]}'", '{"gap_width": [2, 1]}'),
        ("'{\"max_cycles\": null}'", '{"max_cycles": null}'),
        ("'\"x\"'", '"x"'),
    ):
        yield C(
            f"evaluate --env-kwargs {label}",
            [*ev, "--episodes", "2", "--env-kwargs", kw],
            ("--env-kwargs", "gap_width", "max_cycles"),
        )
    yield C(
        "evaluate --policy nope.zip",
        [*ev, "--episodes", "2", "--policy", str(tmp / "nope.zip")],
        ("--policy", "nope.zip"),
    )
    yield C(
        "evaluate --policy corrupt.zip", [*ev, "--episodes", "2", "--policy", str(corrupt)], ("--policy", "corrupt.zip")
    )
    yield C("evaluate --scenario maze", ["evaluate", "--scenario", "maze"], "--scenario")
    yield C(
        "evaluate --out under a file",
        [*ev, "--episodes", "1", "--out", str(a_file / "sub")],
        ("--out", "a_file", "sub"),
    )
    yield C(
        "evaluate --episodes 1 --policy random (valid)", [*ev, "--episodes", "1", "--policy", "random"], (), valid=True
    )

    for flag, val in (("--episodes", "0"), ("--episodes", "-1"), ("--seed", "-2"), ("--scenarios", "maze")):
        yield C(f"leaderboard {flag} {val}", ["leaderboard", flag, val], flag)
    yield C(
        "leaderboard --policies /nonexistent",
        [
            "leaderboard",
            "--episodes",
            "1",
            "--scenarios",
            "hold",
            "--policies",
            str(tmp / "nonexistent"),
            "--out",
            str(tmp / "lb.md"),
        ],
        ("--policies", "nonexistent"),
    )
    yield C("reproduce --out under a file", ["reproduce", "--out", str(a_file / "sub")], ("--out", "a_file", "sub"))
    yield C("bench --only nope", ["bench", "--only", "nope"], "--only")
    yield C("no subcommand", [], "command")
    yield C("unknown subcommand", ["fly"], ("command", "fly"))
    yield C("unknown flag", ["rollout", "--speed", "3"], "--speed")


# ---------------------------------------------------------------------------- running
def run(groups: tuple[str, ...], verbose: bool) -> list[Outcome]:
    outcomes: list[Outcome] = []
    with tempfile.TemporaryDirectory() as tmp:
        makers = {"core": core_cases, "env": env_cases, "cli": lambda: cli_cases(Path(tmp))}
        for grp in groups:
            t0 = time.perf_counter()
            for case in makers[grp]():
                o = classify(case)
                outcomes.append(o)
                if verbose and o.cls not in (CLEAR, FINE):
                    print(f"  [{o.cls}] {o.group}: {o.name}: {o.detail}", flush=True)
            print(
                f"[{grp}] {sum(o.group == grp for o in outcomes)} cases in {time.perf_counter() - t0:.0f} s",
                file=sys.stderr,
                flush=True,
            )
    return outcomes


def table(outcomes: list[Outcome]) -> str:
    """Markdown table: cases per group and class, with a total row."""
    groups = list(dict.fromkeys(o.group for o in outcomes))
    head = "| group | cases | " + " | ".join(CLASSES) + " |"
    rows = [head, "|---|---:|" + "---:|" * len(CLASSES)]
    for grp in [*groups, "total"]:
        sel = [o for o in outcomes if grp in ("total", o.group)]
        cells = [str(sum(1 for o in sel if o.cls == c)) for c in CLASSES]
        rows.append(f"| {grp} | {len(sel)} | " + " | ".join(cells) + " |")
    return "\n".join(rows)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.bad_inputs_probe", description=__doc__.splitlines()[0])
    p.add_argument("--only", nargs="*", choices=["core", "env", "cli"], help="groups to run (default: all)")
    p.add_argument("--json", default=None, help="write every outcome to this JSON file")
    p.add_argument("-v", "--verbose", action="store_true", help="print every case that is not clear or fine")
    args = p.parse_args(argv)
    groups = tuple(args.only or ("core", "env", "cli"))
    warnings.simplefilter("ignore")
    outcomes = run(groups, args.verbose)
    print(table(outcomes))
    bad = [o for o in outcomes if o.cls in (OBSCURE, SILENT, REFUSED)]
    if bad:
        print("\nNot clear or fine:")
        for o in bad:
            print(f"- [{o.cls}] {o.group}: {o.name}: {o.detail}")
    if args.json:
        Path(args.json).write_text(json.dumps([asdict(o) for o in outcomes], indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
