"""Choose a run's policy among its checkpoints on validation episodes (model selection, as early stopping does).

A run's weights move from rollout to rollout, and the last ones are not always the best: the run's
checkpoints (``checkpoints/``, ``train.leaders --checkpoints N``) from ``start`` of training on, and its final
weights, are each evaluated on the validation suite (seeds ``VALIDATION_SEED`` ..), and the one with the
highest success rate (then the fewest collisions, then the latest) becomes ``<name>.zip``. The validation
seeds are disjoint from the standard suites (0..999), the planner's tuning seeds (10,000..), the held-out
seeds (100,000..100,499) and the training draws (1,000,000..): the suites a policy is reported on play no
part in choosing it.

Files in the run folder: the final weights stay as ``<name>_last.zip`` (with its statistics and config), the
chosen ones are ``<name>.zip``, and ``selection.json`` holds every candidate's validation metrics.

Usage (a run trained without selection)::

    python -m train.select runs/narrow_passage_ppo_shared_seed0 --episodes 200
"""

from __future__ import annotations

import argparse
import json
import math
import re
import shutil
import sys
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

__all__ = ["VALIDATION_SEED", "select_checkpoint"]

#: First episode seed of the validation suite (see the module docstring for the seeds it avoids).
VALIDATION_SEED = 200_000

_FILES = ("{}.zip", "{}_vecnormalize.pkl", "{}_config.json")


def _copy(src: Sequence[Path], stem: Path) -> None:
    """Copy a (model zip, VecNormalize pickle, config json) triple to ``stem``'s three paths."""
    for s, pattern in zip(src, _FILES, strict=True):
        shutil.copyfile(s, pattern.format(stem))


def _number(x: Any) -> float | None:
    """``x`` as a float, None when it is not finite (no solved episode has no time to goal)."""
    return float(x) if math.isfinite(float(x)) else None


def candidates(run: Path, name: str, start: int) -> list[tuple[int, tuple[Path, Path]]]:
    """(leader steps, (zip, pickle)) of the run's checkpoints from ``start`` steps on, and of its final weights."""
    found = []
    for zp in (run / "checkpoints").glob(f"{name}_*_steps.zip"):
        m = re.fullmatch(rf"{re.escape(name)}_(\d+)_steps\.zip", zp.name)
        pkl = run / "checkpoints" / f"{name}_vecnormalize_{m.group(1) if m else ''}_steps.pkl"
        if m and int(m.group(1)) >= start and pkl.exists():
            found.append((int(m.group(1)), (zp, pkl)))
    last = run / f"{name}_last"
    return sorted(found) + [(10**18, (Path(f"{last}.zip"), Path(f"{last}_vecnormalize.pkl")))]


def select_checkpoint(
    run: str | Path, name: str | None = None, *, episodes: int = 200, seed: int = VALIDATION_SEED, start: float = 0.5
) -> dict[str, Any]:
    """Evaluate the run's candidates on ``episodes`` validation episodes and make the best ``<name>.zip``.

    Args:
        run: the run folder (``train.leaders --out``). name: the file stem (default: the one ``*_config.json``
            that is not a ``_last`` one).
        episodes: validation episodes per candidate. seed: the first validation seed.
        start: the first checkpoint considered, as a fraction of the run's timesteps (0.5: the second half).
    Returns:
        The selection record (also written to ``selection.json`` and to the chosen config's ``"selection"``):
        ``{"seed", "episodes", "start", "chosen_steps", "candidates": [{"steps", "success_rate",
        "collision_rate", "time_to_goal"}]}``; ``chosen_steps`` is None for the final weights.
    """
    from train.evaluate import evaluate

    run = Path(run)
    if name is None:
        stems = [p.name[: -len("_config.json")] for p in run.glob("*_config.json") if "_last_" not in p.name]
        if len(stems) != 1:
            raise ValueError(f"run: expected one <name>_config.json in {run}, found {sorted(stems)}; pass name")
        name = stems[0]
    if episodes < 1:
        raise ValueError(f"episodes must be >= 1, got {episodes}")
    if not 0.0 <= start <= 1.0:
        raise ValueError(f"start must be in [0, 1], got {start}")
    stem, last = run / name, run / f"{name}_last"
    if not Path(f"{last}.zip").exists():  # first selection of this run: its final weights become _last
        _copy([Path(p.format(stem)) for p in _FILES], last)
    config = json.loads(Path(f"{last}_config.json").read_text())
    rows: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory() as tmp:
        for steps, (zp, pkl) in candidates(run, name, int(start * int(config["timesteps"]))):
            probe = Path(tmp) / name
            _copy([zp, pkl, Path(f"{last}_config.json")], probe)
            m = evaluate(f"{probe}.zip", config["scenario"], episodes, seed, gif=False, generalisation=False)["metrics"]
            rows.append({"steps": None if steps == 10**18 else steps, "zip": zp, "pkl": pkl,
                         **{k: _number(m[k]) for k in ("success_rate", "collision_rate", "time_to_goal")}})  # fmt: skip
    best = max(rows, key=lambda r: (r["success_rate"], -r["collision_rate"], r["steps"] or 10**18))
    record = {
        "seed": int(seed),
        "episodes": int(episodes),
        "start": float(start),
        "chosen_steps": best["steps"],
        "candidates": [{k: v for k, v in r.items() if k not in ("zip", "pkl")} for r in rows],
    }
    _copy([best["zip"], best["pkl"], Path(f"{last}_config.json")], stem)
    Path(f"{stem}_config.json").write_text(json.dumps({**config, "selection": record}, indent=2))
    (run / "selection.json").write_text(json.dumps(record, indent=2))
    return record


def main(argv: Sequence[str] | None = None) -> int:
    """Select a trained run's policy and print the selection record as JSON."""
    p = argparse.ArgumentParser(prog="python -m train.select", description=__doc__.splitlines()[0])
    p.add_argument("run", help="the run folder (train.leaders --out)")
    p.add_argument("--episodes", type=int, default=200, help="validation episodes per candidate; default 200")
    p.add_argument("--seed", type=int, default=VALIDATION_SEED, help="first validation seed")
    p.add_argument("--from", dest="start", type=float, default=0.5, help="first candidate, fraction of the run")
    a = p.parse_args(argv)
    try:
        record = select_checkpoint(a.run, episodes=a.episodes, seed=a.seed, start=a.start)
    except (ValueError, FileNotFoundError) as exc:
        p.error(str(exc))
    print(json.dumps(record, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
