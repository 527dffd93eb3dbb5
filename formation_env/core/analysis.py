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

from .dynamics import LinearDynamics
from .errors import FormationError, UnstableParameterError
from .laws import DynamicLeaderLaw, FollowerLaw, StressFeedbackLaw, make_law
from .stress import Partition

__all__ = ["StabilityReport", "dt_interval", "extreme_eigenvalues", "stability_report"]


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
        if self.eps_range is not None:
            lines.append(
                f"  eps = {self.eps:.6g}, stable for eps in ({self.eps_range[0]:.6g}, {self.eps_range[1]:.6g})"
            )
        if self.stable:
            lines.append(f"  decay rate {self.decay_rate:.4g} 1/s, error / 1e6 in {self.steps_to_1e6:.1f} steps")
        lines.extend(f"  note: {n}" for n in self.notes)
        return "\n".join(lines)


def extreme_eigenvalues(part: Partition) -> tuple[float, float]:
    """Smallest and largest eigenvalue of Omega_ff (sparse: Lanczos, shift-invert at 0 for the smallest)."""
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


def stability_report(
    omega: Any,
    leaders: Sequence[int],
    dt: float = 1.0,
    law: str = "stationary",
    dynamics: LinearDynamics | None = None,
    **params: Any,
) -> StabilityReport:
    """Closed-loop stability of ``law`` on stress ``omega`` at sampling period ``dt`` (s).

    Args:
        omega: stress matrix, shape (n, n), dense or sparse.
        leaders: leader indices.
        dt: sampling period T (s).
        law: one of ``stationary``, ``linear``, ``linear_paper``, ``dynamic``, ``dynamic_distributed``.
        dynamics: agent dynamics; default single integrators in 2D (the spectrum does not depend on d).
        **params: law parameters (gain, eps, K, Q, rounds), see :func:`make_law`.

    Returns:
        A :class:`StabilityReport`. Stationary law: rho = max |1 - T g lambda_i|,
        stable iff T g mu_min > -2 (Theorem 1). Dynamic law (exact): rho = |1 - g T|
        for single integrators, stable iff 0 < g T < 2 (Theorem 2). The other laws'
        ranges are found numerically from their mode matrices.
    """
    part = Partition(omega, leaders)
    dyn = dynamics if dynamics is not None else LinearDynamics.single_integrator(2)
    lam_min, lam_max = extreme_eigenvalues(part)
    if lam_min <= 0:
        raise FormationError(f"Omega_ff is not positive definite (smallest eigenvalue {lam_min:.3g})")
    the_law = make_law(law, part, dyn, dt, **params)
    rho = the_law.spectral_radius()
    notes: list[str] = []
    dt_range: tuple[float, float] | None = None
    eps = eps_range = None
    K = getattr(the_law, "K", None)
    if law == "stationary":
        gain = float(params.get("gain", 1.0))
        dt_range = (0.0, 2.0 / (gain * lam_max))
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
        dt_range = dt_interval(lambda t: make_law(law, part, dyn, t, **base), dt)
        if law == "dynamic" and dyn.is_single_integrator and "K" not in params:
            g = float(params.get("gain", 1.0))
            notes.append(
                f"Theorem 2: e(k+1) = (1 - g T) e(k); deadbeat at T = {1 / g:g} s, stable iff 0 < T < {2 / g:g} s"
            )
        if law == "dynamic_distributed":
            notes.append(
                f"{the_law.rounds} Jacobi round(s) per sample, warm-started from the previous input; not in the paper. "
                f"Jacobi spectral radius {np.max(np.abs(the_law.jacobi_eigenvalues())):.4g}"
            )
    stable = rho < 1.0
    decay = -math.log(rho) / dt if 0 < rho < 1 else (math.inf if rho == 0 else 0.0)
    steps = (math.log(1e-6) / math.log(rho) if 0 < rho < 1 else 1.0) if stable else math.inf
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
    )


def require_stable(the_law: FollowerLaw) -> None:
    """Raise ``UnstableParameterError`` if the law's closed loop is not Schur."""
    rho = the_law.spectral_radius()
    if rho >= 1.0:
        raise UnstableParameterError(
            f"law {the_law.name} at T = {the_law.dt:g} s is unstable: closed-loop spectral radius {rho:.6g} >= 1"
        )
