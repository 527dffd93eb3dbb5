"""Leader policies: analytic planners and learned (SB3) policies behind one interface (``agents.policy``)."""

from .policy import AnalyticPolicy, LearnedPolicy, Policy, load_policy

__all__ = ["AnalyticPolicy", "LearnedPolicy", "Policy", "load_policy"]
