"""Stability analysis of every law: closed loop, spectral radius, admissible T (or eps), decay rate."""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import NDArray

from .dynamics import LinearDynamics, check_dynamics
from .errors import FormationError, UnstableParameterError
from .laws import DynamicLeaderLaw, FollowerLaw, StressFeedbackLaw, make_law
from .network import Network, check_network, check_network_law
from .stress import DEFAULT_RTOL, Partition, check_partition
from .validation import check_bool, check_dt, check_rtol

__all__ = [
    "DT_SEARCH",
    "StabilityReport",
    "dt_interval",
    "extreme_eigenvalues",
    "network_dt_max",
    "stability_report",
    "stable_windows",
]

#: Default range of sampling periods T (s) scanned for stable windows by :func:`stability_report`.
DT_SEARCH: tuple[float, float] = (1e-3, 100.0)


@dataclass(frozen=True)
class StabilityReport:
    """What a law does on a stress matrix at sampling period ``dt``.

    Attributes:
        law: law name (see ``formation_env.core.laws.LAWS``).
        dt: sampling period T (s).
        mu_min, mu_max: smallest and largest eigenvalue of -Omega_ff (the paper's mu_i; all < 0).
        cond: condition number of Omega_ff, mu_min / mu_max.
        spectral_radius: of the closed-loop error dynamics; the error shrinks by this factor per step.
        stable: spectral_radius < 1.
        dt_range: open interval of T (s) around ``dt`` on which the law is stable, or None when
            the law adapts to T (``linear``); ``dt_max`` is its upper end.
        eps, eps_range: the stress gain and its admissible open interval (``linear`` laws).
        decay_rate: predicted exponential decay rate of the error, -ln(rho) / T (1/s).
        steps_to_1e6: predicted steps for the error to fall by 10^6 (inf if unstable).
        K: the feedback gain used, shape (p, q).
        notes: remarks on where the paper's statement differs from the computed answer.
        windows: every open interval of T (s) inside ``dt_search`` on which the law is stable,
            increasing (empty: never stable there; None: not computed, e.g. ``linear``, whose eps
            adapts to T).
        dt_opt: the fastest T (s): 2 / (g (lambda_min + lambda_max)) for ``stationary``, the
            numerical minimiser of rho over ``windows`` otherwise (None if there is none).
        rho_opt: the spectral radius at ``dt_opt``.
        dt_search: the range (s) scanned for ``windows``.
        jacobi_radius: ``dynamic_distributed`` only: spectral radius of J = -D^-1 N_ff.
        network: with ``network=``, the network's dict form (:meth:`Network.as_dict`); then
            ``spectral_radius`` is the per-sample decay factor of the loop over the network: rho of the
            augmented one-step matrix (delays), or sqrt(rho(E[A kron A])), the decay of the RMS error
            over the random losses and periods; ``dt_range``/``windows`` are the stable periods at
            that network.
        exact: whether ``stable`` comes from a necessary and sufficient test (None: perfect network,
            where every test above is exact).
        criterion: the test behind ``stable`` (network only).
        delay_max: the largest stable delay (samples) at ``dt``, the other settings kept (networks with a delay).
        loss_max: the largest loss probability that is mean-square stable at ``dt`` (networks with loss).
        steady_error: ``drop`` loss: the stationary RMS formation error sqrt(E ||x_f - x_f*||^2) the dropped
            terms leave (its mean is 0); needs ``x_leaders``.
        ultimate_bound: quantisation: a bound on limsup max_i |x_i - x_i*| (every component of every
            follower) (uniform: always; log: when the sector condition holds and ``x_leaders`` is given).
    """

    law: str
    dt: float
    mu_min: float
    mu_max: float
    cond: float
    spectral_radius: float
    stable: bool
    dt_range: tuple[float, float] | None
    eps: float | None
    eps_range: tuple[float, float] | None
    decay_rate: float
    steps_to_1e6: float
    K: NDArray[np.float64] | None = None
    rounds: int | None = None
    notes: tuple[str, ...] = field(default_factory=tuple)
    windows: list[tuple[float, float]] | None = None
    dt_opt: float | None = None
    rho_opt: float | None = None
    dt_search: tuple[float, float] | None = None
    jacobi_radius: float | None = None
    network: dict[str, Any] | None = None
    exact: bool | None = None
    criterion: str | None = None
    delay_max: int | None = None
    loss_max: float | None = None
    steady_error: float | None = None
    ultimate_bound: float | None = None

    @property
    def dt_max(self) -> float | None:
        """Largest stable sampling period (s), the upper end of ``dt_range``."""
        return None if self.dt_range is None else self.dt_range[1]

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready dict."""
        out: dict[str, Any] = {}
        for k, v in self.__dict__.items():
            if isinstance(v, np.ndarray):
                v = v.tolist()
            elif isinstance(v, tuple):
                v = list(v)
            elif isinstance(v, list):
                v = [list(w) for w in v]
            elif isinstance(v, dict):
                v = dict(v)
            elif isinstance(v, float) and not math.isfinite(v):
                v = str(v)
            out[k] = v
        out["dt_max"] = self.dt_max
        return out

    def __str__(self) -> str:
        lines = [
            f"law {self.law} at T = {self.dt:g} s" + (f", {self.rounds} round(s)" if self.rounds else ""),
            f"  mu_min = {self.mu_min:.4g}, mu_max = {self.mu_max:.4g}, cond(Omega_ff) = {self.cond:.4g}",
            f"  spectral radius {self.spectral_radius:.6g} -> {'stable' if self.stable else 'UNSTABLE'}",
        ]
        if self.dt_range is not None:
            lines.append(f"  stable for T in ({self.dt_range[0]:.6g}, {self.dt_range[1]:.6g}) s")
        if self.windows is not None and self.dt_search is not None:
            ws = ", ".join(f"({a:.6g}, {b:.6g})" for a, b in self.windows) or "none"
            lines.append(f"  stable windows of T in [{self.dt_search[0]:g}, {self.dt_search[1]:g}] s: {ws}")
        if self.dt_opt is not None:
            lines.append(f"  fastest T = {self.dt_opt:.6g} s (spectral radius {self.rho_opt:.6g})")
        if self.eps_range is not None:
            lines.append(
                f"  eps = {self.eps:.6g}, stable for eps in ({self.eps_range[0]:.6g}, {self.eps_range[1]:.6g})"
            )
        if self.stable:
            lines.append(f"  decay rate {self.decay_rate:.4g} 1/s, error / 1e6 in {self.steps_to_1e6:.1f} steps")
        if self.network is not None:
            lines.insert(1, f"  network {self.network}")
            lines.append(f"  test: {self.criterion} ({'exact' if self.exact else 'sufficient'})")
            for key in ("delay_max", "loss_max", "steady_error", "ultimate_bound"):
                val = getattr(self, key)
                if val is not None:
                    lines.append(f"  {key} = {val:.6g}" if isinstance(val, float) else f"  {key} = {val}")
        lines.extend(f"  note: {n}" for n in self.notes)
        return "\n".join(lines)


def extreme_eigenvalues(part: Partition) -> tuple[float, float]:
    """Smallest and largest eigenvalue of Omega_ff (sparse: Lanczos, shift-invert at 0 for the smallest)."""
    if not isinstance(part, Partition):
        raise TypeError(f"part must be a Partition, got {type(part).__name__}")
    if not part.sparse or part.n_f <= 2000:
        lam = np.linalg.eigvalsh(part.omega_ff_dense)
        return float(lam[0]), float(lam[-1])
    a = sp.csc_matrix(part.omega_ff)
    hi = spla.eigsh(a, k=1, which="LA", return_eigenvectors=False, tol=1e-8)[0]
    lo = spla.eigsh(a, k=1, sigma=0.0, which="LM", return_eigenvectors=False, tol=1e-8)[0]
    return float(lo), float(hi)


def dt_interval(law_at: Any, dt: float, dt_search_max: float = 100.0) -> tuple[float, float]:
    """Open interval of T around ``dt`` on which ``law_at(T).spectral_radius() < 1``.

    Scans T on a log grid from ``dt`` outwards in both directions and bisects the
    first change of stability to 1e-10 relative. If ``dt`` itself is unstable,
    returns the stable interval nearest below it (or (0, 0) if none).
    """

    def stable(t: float) -> bool:
        return bool(law_at(t).spectral_radius() < 1.0)

    def bisect(good: float, bad: float) -> float:
        for _ in range(60):
            mid = 0.5 * (good + bad)
            if stable(mid):
                good = mid
            else:
                bad = mid
        return 0.5 * (good + bad)

    if not stable(dt):
        below = np.geomspace(dt, dt * 1e-4, 200)[1:]
        hit = next((t for t in below if stable(t)), None)
        if hit is None:
            return 0.0, 0.0
        dt = float(hit)
    hi = math.inf
    for a, b in itertools.pairwise(np.geomspace(dt, dt_search_max, 300)):
        if not stable(b):
            hi = bisect(float(a), float(b))
            break
    lo = 0.0
    down = np.geomspace(dt, dt * 1e-6, 200)
    for a, b in itertools.pairwise(down):
        if not stable(b):
            lo = bisect(float(a), float(b))
            break
    return lo, hi


def stable_windows(
    rho: Any, t_lo: float, t_hi: float, points: int = 240, refine: int = 40
) -> tuple[list[tuple[float, float]], float | None, float | None]:
    """Every open interval of T in [t_lo, t_hi] on which ``rho(T) < 1``, and the minimiser of rho.

    Scans ``points`` log-spaced periods, bisects each change of stability (``refine``
    halvings), and minimises rho with a bounded scalar search around the best grid point.
    Windows narrower than the grid spacing can be missed; a window touching an end of the
    range is reported up to that end.

    Args:
        rho: T (s) -> spectral radius.
        t_lo, t_hi: the range scanned (s), 0 < t_lo < t_hi.
    Returns:
        (windows, T_opt, rho(T_opt)); T_opt None when there is no window.
    """
    from scipy.optimize import minimize_scalar

    grid = np.geomspace(t_lo, t_hi, points)
    vals = np.array([rho(float(t)) for t in grid])
    ok = vals < 1.0

    def edge(good: float, bad: float) -> float:
        for _ in range(refine):
            mid = math.sqrt(good * bad)
            if rho(mid) < 1.0:
                good = mid
            else:
                bad = mid
        return math.sqrt(good * bad)

    windows: list[tuple[float, float]] = []
    i = 0
    while i < points:
        if not ok[i]:
            i += 1
            continue
        j = i
        while j + 1 < points and ok[j + 1]:
            j += 1
        lo = float(grid[0]) if i == 0 else edge(float(grid[i]), float(grid[i - 1]))
        hi = float(grid[-1]) if j == points - 1 else edge(float(grid[j]), float(grid[j + 1]))
        windows.append((lo, hi))
        i = j + 1
    if not windows:
        return windows, None, None
    k = int(np.argmin(vals))
    a, b = float(grid[max(k - 1, 0)]), float(grid[min(k + 1, points - 1)])
    res = minimize_scalar(lambda lt: rho(math.exp(lt)), bounds=(math.log(a), math.log(b)), method="bounded")
    t_opt, r_opt = (math.exp(res.x), float(res.fun)) if res.fun <= vals[k] else (float(grid[k]), float(vals[k]))
    return windows, t_opt, r_opt


def stability_report(
    omega: Any,
    leaders: Sequence[int],
    dt: float = 1.0,
    law: str = "stationary",
    dynamics: LinearDynamics | None = None,
    *,
    check: bool = True,
    rtol: float = DEFAULT_RTOL,
    dt_search: tuple[float, float] | None = None,
    network: Network | dict[str, Any] | None = None,
    x_leaders: Any = None,
    **params: Any,
) -> StabilityReport:
    """Closed-loop stability of ``law`` on stress ``omega`` at sampling period ``dt`` (s).

    Args:
        omega: stress matrix, shape (n, n), dense or sparse.
        leaders: leader indices.
        dt: sampling period T (s).
        law: one of ``stationary``, ``linear``, ``linear_paper``, ``dynamic``, ``dynamic_distributed``.
        dynamics: agent dynamics; default single integrators in 2D (the spectrum does not depend on d).
        check: validate omega first (:func:`~formation_env.core.stress.check_partition`:
            symmetric, zero row sums, Omega_ff positive definite, at ``rtol``); ``check=False``
            skips it for speed (an asymmetric omega then gives a meaningless report).
        rtol: relative tolerance of that check (``1e-3`` accepts a rounded matrix such as the paper's printed
            one, ``paper_omega(exact=False)``).
        dt_search: range (s) of T scanned for every stable window (default :data:`DT_SEARCH`).
        network: a :class:`~formation_env.core.network.Network` (or its dict form): analyse the loop over
            it (laws ``stationary`` and ``linear``); see :func:`network_report` for what is computed.
        x_leaders: leader positions (n_l, d) (m), for the network quantities that depend on the formation
            (``drop`` steady error, ``log`` quantiser bound); ignored without a network.
        **params: law parameters (gain, eps, K, Q, rounds), see :func:`make_law`.

    Returns:
        A :class:`StabilityReport`. Stationary law: rho = max |1 - T g lambda_i|,
        stable iff T g mu_min > -2 (Theorem 1). Dynamic law (exact): rho = |1 - g T|
        for single integrators, stable iff 0 < g T < 2 (Theorem 2). The other laws'
        ranges are found numerically from their mode matrices.
    """
    part = Partition(omega, leaders)
    rtol = check_rtol(rtol)
    if check_bool(check, "check"):
        check_partition(part, rtol)
    dt = check_dt(dt)
    dyn = check_dynamics(dynamics) if dynamics is not None else LinearDynamics.single_integrator(2)
    if dt_search is None:
        dt_search = DT_SEARCH
    try:
        t_lo, t_hi = dt_search
    except (TypeError, ValueError) as exc:
        raise TypeError(f"dt_search must be a pair (T_lo, T_hi) of periods in seconds, got {dt_search!r}") from exc
    t_lo = check_dt(t_lo, "dt_search[0]")
    t_hi = check_dt(t_hi, "dt_search[1]")
    if not t_lo < t_hi:
        raise FormationError(f"dt_search must be increasing (T_lo < T_hi), got ({t_lo:g}, {t_hi:g})")
    lam_min, lam_max = extreme_eigenvalues(part)
    if lam_min <= 0:
        raise FormationError(f"Omega_ff is not positive definite (smallest eigenvalue {lam_min:.3g})")
    net = check_network(network)
    if net is None and x_leaders is not None:
        raise TypeError("x_leaders is used only with network= (the drop and log-quantiser quantities); got no network")
    the_law = make_law(law, part, dyn, dt, **params)
    if net is not None:
        check_network_law(law)
        return network_report(part, dyn, dt, law, params, net, x_leaders, (t_lo, t_hi), (lam_min, lam_max))
    if law == "stationary":  # exact from the extreme eigenvalues (no full spectrum for large sparse stresses)
        g = float(params.get("gain", 1.0))
        rho = max(abs(1.0 - dt * g * lam_min), abs(1.0 - dt * g * lam_max))
    else:
        rho = the_law.spectral_radius()
    notes: list[str] = []
    dt_range: tuple[float, float] | None = None
    eps = eps_range = None
    K = getattr(the_law, "K", None)
    windows: list[tuple[float, float]] | None = None
    dt_opt = rho_opt = jac = None
    if law == "stationary":
        gain = float(params.get("gain", 1.0))
        dt_range = (0.0, 2.0 / (gain * lam_max))
        dt_opt = 2.0 / (gain * (lam_min + lam_max))
        rho_opt = (lam_max - lam_min) / (lam_max + lam_min)
        windows = [(t_lo, min(t_hi, dt_range[1]))] if t_lo < dt_range[1] else []
        notes.append(
            f"Theorem 1: stable iff T g mu_min > -2, i.e. T < {dt_range[1]:.6g} s; the best T is "
            f"2 / (lambda_min + lambda_max) = {2.0 / (gain * (lam_min + lam_max)):.6g} s "
            "with rho = (cond - 1) / (cond + 1)"
        )
    elif isinstance(the_law, StressFeedbackLaw):  # linear, linear_paper
        eps = the_law.eps
        eps_range = the_law.eps_range()
        if law == "linear_paper":
            notes.append(
                "literal eq. 25: the '+ x_i' term pulls the followers toward the origin, so they do not reach "
                "the affine targets even when this matrix is Schur; use law='linear'"
            )
    elif isinstance(the_law, DynamicLeaderLaw):
        base = dict(params)
        rho_of = _dynamic_rho(the_law, dyn, params)
        dt_range = dt_interval(lambda t: _Rho(rho_of(t)), dt)
        windows, dt_opt, rho_opt = stable_windows(rho_of, t_lo, t_hi)
        if windows and dt_range == (0.0, 0.0):
            near = min(windows, key=lambda w: abs(math.log(math.sqrt(w[0] * w[1]) / dt)))
            dt_range = near
        if law == "dynamic" and dyn.is_single_integrator and "K" not in params:
            g = float(params.get("gain", 1.0))
            notes.append(
                f"Theorem 2: e(k+1) = (1 - g T) e(k); deadbeat at T = {1 / g:g} s, stable iff 0 < T < {2 / g:g} s"
            )
        if law == "dynamic_distributed":
            jac = float(np.max(np.abs(the_law.jacobi_eigenvalues())))
            notes.append(
                f"{the_law.rounds} Jacobi round(s) per sample, warm-started from the previous input; not in the paper. "
                f"Jacobi spectral radius rho(J) = {jac:.4g} (J = -D^-1 N_ff); the law can be stable for some T "
                "only if rho(J) < 1"
            )
            if jac >= 1.0:
                notes.append(
                    f"rho(J) = {jac:.4g} >= 1: no T and no number of rounds m stabilises dynamic_distributed on this "
                    "stress (a Jacobi mode never decays); use law='dynamic' (centralised solve) or 'stationary'"
                )
            elif not windows:
                m_ok = _rounds_that_work(law, part, dyn, base, t_lo, t_hi, the_law.rounds)
                notes.append(
                    f"never stable with m = {the_law.rounds} round(s) for T in [{t_lo:g}, {t_hi:g}] s; "
                    + (f"m = {m_ok} rounds gives stable windows" if m_ok else "no m up to 64 helps either")
                )
    if windows is not None and not windows and law != "dynamic_distributed":
        notes.append(f"never stable for T in [{t_lo:g}, {t_hi:g}] s")
    if law in ("linear", "linear_paper") and not dyn.is_single_integrator:
        notes.append(
            "the linear law tracks the affine targets only while the leaders move on free trajectories "
            "x_l(k+1) = A_d x_l(k) (u_l = 0); leaders held still or steered leave a tracking error (use 'dynamic')"
        )
    stable = rho < 1.0
    decay, steps = _decay(rho, dt)
    return StabilityReport(
        law=law,
        dt=float(dt),
        mu_min=-lam_max,
        mu_max=-lam_min,
        cond=lam_max / lam_min,
        spectral_radius=rho,
        stable=stable,
        dt_range=dt_range,
        eps=eps,
        eps_range=eps_range,
        decay_rate=decay,
        steps_to_1e6=steps,
        K=None if K is None else np.asarray(K),
        rounds=getattr(the_law, "rounds", None),
        notes=tuple(notes),
        windows=windows,
        dt_opt=dt_opt,
        rho_opt=rho_opt,
        dt_search=(t_lo, t_hi),
        jacobi_radius=jac,
    )


class _Rho:
    """A stand-in law for :func:`dt_interval`: only ``spectral_radius``."""

    def __init__(self, rho: float) -> None:
        self._rho = rho

    def spectral_radius(self) -> float:
        return self._rho


def _dynamic_rho(the_law: DynamicLeaderLaw, dyn: LinearDynamics, params: dict[str, Any]) -> Any:
    """T -> closed-loop spectral radius of a dynamic-leader law, reusing its T-independent parts
    (the Jacobi eigenvalues nu^m; a given K) instead of rebuilding the law at every T."""
    from .dynamics import c2d_zoh, riccati_gain
    from .laws import jacobi_modes, spectral_radius

    c = None if the_law.rounds is None else the_law.jacobi_eigenvalues() ** the_law.rounds
    fixed_k = params.get("K")
    gain = float(params.get("gain", 1.0))

    def rho(t: float) -> float:
        a_d, b_d = (dyn.A, dyn.B) if dyn.discrete else c2d_zoh(dyn.A, dyn.B, t)
        if fixed_k is not None:
            k = np.asarray(fixed_k, dtype=np.float64)
        elif dyn.is_single_integrator:
            k = -gain * np.eye(dyn.q)
        else:
            try:
                k = riccati_gain(a_d, b_d, params.get("Q"))
            except FormationError:
                return math.inf
        if c is None:
            return float(np.max(np.abs(np.linalg.eigvals(a_d + b_d @ k))))
        return spectral_radius(jacobi_modes(a_d, b_d, k, c))

    return rho


def _rounds_that_work(
    law: str, part: Partition, dyn: LinearDynamics, base: dict[str, Any], t_lo: float, t_hi: float, m0: int | None
) -> int | None:
    """The smallest m in 2, 4, .., 64 (above ``m0``) with a stable window on a coarse grid, or None."""
    grid = np.geomspace(t_lo, t_hi, 80)
    for m in (2, 4, 8, 16, 32, 64):
        if m0 is not None and m <= m0:
            continue
        kw = dict(base, rounds=m)
        if any(make_law(law, part, dyn, float(t), **kw).spectral_radius() < 1.0 for t in grid):
            return m
    return None


def require_stable(the_law: FollowerLaw) -> None:
    """Raise ``UnstableParameterError`` if the law's closed loop is not Schur."""
    rho = the_law.spectral_radius()
    if rho >= 1.0:
        raise UnstableParameterError(
            f"law {the_law.name} at T = {the_law.dt:g} s is unstable: closed-loop spectral radius {rho:.6g} >= 1"
        )


#: Largest delay (samples) searched for ``delay_max``.
DELAY_CAP = 64


def network_stability(part: Partition, dyn: LinearDynamics, dt: float, G: Any, net: Network) -> float | None:
    """The loop's per-sample decay factor over ``net`` (quantisation left out), or None when the
    framework is beyond the analysed size (``simulate`` then skips its warning)."""
    from .network import loop_model, network_radius

    try:
        return network_radius(loop_model(part, dyn, G, net), dt)
    except FormationError:
        return None


def network_report(
    part: Partition,
    dyn: LinearDynamics,
    dt: float,
    law: str,
    params: dict[str, Any],
    net: Network,
    x_leaders: Any,
    dt_search: tuple[float, float],
    lams: tuple[float, float],
) -> StabilityReport:
    """``stability_report`` over a network (see docs/networks.md).

    * Delay (no loss, no jitter): rho of the augmented one-step matrix [e(k), .., e(k - d), ...], exact.
    * Loss (and jitter): the augmented one-step matrix is affine in the independent deliveries theta_e,
      A = A_0 + sum_e theta_e A_e; mean-square stable iff rho(E[A kron A]) < 1 with
      E[A kron A] = Abar kron Abar + p (1 - p) sum_e A_e kron A_e (averaged over the period under jitter,
      Gauss-Legendre), exact. ``spectral_radius`` = sqrt(rho(E[A kron A])).
    * Jitter without loss: ``stable`` means stable for every period sequence in [T_min, T_max]: exact for
      the single-integrator loop without delay (commuting matrices), else a common quadratic Lyapunov
      function (sufficient); ``spectral_radius`` is still the RMS decay under i.i.d. uniform periods.
    * Quantisation (with a delay at most): uniform: stable iff the loop without quantisation is, and
      limsup max |e| <= N delta / 2; log: the sector condition delta_rho N < 1 (l-inf small gain,
      sufficient), N = sum_k ||C A^k E||_inf the gain from what is sent to the formation error.
    """
    from .network import (
        drop_steady_error,
        jitter_robust,
        loop_model,
        network_radius,
        quantisation_gain,
    )

    lam_min, lam_max = lams
    t_lo, t_hi = dt_search
    if net.quantise is not None and net.random:
        raise FormationError(
            "stability_report analyses quantisation alone or with a delay; with loss or jitter as well it is "
            "not implemented (simulate() runs it)"
        )
    xl = None
    if x_leaders is not None:
        from .network import as_leader_positions

        xl = as_leader_positions(x_leaders, part.n_l)
        if xl.shape[1] not in (dyn.d, dyn.q):
            raise FormationError(f"x_leaders must have shape ({part.n_l}, {dyn.d}) (positions), got {xl.shape}")
        if xl.shape[1] == dyn.d and dyn.q != dyn.d:
            xl = dyn.state_from_position(xl)

    def model_at(t: float, network: Network = net) -> Any:
        the_law = make_law(law, part, dyn, t, **params)
        return loop_model(part, dyn, the_law.eps * the_law.K, network)  # type: ignore[attr-defined]

    def rho_at(t: float, network: Network = net) -> float:
        try:
            return network_radius(model_at(t, network), t)
        except UnstableParameterError:
            return math.inf

    model = model_at(dt)
    the_law = make_law(law, part, dyn, dt, **params)
    rho = network_radius(model, dt)
    notes: list[str] = []
    exact = True
    stable = rho < 1.0
    if net.loss > 0:
        criterion = "mean-square stability, rho(E[A kron A]) < 1 over the independent link losses"
        if net.jitter is not None:
            criterion += " and the uniform periods"
    elif net.jitter is not None:
        stable, exact, how = jitter_robust(model, dt)
        criterion = f"stability for every sequence of periods in [{net.jitter[0]:g}, {net.jitter[1]:g}] s: {how}"
        notes.append(
            f"with periods drawn i.i.d. uniformly, the RMS error decays by {rho:.6g} per sample "
            "(sqrt(rho(E[A kron A])), exact mean square); that can hold where some period sequences diverge"
        )
    elif net.delay > 0:
        criterion = f"spectral radius of the augmented one-step matrix over the delay d = {net.delay}"
    else:
        criterion = "spectral radius of the closed loop (no delay, loss or jitter)"
    if net.delay > 0 and net.delayed == "input" and law == "stationary" and net.jitter is None and net.loss == 0:
        from .network import levin_may_bound

        g = float(params.get("gain", 1.0))
        bound = levin_may_bound(net.delay)
        notes.append(
            f"Levin and May: stable iff 0 < T g lambda_i < 2 sin(pi / (2 (2d + 1))) = {bound:.6g} for every "
            f"eigenvalue lambda_i of Omega_ff, i.e. T < {bound / (g * lam_max):.6g} s"
        )
    ultimate = None
    if net.quantise is not None:
        exact = False
        kind, val = net.quantise
        n_gain = quantisation_gain(model, dt)
        if kind == "uniform":
            ultimate = n_gain * val / 2.0
            criterion += f"; uniform quantiser: limsup max |e| <= N delta / 2 with N = {n_gain:.6g} (a bound)"
        else:
            delta = net.sector or 0.0
            ok = delta * n_gain < 1.0
            stable = stable and ok
            criterion += (
                f"; log quantiser sector condition delta N < 1 with delta = (1 - rho) / (1 + rho) = {delta:.6g}, "
                f"N = {n_gain:.6g}: {delta * n_gain:.6g} (l-inf small gain, sufficient)"
            )
            if ok and xl is not None:
                x_star = np.concatenate([xl, part.targets(xl)], axis=0)
                ultimate = n_gain * delta * float(np.max(np.abs(x_star))) / (1.0 - delta * n_gain)
            elif ok:
                notes.append("pass x_leaders for the log quantiser's ultimate bound (it scales with |x|)")
    steady = None
    if net.loss > 0 and net.loss_model == "drop":
        if xl is None:
            notes.append("pass x_leaders for the steady error the dropped terms leave")
        else:
            x_abs = np.zeros((part.n, xl.shape[1]))
            x_abs[part.leaders] = xl
            x_abs[part.followers] = part.targets(xl)
            steady = drop_steady_error(model, dt, x_abs)
            notes.append(
                "drop: every link delivers with the same probability 1 - p, so the mean error tends to 0 (no "
                f"bias in the mean); the dropped terms leave a random error of stationary RMS {steady:.6g}"
            )
    delay_max = None
    if net.delay > 0:
        delay_max = _largest(lambda d: rho_at(dt, _replace(net, delay=d)) < 1.0, DELAY_CAP)
        if delay_max == DELAY_CAP:
            notes.append(f"no delay up to {DELAY_CAP} samples destabilises the loop at this T (delay_max is the cap)")
    loss_max = None
    if net.loss > 0:
        loss_max = _largest_loss(lambda p: rho_at(dt, _replace(net, loss=p)) < 1.0)
    dt_range = None
    windows = dt_opt = rho_opt = None
    if net.jitter is None:
        windows, dt_opt, rho_opt = stable_windows(lambda t: rho_at(t), t_lo, t_hi, points=120, refine=40)
        inside = [w for w in windows if w[0] <= dt <= w[1]]
        if inside:
            dt_range = (0.0 if inside[0][0] == t_lo else inside[0][0], inside[0][1])
        elif windows:
            dt_range = min(windows, key=lambda w: abs(math.log(math.sqrt(w[0] * w[1]) / dt)))
    else:
        notes.append("under jitter the periods are given, so no range of T is reported")
    decay, steps = _decay(rho, dt)
    eps = getattr(the_law, "eps", None) if law == "linear" else None
    return StabilityReport(
        law=law,
        dt=float(dt),
        mu_min=-lam_max,
        mu_max=-lam_min,
        cond=lam_max / lam_min,
        spectral_radius=rho,
        stable=bool(stable),
        dt_range=dt_range,
        eps=eps,
        eps_range=the_law.eps_range() if law == "linear" else None,  # type: ignore[attr-defined]
        decay_rate=decay,
        steps_to_1e6=steps,
        K=np.asarray(the_law.K),  # type: ignore[attr-defined]
        notes=tuple(notes),
        windows=windows,
        dt_opt=dt_opt,
        rho_opt=rho_opt,
        dt_search=dt_search,
        network=net.as_dict(),
        exact=exact,
        criterion=criterion,
        delay_max=delay_max,
        loss_max=loss_max,
        steady_error=steady,
        ultimate_bound=ultimate,
    )


def _decay(rho: float, dt: float) -> tuple[float, float]:
    """The decay rate (1/s) and the samples to shrink an error 1e6-fold at per-sample factor ``rho`` (inf, 0 and
    inf, 1 at the edges; 0 and inf when unstable)."""
    decay = -math.log(rho) / dt if 0 < rho < 1 else (math.inf if rho == 0 else 0.0)
    steps = (math.log(1e-6) / math.log(rho) if 0 < rho < 1 else 1.0) if rho < 1 else math.inf
    return decay, steps


def _replace(net: Network, **changes: Any) -> Network:
    import dataclasses

    return dataclasses.replace(net, **changes)


def _largest(ok: Any, cap: int) -> int | None:
    """The largest d in 0..cap with ok(d), by doubling then bisection (ok taken monotone decreasing in d).
    A delay beyond the analysed size stops the search there. None if ok(0) fails."""

    def test(d: int) -> bool | None:
        try:
            return bool(ok(d))
        except FormationError:  # beyond the supported size
            return None

    if not test(0):
        return None
    good, bad = 0, None
    d = 1
    while bad is None:
        d = min(d, cap)
        res = test(d)
        if res is None:
            return good
        if res:
            good = d
            if d == cap:
                return cap
            d *= 2
        else:
            bad = d
    while bad - good > 1:
        mid = (good + bad) // 2
        res = test(mid)
        if res is None:
            return good
        good, bad = (mid, bad) if res else (good, mid)
    return good


def _largest_loss(ok: Any) -> float:
    """The largest p in [0, 1) with ok(p), by bisection to 1e-6 (ok taken monotone decreasing)."""
    if ok(1.0 - 1e-9):
        return 1.0
    good, bad = 0.0, 1.0 - 1e-9
    while bad - good > 1e-6:
        mid = 0.5 * (good + bad)
        if ok(mid):
            good = mid
        else:
            bad = mid
    return good


def network_dt_max(
    omega: Any,
    leaders: Sequence[int],
    network: Network | dict[str, Any],
    law: str = "stationary",
    dynamics: LinearDynamics | None = None,
    *,
    t_lo: float = 1e-3,
    t_hi: float = 10.0,
    points: int = 60,
    **params: Any,
) -> float:
    """The largest sampling period (s) of the first stable window of T over ``network`` (no jitter).

    Scans ``points`` log-spaced periods in [t_lo, t_hi] from below and bisects the first loss of stability
    (60 halvings); ``t_hi`` if none is lost, 0 if already ``t_lo`` is unstable. Stability is
    :func:`stability_report`'s: rho of the augmented matrix (delays), mean square (loss).
    """
    from .network import loop_model, network_radius

    part = Partition(omega, leaders)
    check_partition(part)
    net = check_network(network)
    if net is None:
        raise TypeError("network must be a Network or a dict of its fields, got None")
    if net.jitter is not None:
        raise FormationError("network_dt_max needs a network without jitter (under jitter the periods are given)")
    check_network_law(law)
    dyn = check_dynamics(dynamics) if dynamics is not None else LinearDynamics.single_integrator(2)
    t_lo, t_hi = check_dt(t_lo, "t_lo"), check_dt(t_hi, "t_hi")

    def stable(t: float) -> bool:
        try:
            the_law = make_law(law, part, dyn, t, **params)
        except UnstableParameterError:
            return False
        return network_radius(loop_model(part, dyn, the_law.eps * the_law.K, net), t) < 1.0  # type: ignore[attr-defined]

    grid = np.geomspace(t_lo, t_hi, points)
    if not stable(float(grid[0])):
        return 0.0
    for a, b in itertools.pairwise(grid):
        if not stable(float(b)):
            good, bad = float(a), float(b)
            for _ in range(60):
                mid = 0.5 * (good + bad)
                good, bad = (mid, bad) if stable(mid) else (good, mid)
            return good
    return float(t_hi)
