"""The two entry points reach everything CI checks: ``make test`` runs the test suite and then ``make lint``."""

from __future__ import annotations

import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib


def _recipe(target: str) -> list[str]:
    """The recipe lines of a Makefile target."""
    lines = (ROOT / "Makefile").read_text().splitlines()
    start = next(i for i, line in enumerate(lines) if re.match(rf"^{target}:", line))
    out = []
    for line in lines[start + 1 :]:
        if not line.startswith("\t"):
            break
        out.append(line.strip())
    return out


def test_make_test_runs_the_linters_and_ci_runs_make_test() -> None:
    test = _recipe("test")
    assert any("pytest" in line for line in test)
    assert any(re.search(r"\$\(MAKE\).* lint$", line) for line in test), test
    lint = " ".join(_recipe("lint"))
    assert "ruff check ." in lint and "ruff format --check ." in lint and "mypy" in lint
    ci = [line for line in (ROOT / ".ci" / "run").read_text().splitlines() if line and not line.startswith("#")]
    assert ci[-1] == "make test"
    first_block = (ROOT / "README.md").read_text().split("```bash\n", 1)[1].split("```", 1)[0]
    assert first_block.split("\n")[:-1] == ["make run", "make test"]


def test_mypy_scope_is_the_library_the_policies_and_the_training_scripts() -> None:
    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["mypy"]
    assert cfg["files"] == ["formation_env", "agents", "train"]
    assert cfg["disallow_untyped_defs"] and cfg["check_untyped_defs"] and cfg["warn_unused_ignores"]
