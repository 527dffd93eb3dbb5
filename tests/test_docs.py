"""The code on docs/architecture.md runs as written (its blocks in order, in one fresh process: the guide
registers a block, a term and a scenario, which must not leak into the other tests' registries)."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "architecture.md"


def test_architecture_guide_code_runs():
    blocks = re.findall(r"```python\n(.*?)```", DOC.read_text(), flags=re.S)
    assert len(blocks) >= 4
    code = "\n".join(blocks) + "\nprint('guide ran')\n"
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert res.returncode == 0, res.stderr[-3000:]
    assert res.stdout.strip().endswith("guide ran")


def test_readme_python_snippets_run():
    text = (ROOT / "README.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, flags=re.S)
    assert len(blocks) >= 3
    code = "\n".join(blocks) + "\nprint('readme ran')\n"
    env = {**__import__("os").environ, "SDL_VIDEODRIVER": "dummy"}
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=600, env=env)
    assert res.returncode == 0, res.stderr[-3000:]
    assert res.stdout.strip().endswith("readme ran")


def test_networks_page_code_runs():
    blocks = re.findall(r"```python\n(.*?)```", (ROOT / "docs" / "networks.md").read_text(), flags=re.S)
    assert blocks
    code = "\n".join(blocks) + "\nprint('networks ran')\n"
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert res.returncode == 0, res.stderr[-3000:]
    assert res.stdout.strip().endswith("networks ran")


def test_readme_policy_table_wall_times_are_the_configs():
    """Every wall time in the README's table of shipped policies is its ``_config.json``'s ``wall_time_s`` (min, to
    0.1), row by row: a policy retrained without its row rewritten fails here."""
    table = (ROOT / "README.md").read_text().split("| policy | command | wall time |")[1].split("\n\n")[0]
    checked = 0
    for row in table.strip().splitlines()[1:]:
        cells = [c.strip() for c in row.strip("|").split("|")]
        seeded = [s for s in re.findall(r"`([a-z0-9_]+)`", cells[0]) if re.search(r"_seed\d$", s)]
        if not seeded:
            continue
        base = re.sub(r"_seed\d$", "", next(s for s in seeded if not s.startswith("_")))
        stems = [base + s if s.startswith("_") else s for s in seeded]
        minutes = [float(m) for m in re.findall(r"(\d+(?:\.\d+)?)(?=,| min)", cells[2])]
        assert len(minutes) == len(stems), row
        for stem, m in zip(stems, minutes, strict=True):
            cfg = json.loads((ROOT / "agents" / "pretrained" / f"{stem}_config.json").read_text())
            assert round(cfg["wall_time_s"] / 60, 1) == m, (stem, m, cfg["wall_time_s"] / 60)
            checked += 1
    assert checked >= 45
