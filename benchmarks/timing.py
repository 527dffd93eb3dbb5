"""Shared timing helpers: medians over repeats, interleaved comparisons, machine description."""

from __future__ import annotations

import os
import platform
import statistics
import time
from collections.abc import Callable


def time_call(fn: Callable[[], object], number: int, repeat: int) -> list[float]:
    """Seconds per call of ``fn`` for each of ``repeat`` batches of ``number`` calls."""
    out = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        for _ in range(number):
            fn()
        out.append((time.perf_counter() - t0) / number)
    return out


def interleaved(fns: dict[str, Callable[[], object]], number: int, repeat: int) -> dict[str, list[float]]:
    """Time several functions batch by batch in turn, so machine noise hits them alike."""
    res: dict[str, list[float]] = {k: [] for k in fns}
    for _ in range(repeat):
        for name, fn in fns.items():
            res[name].extend(time_call(fn, number, 1))
    return res


def summary(samples: list[float]) -> tuple[float, float, float]:
    """(median, min, max) of per-call seconds."""
    return statistics.median(samples), min(samples), max(samples)


def machine() -> str:
    """One line: CPU model, cores, Python, numpy."""
    import numpy as np

    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return f"{cpu}, {os.cpu_count()} cores, Python {platform.python_version()}, numpy {np.__version__}"
