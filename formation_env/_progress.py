"""Progress bars for the long commands (evaluate, report, leaderboard, bench): on stderr, never on stdout, so
``--json`` output stays one JSON object; shown on a terminal or when asked with ``--progress``.

tqdm comes with the ``train`` extra; without it the bar is a silent stand-in. This module imports only the standard
library at import time.
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

__all__ = ["add_progress_argument", "progress_bar"]


class _Silent:
    """What :func:`progress_bar` returns when nothing is shown: the used part of tqdm's interface, doing nothing."""

    n = 0

    def update(self, n: int = 1) -> None:
        self.n += n

    def set_description_str(self, desc: str) -> None:
        return None

    def close(self) -> None:
        return None

    def __enter__(self) -> _Silent:
        return self

    def __exit__(self, *exc: object) -> None:
        return None


def progress_bar(total: int, desc: str, show: bool | None = False, unit: str = "it") -> Any:
    """A tqdm bar of ``total`` steps on stderr, or a silent stand-in.

    Args:
        show: True always, False never (the default of library calls), None when stderr is a terminal (the
            default of the command line).
    """
    if show is None:
        show = sys.stderr.isatty()
    if not show:
        return _Silent()
    try:
        from tqdm import tqdm
    except ImportError:
        return _Silent()
    return tqdm(total=total, desc=desc, unit=unit, file=sys.stderr, leave=False, dynamic_ncols=True)


def add_progress_argument(p: argparse.ArgumentParser) -> None:
    """``--progress`` / ``--no-progress`` (default: a bar on stderr when it is a terminal)."""
    p.add_argument(
        "--progress",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="a progress bar on stderr (default: when stderr is a terminal)",
    )
