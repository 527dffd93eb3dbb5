"""Configuration of the engine: dynamics, framework and stress, the follower law and its defaults.

Nothing here steps; :class:`~formation_env.env.engine.Engine` calls these once at construction.

* Frameworks of up to ``MAX_AGENTS`` agents keep a dense stress, and the law's one-step linear map M
  ([x', mem'] = [x, u_l, mem] M, read off ``FollowerLaw.step`` by probing it with unit vectors: every law is
  linear) is the update: one matmul. Larger ones keep a scipy.sparse CSR stress and step the core law
  itself (``FollowerLaw.step``: a sparse product, a sparse LU solve for ``dynamic``), O(n + edges).
* Law defaults where the core's are slow or unstable: see :func:`make_follower_law`.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import ArrayLike, NDArray

from formation_env.core.analysis import extreme_eigenvalues
from formation_env.core.design import design_stress, trilateration_cliques
from formation_env.core.dynamics import LinearDynamics, riccati_gain
from formation_env.core.errors import ControlDimension, FormationError
from formation_env.core.framework import Framework
from formation_env.core.frameworks import NAMED_FRAMEWORKS
from formation_env.core.laws import (
    DynamicLeaderLaw,
    FollowerLaw,
    gamma_interval,
    jacobi_modes,
    make_law,
    spectral_radius,
    stress_modes,
)
from formation_env.core.stress import Partition, check_stress
from formation_env.core.validation import check_square_matrix

from .scenarios import REGISTRY

__all__ = [
    "DYNAMICS",
    "FOLLOWER_LAWS",
    "MAX_AGENTS",
    "check_combination",
    "make_follower_law",
    "offered_combinations",
    "resolve_dynamics",
    "resolve_framework",
]

Array = NDArray[np.float64]

#: Follower laws the env offers (``linear_paper`` is left out: its followers do not track, see core.laws).
FOLLOWER_LAWS: tuple[str, ...] = ("stationary", "dynamic", "dynamic_distributed", "linear")
#: Named dynamics (a ``LinearDynamics`` is accepted too).
DYNAMICS: tuple[str, ...] = ("single_integrator", "double_integrator")
#: Largest framework with a dense stress and the law's linear map; larger ones stay sparse (read at
#: construction, so tests may lower it).
MAX_AGENTS = 256

#: Up to this many followers the spectra of Omega_ff and of the Jacobi matrix are computed exactly
#: (dense), as the folded path does; above, their extreme eigenvalues bound an interval.
EXACT_SPECTRUM_UP_TO = 2000
#: Points of the eigenvalue interval at which the modes are evaluated above ``EXACT_SPECTRUM_UP_TO``.
INTERVAL_POINTS = 513


# ---------------------------------------------------------------------------- configuration
def resolve_dynamics(dynamics: str | LinearDynamics, d: int) -> LinearDynamics:
    """``"single_integrator"`` | ``"double_integrator"`` in R^d, or a ``LinearDynamics`` with position dim d."""
    if not isinstance(dynamics, LinearDynamics | str):
        raise TypeError(f"dynamics must be one of {list(DYNAMICS)} or a LinearDynamics, got {type(dynamics).__name__}")
    if isinstance(dynamics, LinearDynamics):
        if dynamics.d != d:
            raise ControlDimension(f"dynamics has position dimension {dynamics.d}, the framework is in R^{d}")
        return dynamics
    if dynamics == "single_integrator":
        return LinearDynamics.single_integrator(d)
    if dynamics == "double_integrator":
        return LinearDynamics.double_integrator(d)
    raise FormationError(f"unknown dynamics {dynamics!r}; choose one of {list(DYNAMICS)} or pass a LinearDynamics")


def check_combination(follower_law: str, dynamics: LinearDynamics) -> None:
    """Refuse law/dynamics pairs the env does not offer, with the reason."""
    if not isinstance(follower_law, str):
        raise TypeError(f"follower_law must be one of {list(FOLLOWER_LAWS)}, got {type(follower_law).__name__}")
    if follower_law not in FOLLOWER_LAWS:
        extra = " (linear_paper is the paper's literal eq. 25, whose followers do not track)" * (
            follower_law == "linear_paper"
        )
        raise FormationError(f"unknown follower_law {follower_law!r}{extra}; choose one of {list(FOLLOWER_LAWS)}")
    if follower_law == "stationary" and not dynamics.is_single_integrator:
        raise FormationError(
            f"follower_law='stationary' (eq. 17) needs single_integrator dynamics, got {dynamics.name}; "
            "use 'dynamic', 'dynamic_distributed' or 'linear'"
        )


def offered_combinations() -> list[tuple[str, str, str]]:
    """Every (scenario, dynamics, follower_law) the env offers, for parametrised tests."""
    return [
        (s, dyn, law)
        for s in REGISTRY
        for dyn in DYNAMICS
        for law in FOLLOWER_LAWS
        if not (law == "stationary" and dyn != "single_integrator")
    ]


def _designed_stress(fw: Framework) -> Any:
    """A stress for ``fw`` by ``design_stress``: the fast constructive design on a trilateration ordering, else
    the SDP."""
    try:
        trilateration_cliques(fw)
        method = "constructive"
    except FormationError:
        method = "sdp"
    return design_stress(fw, method)


def resolve_framework(
    framework: str | Framework | None, omega: ArrayLike | None, default: str
) -> tuple[Framework, Any]:
    """The framework and its checked stress matrix: dense (n, n), or scipy.sparse CSR above ``MAX_AGENTS``.

    Args:
        framework: a name (``NAMED_FRAMEWORKS`` or a function of ``formation_env.core.frameworks``),
            a ``Framework``, or None for ``default``.
        omega: stress matrix (n, n), dense or scipy.sparse; None takes the named one, or designs one.
    Raises:
        FormationError: unknown name; StressMatrixError: omega fails ``check_stress``.
    """
    name = default if framework is None else framework
    om: Any = None
    if isinstance(name, str):
        if name in NAMED_FRAMEWORKS:
            fw, om = NAMED_FRAMEWORKS[name]()
        else:
            from formation_env.core import frameworks as lib

            fn = getattr(lib, name, None)
            if name.startswith("_") or not callable(fn):
                raise FormationError(
                    f"unknown framework {name!r}; named ones are {sorted(NAMED_FRAMEWORKS)} and the functions of "
                    "formation_env.core.frameworks, or pass a Framework"
                )
            fw = fn()
            if not isinstance(fw, Framework):
                raise FormationError(f"formation_env.core.frameworks.{name}() did not return a Framework")
    elif isinstance(name, Framework):
        fw = name
    else:
        raise TypeError(f"framework must be a name or a Framework, got {type(name).__name__}")
    om = omega if omega is not None else om
    if om is None:
        om = _designed_stress(fw)
    om = check_square_matrix(om, "omega")
    if fw.n > MAX_AGENTS:  # the sparse path: never densify
        om = sp.csr_matrix(om, dtype=np.float64)
    elif sp.issparse(om):
        om = om.toarray()
    check_stress(om, fw)
    return fw, om


# ---------------------------------------------------------------------------- the law
_MAP_CACHE: dict[tuple[Any, ...], tuple[FollowerLaw, Array, float]] = {}


def _key(x: Any) -> Any:
    if isinstance(x, np.ndarray):
        return (x.shape, x.tobytes())
    if isinstance(x, dict):
        return tuple(sorted((k, _key(v)) for k, v in x.items()))
    return x


def _law_and_map(
    omega: Array, leaders: tuple[int, ...], dyn: LinearDynamics, law_name: str, dt: float, params: dict[str, Any]
) -> tuple[FollowerLaw, Array, float]:
    """The law, its one-step linear map M with [x', mem'] = [x, u_l, mem] @ M, and its spectral radius."""
    key = (_key(omega), leaders, _key(dyn.A), _key(dyn.B), _key(dyn.C), dyn.discrete, law_name, dt, _key(params))
    hit = _MAP_CACHE.get(key)
    if hit is not None:
        return hit
    part = Partition(omega, leaders)
    law = make_law(law_name, part, dyn, dt, **params)
    n, q, p = part.n, dyn.q, dyn.p
    mem0 = law.initial_memory((1,))
    m = 0 if mem0 is None else int(mem0[0].size)
    z = n * q + part.n_l * p + m
    eye = np.eye(z)
    xs = eye[:, : n * q].reshape(z, n, q)
    us = eye[:, n * q : n * q + part.n_l * p].reshape(z, part.n_l, p)
    ms = None if m == 0 else eye[:, n * q + part.n_l * p :].reshape(z, part.n_f, p)
    x1, mem1 = law.step(xs, us, ms)
    cols = [x1.reshape(z, -1)] + ([] if mem1 is None else [np.asarray(mem1).reshape(z, -1)])
    mat = np.concatenate(cols, axis=1)
    try:
        rho = float(law.spectral_radius())
    except FormationError:
        rho = float("nan")
    if len(_MAP_CACHE) > 64:
        _MAP_CACHE.clear()
    _MAP_CACHE[key] = (law, mat, rho)
    return law, mat, rho


def _fewest_stable_rounds(
    omega: Array, leaders: tuple[int, ...], dyn: LinearDynamics, dt: float, params: dict[str, Any], most: int = 30
) -> int:
    """The fewest Jacobi rounds m <= ``most`` whose ``dynamic_distributed`` closed loop is stable (else 1).

    Odd m can be unstable where even m is not (a negative Jacobi eigenvalue nu gives c = nu^m < 0):
    on the paper's framework with double integrators at T = 0.1, m = 1 diverges and m = 2 converges.
    """
    for m in range(1, most + 1):
        if _law_and_map(omega, leaders, dyn, "dynamic_distributed", dt, {**params, "rounds": m})[2] < 1.0:
            return m
    return 1


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
    """The follower law on a sparse stress and the spectral radius of its error dynamics, with the defaults of
    :func:`make_follower_law` filled into ``params`` without a dense n x n."""
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
            stable = (m for m in range(1, 31) if spectral_radius(jacobi_modes(A_d, B_d, probe.K, nu**m)) < 1.0)
            params["rounds"] = next(stable, 1)
        law = make_law(law_name, part, dyn, dt, **params)
        return law, spectral_radius(jacobi_modes(A_d, B_d, probe.K, nu ** int(params["rounds"])))
    law = make_law(law_name, part, dyn, dt, **params)
    if law_name in ("stationary", "linear"):
        return law, spectral_radius(stress_modes(law.A_d, law.B_d, law.K, law.eps, lam))  # type: ignore[attr-defined]
    return law, float(law.spectral_radius())


def make_follower_law(
    omega: Any, leaders: tuple[int, ...], dyn: LinearDynamics, law_name: str, dt: float, params: dict[str, Any]
) -> tuple[FollowerLaw, Array | None, float]:
    """The follower law with the engine's defaults filled into ``params``, its one-step linear map M
    ([x', mem'] = [x, u_l, mem] M; None on a sparse stress) and the spectral radius of its error dynamics.

    Defaults where the core's are slow or unstable: ``stationary`` without ``gain`` takes g = 2 / (T (lambda_min +
    lambda_max)) of Omega_ff (the fastest, Theorem 1); ``dynamic_distributed`` without ``rounds`` the fewest
    rounds (<= 30) with a stable closed loop; on a sparse stress ``linear`` without ``eps`` the eps minimising the
    worst mode over [lambda_min, lambda_max] (:func:`make_swarm_law`).
    """
    if sp.issparse(omega):
        law, rho = make_swarm_law(omega, leaders, dyn, law_name, dt, params)
        return law, None, rho
    if law_name == "stationary" and "gain" not in params:
        lam = np.linalg.eigvalsh(Partition(omega, leaders).omega_ff_dense)
        params["gain"] = 2.0 / (dt * (lam[0] + lam[-1]))
    if law_name == "dynamic_distributed" and "rounds" not in params:
        params["rounds"] = _fewest_stable_rounds(omega, leaders, dyn, dt, params)
    return _law_and_map(omega, leaders, dyn, law_name, dt, params)
