"""formation-env: discrete-time stress-matrix affine formation control as a research tool.

``formation_env.core`` is the numpy/scipy maths core; ``formation_env.formation_v0``
the PettingZoo environment; ``gymnasium.make("formation_env/FormationCommander-v0")``
the single-agent (commander) view, registered on import.
"""

__version__ = "0.1.0"


def _register_gymnasium() -> None:
    try:
        import gymnasium
    except ImportError:  # the maths core works without gymnasium
        return
    env_id = "formation_env/FormationCommander-v0"
    if env_id not in gymnasium.registry:
        gymnasium.register(id=env_id, entry_point="formation_env.env.commander:FormationCommanderEnv")


_register_gymnasium()
