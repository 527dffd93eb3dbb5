"""formation-env: discrete-time stress-matrix affine formation control as a research tool.

``formation_env.core`` is the numpy/scipy maths core; ``formation_env.formation_v0``
the PettingZoo environment.
"""

__version__ = "0.1.0"
