"""Training recipes as YAML files (``train/configs/``) and the JSON flags that override them, shared by
``train.leaders``, ``train.rllib``, ``train.evaluate`` and the ``formation-env`` CLI."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from formation_env.core.validation import json_object

__all__ = ["json_object", "load_recipe"]


def load_recipe(path: str | Path, keys: Sequence[str]) -> dict[str, Any]:
    """The mapping in the YAML file ``path``; a missing file, a non-mapping or a key not in ``keys`` raises,
    naming the file (and the key)."""
    import yaml

    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"--config: no recipe file at {p}")
    cfg = yaml.safe_load(p.read_text()) or {}
    if not isinstance(cfg, dict):
        raise ValueError(f"--config: {p} must hold a mapping of training arguments, got {type(cfg).__name__}")
    unknown = sorted(set(cfg) - set(keys))
    if unknown:
        raise ValueError(f"--config: {p} has unknown keys {unknown}; allowed: {list(keys)}")
    return cfg
