"""The sparse step of large swarms: frameworks of more than ``engine.MAX_AGENTS`` agents.

The folded step of :mod:`formation_env.env.engine` multiplies by one (n q + ...) x (...) matrix,
which grows as n^2 (a dense n x n is 800 MB at n = 10,000). Here nothing grows faster than
n + edges:

* the stress stays a scipy.sparse CSR matrix; the followers run the core law directly
  (``FollowerLaw.step``: one sparse product, plus a sparse LU solve for ``dynamic``);
* agent-agent contacts along the graph's edges, walls and circles per agent, O(n (S + C));
* the affine fit through H^+ (d + 1, n), H = [r, 1]: (Theta, b) = H^+ p, residual p - H (H^+ p),
  formation error its RMS over agents (never the n x n projector);
* leader observations gathered directly (position, velocity, other leaders, goal delta, goal
  velocity, Theta of the fit, time);
* law defaults from the extreme eigenvalues of Omega_ff (Lanczos above ``EXACT_SPECTRUM_UP_TO``
  followers), and the spectral radius as the largest over the eigenvalue interval (an upper bound).

Observations, rewards, state and info are those of the folded step up to rounding (1e-12):
``tests/test_env_swarm.py`` runs both on one framework by lowering ``engine.MAX_AGENTS``.

World: ``hold`` and ``maneuver`` set poses of the formation itself, so their world box grows to
hold a framework too large for it (:func:`fit_world`); scenarios with fixed obstacles refuse one.
"""

from __future__ import annotations

import warnings
from typing import TYPE_CHECKING, Any

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import ArrayLike, NDArray

from formation_env.core.analysis import extreme_eigenvalues
from formation_env.core.dynamics import LinearDynamics, riccati_gain
from formation_env.core.errors import FormationError
from formation_env.core.laws import (
    DynamicLeaderLaw,
    FollowerLaw,
    gamma_interval,
    jacobi_modes,
    make_law,
    spectral_radius,
    stress_modes,
)
from formation_env.core.stress import Partition

from . import geometry
from .scenarios._base import Scenario

if TYPE_CHECKING:
    from .engine import Engine, EngineState

__all__ = ["EXACT_SPECTRUM_UP_TO", "GROWING_WORLDS", "SwarmStep", "fit_world", "make_swarm_law"]

Array = NDArray[np.float64]

#: Up to this many followers the spectra of Omega_ff and of the Jacobi matrix are computed exactly
#: (dense), as the folded path does; above, their extreme eigenvalues bound an interval.
EXACT_SPECTRUM_UP_TO = 2000
#: Points of the eigenvalue interval at which the modes are evaluated above ``EXACT_SPECTRUM_UP_TO``.
INTERVAL_POINTS = 513
#: Scenarios whose task is a pose of the formation itself: their world box grows with the framework.
GROWING_WORLDS: tuple[str, ...] = ("hold", "maneuver", "maneuver_3d")
#: Reach of a pose beyond the nominal framework: |Theta| <= 1.4 (scale) x 1.5 (shear) over those scenarios.
REACH = 2.2


# ---------------------------------------------------------------------------- world
def fit_world(scenario: Scenario) -> None:
    """Fit the scenario's world box to a large framework, or refuse the framework (FormationError).

    With R = max_i |r_i| (m): ``GROWING_WORLDS`` scenarios whose box half-width h is below REACH R
    get h' = REACH R + h per axis (so every pose they draw stays inside); the others have fixed
    obstacles sized for formations of a few metres and refuse a framework wider than half their box.
    """
    r = scenario.r
    reach = float(np.max(np.linalg.norm(r, axis=1)))
    half = scenario.bounds[1]
    if scenario.name in GROWING_WORLDS:
        if REACH * reach > float(np.min(half)):
            grown = REACH * reach + half
            scenario.bounds = np.stack([-grown, grown]).astype(np.float64)
        return
    span = np.ptp(r, axis=0)
    if np.any(span > half):
        raise FormationError(
            f"scenario {scenario.name!r} has fixed obstacles in a world of "
            f"{' x '.join(f'{2 * h:g}' for h in half)} m, sized for formations of a few metres; the framework "
            f"{scenario.fw.name or '(custom)'} spans {' x '.join(f'{s:.3g}' for s in span)} m: scale its positions "
            f"(Framework(fw.positions * s, fw.edges, fw.leaders): the stress stays valid), or use one of "
            f"{list(GROWING_WORLDS)}, whose world grows with the framework"
        )


# ---------------------------------------------------------------------------- law
def _ff_spectrum(part: Partition) -> Array:
    """Eigenvalues of Omega_ff (n_f <= ``EXACT_SPECTRUM_UP_TO``), else a grid over [lambda_min, lambda_max]."""
    if part.n_f <= EXACT_SPECTRUM_UP_TO:
        return np.asarray(np.linalg.eigvalsh(part.omega_ff_dense), dtype=np.float64)
    lo, hi = extreme_eigenvalues(part)
    return np.linspace(lo, hi, INTERVAL_POINTS)


def _jacobi_spectrum(law: DynamicLeaderLaw) -> Array:
    """Eigenvalues nu of J = I - D^-1/2 Omega_ff D^-1/2 (exact up to ``EXACT_SPECTRUM_UP_TO`` followers),
    else a grid over [nu_min, nu_max] from Lanczos on the scaled Omega_ff (shift-invert for its smallest)."""
    part = law.part
    if part.n_f <= EXACT_SPECTRUM_UP_TO:
        return law.jacobi_eigenvalues()
    s = sp.diags(1.0 / np.sqrt(np.asarray(part.omega_ff.diagonal())))
    a = sp.csc_matrix(s @ part.omega_ff @ s)
    hi = spla.eigsh(a, k=1, which="LA", return_eigenvectors=False, tol=1e-8)[0]
    lo = spla.eigsh(a, k=1, sigma=0.0, which="LM", return_eigenvectors=False, tol=1e-8)[0]
    return np.linspace(1.0 - hi, 1.0 - lo, INTERVAL_POINTS)


def make_swarm_law(
    omega: Any, leaders: tuple[int, ...], dyn: LinearDynamics, law_name: str, dt: float, params: dict[str, Any]
) -> tuple[FollowerLaw, float]:
    """The follower law on a sparse stress and the spectral radius of its error dynamics.

    Fills the engine's defaults into ``params`` without a dense n x n: ``stationary`` gain
    2 / (T (lambda_min + lambda_max)); ``linear`` eps minimising the worst mode over [lambda_min,
    lambda_max]; ``dynamic_distributed`` the fewest rounds (<= 30) with a stable closed loop.
    """
    part = Partition(omega, leaders)
    A_d, B_d = dyn.zoh(dt)
    if law_name == "stationary" and "gain" not in params:
        lo, hi = extreme_eigenvalues(part)
        params["gain"] = 2.0 / (dt * (lo + hi))
    lam = _ff_spectrum(part) if law_name in ("stationary", "linear") else np.zeros(0)
    if law_name == "linear" and "eps" not in params and part.n_f > EXACT_SPECTRUM_UP_TO:
        from scipy.optimize import minimize_scalar

        K = np.asarray(params["K"]) if "K" in params else riccati_gain(A_d, B_d, params.get("Q"))
        g_lo, g_hi = gamma_interval(A_d, B_d, K)
        lo_e, hi_e = g_lo / lam[0], g_hi / lam[-1]
        if not lo_e < hi_e:
            raise FormationError(f"no eps stabilises every mode: need eps in ({lo_e:.4g}, {hi_e:.4g}), which is empty")
        res = minimize_scalar(
            lambda e: spectral_radius(stress_modes(A_d, B_d, K, e, lam)), bounds=(lo_e, hi_e), method="bounded"
        )
        params["eps"] = float(res.x)
    if law_name == "dynamic_distributed":
        probe = make_law(law_name, part, dyn, dt, **{**params, "rounds": params.get("rounds", 1)})
        assert isinstance(probe, DynamicLeaderLaw)
        nu = _jacobi_spectrum(probe)
        if "rounds" not in params:
            rounds = next(
                (m for m in range(1, 31) if spectral_radius(jacobi_modes(A_d, B_d, probe.K, nu**m)) < 1.0),
                1,
            )
            params["rounds"] = rounds
        law = make_law(law_name, part, dyn, dt, **params)
        return law, spectral_radius(jacobi_modes(A_d, B_d, probe.K, nu ** int(params["rounds"])))
    law = make_law(law_name, part, dyn, dt, **params)
    if law_name in ("stationary", "linear"):
        return law, spectral_radius(stress_modes(law.A_d, law.B_d, law.K, law.eps, lam))  # type: ignore[attr-defined]
    return law, float(law.spectral_radius())


# ---------------------------------------------------------------------------- step
class SwarmStep:
    """The engine's ``reset``/``observe``/``step`` in O(n + edges) for one ``Engine`` (its constants).

    Shapes as in the engine: positions (B, n, d) m, observations (B, n_l, obs_dim) float32.
    """

    def __init__(self, engine: Engine) -> None:
        self.eng = eng = engine
        self.law = eng.law
        self._h = eng.affine._h  # (n, d + 1)
        self._pinv = eng.affine._pinv  # (d + 1, n)
        e = np.asarray(eng._pairs, dtype=np.int64).reshape(-1, 2)
        self._ei, self._ej = e[:, 0], e[:, 1]
        dyn = eng.dynamics
        self._Ct = np.ascontiguousarray(dyn.C.T)  # (q, d)
        self._CAt = np.ascontiguousarray((dyn.C @ dyn.A).T)
        self._vel_from_state = not dyn.discrete and not np.any(dyn.C @ dyn.B)
        nl = eng.n_l
        self._others = np.array([[b for b in range(nl) if b != a] for a in range(nl)], dtype=np.int64)
        self._falses: dict[int, NDArray[np.bool_]] = {}
        if e.shape[0]:
            r = eng.fw.positions
            shortest = float(np.min(np.linalg.norm(r[self._ei] - r[self._ej], axis=1)))
            if shortest < 2.0 * eng.agent_radius:
                warnings.warn(
                    f"agents touch in the nominal formation: its shortest edge is {shortest:.3g} m < 2 agent_radius "
                    f"= {2 * eng.agent_radius:g} m, so episodes start in contact; "
                    f"pass agent_radius < {shortest / 2:.3g}",
                    stacklevel=4,
                )

    # ------------------------------------------------------------------ measurements
    def measure(
        self, prev: Array | None, pos: Array, ref: Array, params: dict[str, Array]
    ) -> tuple[Array, NDArray[np.bool_], NDArray[np.bool_], Array, Array]:
        """Contact clearance (B,) m (swept when ``prev`` is given and an agent moved fast), out-of-box (B,),
        collision (B,), goal distances of every agent (B, n) m, formation error (B,) m."""
        eng = self.eng
        B, n, d = pos.shape
        rad = eng.agent_radius
        goal = ref[:, : n * d].reshape(B, n, d)
        dg = goal - pos
        gd = np.sqrt(np.einsum("bnd,bnd->bn", dg, dg))
        res = pos - np.matmul(self._h, np.matmul(self._pinv, pos))
        err = np.sqrt(np.einsum("bnd,bnd->b", res, res) / n)
        if self._ei.size:
            dp = pos[:, self._ei] - pos[:, self._ej]
            clear = np.sqrt(np.einsum("bmd,bmd->bm", dp, dp).min(axis=1)) - 2.0 * rad
        else:
            clear = np.full(B, np.inf)
        circ = params["circles"]
        if eng.n_circ:
            dc = pos[:, :, None, :] - circ[:, None, :, :d]
            cc = np.sqrt(np.einsum("bncd,bncd->bnc", dc, dc)) - circ[:, None, :, d] - rad
            np.minimum(clear, cc.min(axis=(1, 2)), out=clear)
        if eng.n_seg:
            sc = geometry.segment_clearance(pos, params["_a"], params["_e"], params["_einv2"]) - rad
            np.minimum(clear, sc.min(axis=(1, 2)), out=clear)
        collision = clear < 0.0
        lo, hi = eng.bounds
        oob = ((pos < lo) | (pos > hi)).any(axis=(1, 2))
        collision |= oob
        if prev is not None and (eng.n_seg or eng.n_circ) and np.abs(pos - prev).max() > eng._fast:
            if eng.n_seg:
                collision |= geometry.segment_crossings(prev, pos, params["_a"], params["_e"]).any(axis=1)
            if eng.n_circ:
                cc = geometry.circle_clearance(prev, pos, circ).min(axis=(1, 2)) - rad
                np.minimum(clear, cc, out=clear)
                collision |= cc < 0.0
        return clear, oob, collision, gd, err

    def _lin(self, pos: Array, vel: Array, ref: Array) -> Array:
        """The observation entries linear in the state (position .. time), shape (B, n_l L1)."""
        eng = self.eng
        B, n, d = pos.shape
        nl, lead, nd = eng.n_l, eng.leaders, n * d
        pl = pos[:, lead]
        goal = ref[:, :nd].reshape(B, n, d)[:, lead]
        gvel = ref[:, nd : 2 * nd].reshape(B, n, d)[:, lead]
        others = (pl[:, self._others] - pl[:, :, None]).reshape(B, nl, (nl - 1) * d)
        coef = np.matmul(self._pinv, pos)  # (B, d + 1, d): rows Theta^T, then b
        theta = np.swapaxes(coef[:, :d], 1, 2).reshape(B, 1, d * d)
        t = (ref[:, -1] * (1.0 / eng.max_cycles)).reshape(B, 1, 1)
        parts = [pl, vel[:, lead], others, goal - pl, gvel, np.broadcast_to(theta, (B, nl, d * d))]
        return np.concatenate(parts + [np.broadcast_to(t, (B, nl, 1))], axis=2).reshape(B, -1)

    def _sense(self, pos: Array, params: dict[str, Array]) -> Array:
        """Obstacle sensing of every leader (as ``Engine._sense``), shape (B, n_l, ks)."""
        eng = self.eng
        if eng._const_sense is not None:
            return eng._const_sense
        pl = pos[:, eng.leaders]
        B = pos.shape[0]
        if eng.d == 2:
            a = params["_a"] if eng.n_seg else np.zeros((B, 0, 2))
            e = params["_e"] if eng.n_seg else np.zeros((B, 0, 2))
            ranges = geometry.ray_ranges(pl, eng._dirs, a, e, params["circles"], eng.sensor_range)
            return np.minimum(ranges * (1.0 / eng.sensor_range), 1.0)
        vec = geometry.nearest_obstacle_vectors(pl, params["circles"], eng.n_nearest, eng.sensor_range)
        return vec.reshape(B, eng.n_l, -1)

    # ------------------------------------------------------------------ engine hooks
    def reset_from(self, params: dict[str, Array]) -> EngineState:
        """``Engine._reset_from``: the episode's state from the scenario's draws."""
        from .engine import EngineState

        eng = self.eng
        B = int(params["segments"].shape[0])
        start = np.array(params.pop("start"), dtype=np.float64)
        k = np.zeros(B, dtype=np.int64)
        ref = eng._ref(params, k)
        seg, circ = params["segments"], params["circles"]
        if seg.shape[1] != eng.n_seg or circ.shape[1] != eng.n_circ:
            raise FormationError(
                f"scenario {eng.scenario_name!r} must give {eng.n_seg} segments and {eng.n_circ} circles per episode, "
                f"got {seg.shape[1]} and {circ.shape[1]}"
            )
        if eng.n_seg:
            a = seg[:, :, 0]
            e = seg[:, :, 1] - a
            params["_a"], params["_e"] = a, e
            params["_einv2"] = 1.0 / np.maximum(np.einsum("bsd,bsd->bs", e, e), 1e-300)
        params["_pvec"] = np.asarray(eng.scenario.param_vector(params), dtype=np.float64)  # for global_state
        for arr in params.values():
            arr.setflags(write=False)
        _, _, _, gd, err = self.measure(None, start, ref, params)
        return EngineState(
            x=eng.dynamics.state_from_position(start),
            pos=start,
            vel=np.zeros_like(start),
            memory=self.law.initial_memory((B,)),
            k=k,
            ref=ref,
            goal_dist=gd[:, eng.leaders],
            err=err,
            streak=np.zeros(B, dtype=np.int64),
            params=params,
        )

    def observe(self, state: EngineState) -> NDArray[np.float32]:
        """``Engine.observe``: shape (B, n_l, obs_dim) float32."""
        lin = self._lin(state.pos, state.vel, state.ref)
        return self.eng._assemble(lin, state.err, self._sense(state.pos, state.params))

    def step(
        self, state: EngineState, actions: ArrayLike
    ) -> tuple[EngineState, NDArray[np.float32], Array, NDArray[np.bool_], NDArray[np.bool_], dict[str, Array]]:
        """``Engine.step`` (same returns), with the core law stepped on the sparse stress."""
        from .engine import EngineState

        eng = self.eng
        sc = eng.scenario
        B = state.x.shape[0]
        a = np.minimum(np.maximum(eng.check_actions(actions, B), -1.0), 1.0)
        x, memory = self.law.step(state.x, a * eng.u_max, state.memory)
        pos = x @ self._Ct
        vel = x @ self._CAt if self._vel_from_state else (pos - state.pos) * (1.0 / eng.dt)
        k = state.k + 1
        params = state.params
        if sc.moving_goal:
            ref = eng._ref(params, k)
        else:
            ref = state.ref.copy()
            ref[:, -1] += 1.0
        clear, oob, collision, gd, err = self.measure(state.pos, pos, ref, params)
        gd_l = gd[:, eng.leaders]
        goal_distance = gd.max(axis=1)
        ok = sc.is_success(goal_distance, err) > collision
        streak, success, terminated, truncated = eng._episode_end(state, ok, collision, k)
        af = a.reshape(B, -1)
        feats = np.concatenate((success[:, None], collision[:, None], err[:, None], af * af, state.goal_dist, gd_l), 1)
        re = feats @ eng._w_rew
        obs = eng._assemble(self._lin(pos, vel, ref), err, self._sense(pos, params))
        nl = eng.n_l
        new = EngineState(x, pos, vel, memory, k, ref, gd_l, err, streak, params)
        info = eng._info(success, collision, oob, err, clear, goal_distance, re[:, nl:], k)
        return new, obs, re[:, :nl], terminated, truncated, info
