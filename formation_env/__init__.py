"""formation-env: discrete-time stress-matrix affine formation control as a research tool.

``formation_env.core`` is the numpy/scipy maths core; ``formation_env.formation_v0``
the PettingZoo environment; the Gymnasium ids below the single-agent (commander) view.

Gymnasium ids
-------------
``formation_env/FormationCommander-v0`` takes the scenario as a keyword (no step limit of its
own beyond the env's ``max_cycles``); one id per scenario fixes it, with ``max_episode_steps=400``
(:data:`SCENARIO_IDS` lists them). ``gym.make_vec(id, num_envs=N)`` steps N of them as one batch
(:data:`VECTOR_ENTRY_POINT`; ``vectorization_mode="sync"`` gives Gymnasium's loop over N single envs)::

    import gymnasium as gym

    env = gym.make("formation_env:formation_env/NarrowPassage-v0")  # in a fresh process
    # or
    import formation_env
    env = gym.make(formation_env.SCENARIO_IDS["narrow_passage"])

``import formation_env`` imports nothing beyond the standard library (no gymnasium, torch, cvxpy
or pygame): if gymnasium is already imported the ids are registered at once, otherwise when
gymnasium is first imported. The base install is the maths core alone; the environments need
``pip install 'formation-env[env]'`` (see :mod:`formation_env._extras`).
"""

from __future__ import annotations

import sys
from importlib.abc import MetaPathFinder
from importlib.machinery import ModuleSpec
from types import ModuleType
from typing import Any

__version__ = "0.1.0"

__all__ = [
    "COMMANDER_ENTRY_POINT",
    "COMMANDER_ID",
    "COMMANDER_ID_V1",
    "MAX_EPISODE_STEPS",
    "SCENARIO_IDS",
    "SCENARIO_IDS_V1",
    "VECTOR_ENTRY_POINT",
    "register_gymnasium",
]

#: The Gymnasium id of the commander env with the scenario as a keyword: ``gym.make(COMMANDER_ID, scenario=...)``.
COMMANDER_ID = "formation_env/FormationCommander-v0"

#: Where every commander id points.
COMMANDER_ENTRY_POINT = "formation_env.env.commander:FormationCommanderEnv"

#: ``max_episode_steps`` of every per-scenario id (the env's own ``max_cycles`` default is the same).
MAX_EPISODE_STEPS = 400

#: Scenario name (as in ``formation_env.env.scenarios.REGISTRY``) -> its Gymnasium id, registered with
#: ``kwargs={"scenario": name}`` and ``max_episode_steps=400``. ``gym.make(SCENARIO_IDS["hold"])``
#: after ``import formation_env``, or ``gym.make("formation_env:" + SCENARIO_IDS["hold"])`` anywhere.
SCENARIO_IDS: dict[str, str] = {
    "hold": "formation_env/Hold-v0",
    "maneuver": "formation_env/Maneuver-v0",
    "maneuver_3d": "formation_env/Maneuver3D-v0",
    "narrow_passage": "formation_env/NarrowPassage-v0",
    "obstacle_field": "formation_env/ObstacleField-v0",
    "moving_obstacles": "formation_env/MovingObstacles-v0",
}


#: The same scenarios with env version 1's defaults (``formation_v1``: the learnable rewards), registered with
#: ``kwargs={"scenario": name, "version": 1}``; :data:`COMMANDER_ID_V1` takes the scenario as a keyword.
SCENARIO_IDS_V1: dict[str, str] = {name: env_id[: -len("-v0")] + "-v1" for name, env_id in SCENARIO_IDS.items()}
COMMANDER_ID_V1 = "formation_env/FormationCommander-v1"
VERSIONED_ENTRY_POINT = "formation_env.env.commander:versioned"

#: The ``vector_entry_point`` of every id: ``gym.make_vec(id, num_envs=N)`` steps the N envs as one batch
#: (``formation_env.env.batch.GymnasiumFormationVecEnv``), env b replaying ``gym.make(id)`` seeded ``seed + b``.
VECTOR_ENTRY_POINT = "formation_env.env.commander:vector"


def register_gymnasium(gymnasium: ModuleType | None = None) -> None:
    """Register :data:`COMMANDER_ID` and every id of :data:`SCENARIO_IDS` with Gymnasium (idempotent).

    Called for you: on ``import formation_env`` when gymnasium is already imported, otherwise as soon
    as gymnasium is. Registering imports nothing of the env; ``gym.make`` does.
    """
    gym: Any = gymnasium
    if gym is None:
        import gymnasium as gym
    registry = gym.registry
    if COMMANDER_ID not in registry:
        gym.register(id=COMMANDER_ID, entry_point=COMMANDER_ENTRY_POINT, vector_entry_point=VECTOR_ENTRY_POINT)
    if COMMANDER_ID_V1 not in registry:
        gym.register(
            id=COMMANDER_ID_V1,
            entry_point=VERSIONED_ENTRY_POINT,
            vector_entry_point=VECTOR_ENTRY_POINT,
            kwargs={"version": 1},
        )
    for ids, entry, extra in (
        (SCENARIO_IDS, COMMANDER_ENTRY_POINT, {}),
        (SCENARIO_IDS_V1, VERSIONED_ENTRY_POINT, {"version": 1}),
    ):
        for scenario, env_id in ids.items():
            if env_id not in registry:
                gym.register(
                    id=env_id,
                    entry_point=entry,
                    vector_entry_point=VECTOR_ENTRY_POINT,
                    max_episode_steps=MAX_EPISODE_STEPS,
                    kwargs={"scenario": scenario, **extra},
                )


class _RegisterWhenGymnasiumLoads(MetaPathFinder):
    """A one-shot import hook: when ``gymnasium`` is first imported, register our ids right after it loads.

    It finds nothing itself: it asks the other finders for gymnasium's spec and wraps that spec's
    loader so that :func:`register_gymnasium` runs once the module has executed. Without gymnasium
    installed it does nothing.
    """

    def find_spec(self, fullname: str, path: Any = None, target: Any = None) -> ModuleSpec | None:
        if fullname != "gymnasium":
            return None
        _remove_hook()
        from importlib.util import find_spec

        spec = find_spec("gymnasium")
        if spec is None or spec.loader is None or not hasattr(spec.loader, "exec_module"):
            return spec
        loader: Any = spec.loader
        exec_module = loader.exec_module

        def exec_then_register(module: ModuleType) -> None:
            exec_module(module)
            try:
                register_gymnasium(module)
            except Exception as exc:  # never break gymnasium's own import
                import warnings

                warnings.warn(f"formation_env could not register its Gymnasium ids: {exc!r}", stacklevel=2)

        loader.exec_module = exec_then_register
        return spec


_HOOK = _RegisterWhenGymnasiumLoads()


def _remove_hook() -> None:
    try:
        sys.meta_path.remove(_HOOK)
    except ValueError:
        pass


if "gymnasium" in sys.modules:  # e.g. gym.make("formation_env:formation_env/NarrowPassage-v0")
    register_gymnasium(sys.modules["gymnasium"])
else:
    sys.meta_path.insert(0, _HOOK)
