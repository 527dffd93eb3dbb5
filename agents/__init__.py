"""Leader policies: analytic planners and learned (SB3 or RLlib) policies behind one interface (``agents.policy``)."""

from .policy import AnalyticPolicy, LearnedPolicy, Policy, RLlibPolicy, load_policy

__all__ = ["AnalyticPolicy", "LearnedPolicy", "Policy", "RLlibPolicy", "load_policy"]
