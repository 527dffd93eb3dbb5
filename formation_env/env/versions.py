"""Env versions: what ``formation_v0`` and ``formation_v1`` (and their Gymnasium ids ``-v0``, ``-v1``) default to.

A version is a set of default arguments over the engine's own; a change of a default observation, reward or
episode is a new version beside the old ones, so that results stay comparable. The caller's arguments sit
over the version's (``reward_weights`` merged term by term), the version's over the scenario's.

* ``0``: the engine's defaults (reward ``progress`` + ``formation`` + ``effort`` + ``collision`` +
  ``success``).
* ``1``: learnable from scratch (``docs/learning.md`` has the ablation): ``approach`` (a log potential on
  each leader's phase-space distance to its goal state) replaces ``progress``, and ``proximity`` warns of
  contacts before they happen.
"""

from __future__ import annotations

from typing import Any

from formation_env.core.validation import check_mapping

__all__ = ["ENV_VERSIONS", "LATEST", "with_version"]

#: Version -> its default arguments over the engine's.
ENV_VERSIONS: dict[int, dict[str, Any]] = {
    0: {},
    1: {"reward_weights": {"progress": 0.0, "approach": 3.0, "proximity": 2.0}},
}
#: The newest version.
LATEST = max(ENV_VERSIONS)


def with_version(version: int, kwargs: dict[str, Any]) -> dict[str, Any]:
    """``kwargs`` over version ``version``'s defaults (``reward_weights`` merged term by term)."""
    if isinstance(version, bool) or not isinstance(version, int) or version not in ENV_VERSIONS:
        raise ValueError(f"env version must be one of {sorted(ENV_VERSIONS)}, got {version!r}")
    base = ENV_VERSIONS[version]
    check_mapping(kwargs.get("reward_weights"), "reward_weights")
    out = {**base, **kwargs}
    if "reward_weights" in base:
        out["reward_weights"] = {**base["reward_weights"], **(kwargs.get("reward_weights") or {})}
    return out
