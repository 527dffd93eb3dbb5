"""Optional dependencies: import one, or fail with a single line that names the extra to install.

The base install (``pip install formation-env``) is the maths core alone: numpy and scipy. Everything
else comes with an extra (see ``[project.optional-dependencies]`` in ``pyproject.toml``)::

    design   cvxpy                                    design_stress(method="sdp" | "min_cond" | ...)
    env      gymnasium, pettingzoo, numba, pygame-ce  the PettingZoo / Gymnasium environments
    train    stable-baselines3, tensorboard, ...      train.leaders, the learned policies
    video    imageio, imageio-ffmpeg                  saving animations
    plots    matplotlib                               figures of the paper reproduction and reports
    rllib    ray[rllib]                               formation_env.integrations.rllib
    torchrl  torchrl, tensordict                      TorchRL
    benchmarl  benchmarl (torchrl 0.10-0.11)          formation_env.integrations.benchmarl
    bench    mpe2, vmas, supersuit                    the peer benchmarks

A function that needs one calls :func:`require` where it would import the module::

    cp = require("cvxpy", "design", "design_stress(method='sdp')")

and a user without it reads::

    ImportError: design_stress(method='sdp') needs cvxpy: pip install 'formation-env[design]'

This module imports only the standard library.
"""

from __future__ import annotations

import importlib
from types import ModuleType

__all__ = ["EXTRAS", "MissingExtra", "missing_message", "require"]

#: The extras and the top-level modules each one brings (import names, not distribution names).
EXTRAS: dict[str, tuple[str, ...]] = {
    "design": ("cvxpy",),
    "env": ("gymnasium", "pettingzoo", "numba", "pygame"),
    "train": ("stable_baselines3", "torch", "tensorboard", "tqdm", "rich"),
    "video": ("imageio", "imageio_ffmpeg"),
    "plots": ("matplotlib",),
    "rllib": ("ray",),
    "torchrl": ("torchrl", "tensordict"),
    "benchmarl": ("benchmarl",),
    "bench": ("mpe2", "vmas", "supersuit"),
}


class MissingExtra(ImportError):
    """An optional dependency is not installed; the message names the extra that brings it.

    A subclass of :class:`ImportError` (and so caught by ``except ImportError``), with
    ``.name`` the missing module and ``.extra`` the extra to install.
    """

    def __init__(self, message: str, *, name: str, extra: str) -> None:
        super().__init__(message, name=name)
        self.extra = extra


def missing_message(module: str, extra: str, what: str) -> str:
    """The one line :func:`require` raises: ``"<what> needs <module>: pip install 'formation-env[<extra>]'"``."""
    top = module.partition(".")[0]
    return f"{what} needs {top}: pip install 'formation-env[{extra}]'"


def require(module: str, extra: str, what: str) -> ModuleType:
    """Import and return ``module``, or raise :class:`MissingExtra` (an ``ImportError``) in one line.

    ``module`` is a dotted import name (``"cvxpy"``, ``"stable_baselines3.common.vec_env"``),
    ``extra`` the ``formation-env`` extra that installs it (``"design"``), ``what`` the feature
    that needs it, as the user called it (``"design_stress(method='sdp')"``).

    Only a missing ``module`` (or a missing package on its dotted path) becomes the one-line
    message; an installed module that fails inside its own imports (a broken dependency of
    it) re-raises that error as is, so a real breakage is not disguised as a missing extra.
    """
    try:
        return importlib.import_module(module)
    except ModuleNotFoundError as exc:
        parts = module.split(".")
        prefixes = {".".join(parts[: i + 1]) for i in range(len(parts))}
        if exc.name is not None and exc.name not in prefixes:
            raise
        raise MissingExtra(missing_message(module, extra, what), name=module, extra=extra) from None
