"""The environment layer: one batched step, its components, and the env wrappers over it.

``engine.Engine`` steps B environments at once (pure ``step(state, actions)``), with the follower law from
``config``, obstacles from ``obstacles``, observation blocks from ``observations``, reward terms from
``rewards`` and tasks from ``scenarios``; ``state`` holds the records that pass between them.
``formation.FormationEnv`` is the PettingZoo parallel env (B = 1), re-exported by ``formation_env.formation_v0``;
``commander.FormationCommanderEnv`` the Gymnasium view; ``vector.FormationVecEnv`` the batched SB3 ``VecEnv``.
``docs/architecture.md`` has the picture.
"""
