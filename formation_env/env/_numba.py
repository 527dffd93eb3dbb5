"""The decorator of the step's compiled functions, and the one-line notice while numba compiles them."""

from __future__ import annotations

import os
import sys
from collections.abc import Callable
from typing import Any

import numba

__all__ = ["jit"]


def jit(fn: Callable[..., Any]) -> Any:
    """``fn`` compiled by numba: the decorator of every part of the step and of every component (observation
    block, reward term, scenario or obstacle row). Cached on disk when ``fn`` comes from a file (not from a
    notebook cell or ``python -c``)."""
    source = getattr(getattr(fn, "__code__", None), "co_filename", "")
    return numba.njit(cache=os.path.isfile(source))(fn)


class _CompileNotice(numba.core.event.Listener):
    """One line on stderr when numba starts compiling a part of the step, once per process.

    numba fires ``"numba:compile"`` only when a function is not in its disk cache yet (the first run after an
    install, a change of the code, or a new composition of blocks and terms); a function loaded from the cache
    fires nothing, so later runs stay silent.
    """

    shown = False

    def on_start(self, event: Any) -> None:
        disp = event.data.get("dispatcher") if isinstance(event.data, dict) else None
        module = getattr(getattr(disp, "py_func", None), "__module__", None) or ""
        if self.shown or not module.startswith(("formation_env.", "formation_env_steps.")):
            return
        type(self).shown = True
        print(
            "formation-env: compiling the env's step kernels with numba (first run only, cached on disk) ...",
            file=sys.stderr,
            flush=True,
        )

    def on_end(self, event: Any) -> None:
        return None


numba.core.event.register("numba:compile", _CompileNotice())
