"""The environment layer: batched engine, scenarios, PettingZoo env, commander env and rendering.

``engine.Engine`` steps B environments at once (pure ``step(state, actions)``);
``formation.FormationEnv`` is the PettingZoo parallel env over it (B = 1), re-exported by
``formation_env.formation_v0``; ``commander.FormationCommanderEnv`` the Gymnasium view.
"""
