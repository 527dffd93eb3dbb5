"""Issue 21's done-when, kept: the bad-input probe finds no silent acceptance, refuses no valid edge input, and
leaves at most 5 obscure errors (benchmarks/bad_inputs_probe.py lists every case)."""

from __future__ import annotations

import pytest

from benchmarks.bad_inputs_probe import OBSCURE, REFUSED, SILENT, run


@pytest.mark.slow
def test_probe_finds_nothing_silent_and_few_obscure_errors():
    outcomes = run(("core", "env", "cli"), verbose=False)
    assert len(outcomes) > 600
    silent = [(o.name, o.detail) for o in outcomes if o.cls in (SILENT, REFUSED)]
    assert not silent, silent
    obscure = [(o.name, o.detail) for o in outcomes if o.cls == OBSCURE]
    assert len(obscure) <= 5, obscure
