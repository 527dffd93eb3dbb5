"""The decorator of the step's compiled functions, their disk cache's freshness, and the one-line notice while
numba compiles them.

numba caches a compiled function with a stamp of its own file only, while the machine code it saves holds the
code of every compiled function it calls: edit ``obstacles.py`` and ``kernel.contacts_row``, which calls
``obstacles.path_clearance``, would load its old code. Every function compiled by :func:`jit` is cached instead
with the stamp :func:`source_stamp`: the hash of its own file and of the file of every compiled function it
calls, module by module, so an edit to any of them compiles it again. The composed step's key
(:func:`formation_env.env.kernel.compose`) is made of the same stamps.
"""

from __future__ import annotations

import hashlib
import os
import sys
import types
from collections.abc import Callable
from typing import Any

import numba
from numba.core import caching
from numba.core.dispatcher import Dispatcher

__all__ = ["jit", "source_files", "source_stamp"]

#: The attribute of a Python function that carries its stamp to the cache locator.
_STAMP = "__formation_env_stamp__"
#: numba's cache implementation, whose locator classes find where (and with which stamp) a function is cached.
_IMPL: Any = vars(caching).get("CacheImpl") or vars(caching)["_CacheImpl"]


def _file_hash(path: str) -> str:
    st = os.stat(path)
    return _file_hash_at(path, st.st_mtime_ns, st.st_size)


_HASHES: dict[tuple[str, int, int], str] = {}


def _file_hash_at(path: str, mtime: int, size: int) -> str:
    key = (path, mtime, size)
    if key not in _HASHES:
        with open(path, "rb") as fh:
            _HASHES[key] = hashlib.sha256(fh.read()).hexdigest()
    return _HASHES[key]


def _code_names(code: types.CodeType) -> set[str]:
    names = set(code.co_names)
    for const in code.co_consts:
        if isinstance(const, types.CodeType):
            names |= _code_names(const)
    return names


def source_files(fn: Any, _seen: set[int] | None = None) -> set[str]:
    """The source files of a compiled function (a numba dispatcher or its Python function) and of every compiled
    function it calls, as far as its module's globals name them now (a callee in the same file is covered by the
    file)."""
    py = getattr(fn, "py_func", fn)
    seen = set() if _seen is None else _seen
    if id(py) in seen or not hasattr(py, "__code__"):
        return set()
    seen.add(id(py))
    own = getattr(py.__code__, "co_filename", "")
    files = {own} if os.path.isfile(own) else set()
    glb = getattr(py, "__globals__", {})
    names = _code_names(py.__code__)
    for name in names:
        obj = glb.get(name)
        if isinstance(obj, types.ModuleType):  # ``module.function`` in the code
            callees = [getattr(obj, attr, None) for attr in names]
        else:
            callees = [obj]
        for callee in callees:
            if isinstance(callee, Dispatcher):
                files |= source_files(callee, seen)
    return files


def source_stamp(fn: Any) -> str:
    """The hash of :func:`source_files` of ``fn`` (their contents), or a key unique to this process when ``fn`` has
    no file (a notebook cell, ``python -c``) or closes over variables (numba takes their values as constants)."""
    py = getattr(fn, "py_func", fn)
    given = getattr(py, _STAMP, None)
    if given is not None:
        return str(given)
    files = sorted(source_files(py))
    if not files or getattr(py, "__closure__", None):
        return f"process {os.getpid()}: {id(py)}"
    digest = hashlib.sha256()
    for path in files:
        digest.update(f"{path}\0{_file_hash(path)}\0".encode())
    return digest.hexdigest()[:32]


class _StampedLocator(caching._CacheLocator):
    """numba's own cache location for a function, with :func:`source_stamp` as its freshness stamp."""

    def __init__(self, inner: Any, stamp: str) -> None:
        self._inner = inner
        self._stamp = stamp

    def ensure_cache_path(self) -> None:
        self._inner.ensure_cache_path()

    def get_cache_path(self) -> str:
        return str(self._inner.get_cache_path())

    def get_source_stamp(self) -> str:
        return self._stamp

    def get_disambiguator(self) -> str:
        return str(self._inner.get_disambiguator())

    @classmethod
    def from_function(cls, py_func: Any, py_file: str) -> _StampedLocator | None:
        stamp = getattr(py_func, _STAMP, None)
        if stamp is None:
            return None
        for other in _IMPL._locator_classes:
            if other is cls:
                continue
            inner = other.from_function(py_func, py_file)
            if inner is not None:
                return cls(inner, stamp)
        return None


if _StampedLocator not in _IMPL._locator_classes:
    _IMPL._locator_classes.insert(0, _StampedLocator)


def jit(fn: Callable[..., Any]) -> Any:
    """``fn`` compiled by numba: the decorator of every part of the step and of every component (observation
    block, reward term, scenario or obstacle row). Cached on disk, with the stamp of :func:`source_stamp`, when
    ``fn`` comes from a file (not from a notebook cell or ``python -c``)."""
    stamp = source_stamp(fn)
    cache = not stamp.startswith("process ")
    if cache:
        setattr(fn, _STAMP, stamp)
    return numba.njit(cache=cache)(fn)


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
