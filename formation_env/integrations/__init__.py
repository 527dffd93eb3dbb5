"""Bridges to other RL libraries (each in its own optional extra): :mod:`~formation_env.integrations.rllib`."""
