"""The maths core of formation-env: numpy and scipy only (cvxpy for stress design).

Stress matrices, frameworks, affine targets, agent dynamics, the paper's
sampled-data laws, their stability analysis, and ``simulate``. Knows nothing of
PettingZoo, Gymnasium, pygame or torch.
"""

from .affine import (
    AffineImage,
    Maneuver,
    affine_targets,
    hold,
    rotate,
    rotation,
    scale,
    scaling,
    shear,
    shear_matrix,
    translate,
)
from .analysis import StabilityReport, extreme_eigenvalues, stability_report
from .design import condition_number, design_stress
from .dynamics import LinearDynamics, c2d_zoh, dare, dlqr, riccati_gain
from .errors import (
    ControlDimension,
    FormationError,
    FrameworkError,
    LawAssumptionWarning,
    ReachabilityWarning,
    StabilityWarning,
    StressMatrixError,
    UnknownNameError,
    UnstableParameterError,
)
from .framework import Framework
from .frameworks import paper_example, paper_omega
from .laws import LAWS, DynamicLeaderLaw, FollowerLaw, PaperLinearLaw, StressFeedbackLaw, make_law
from .network import Network
from .simulate import SimResult, simulate
from .stress import (
    Partition,
    check_stress,
    equilibrium_stress_basis,
    follower_targets,
    project_stress,
    stress_from_weights,
)

__all__ = [
    "LAWS",
    "AffineImage",
    "ControlDimension",
    "DynamicLeaderLaw",
    "FollowerLaw",
    "FormationError",
    "Framework",
    "FrameworkError",
    "LawAssumptionWarning",
    "LinearDynamics",
    "Maneuver",
    "Network",
    "PaperLinearLaw",
    "Partition",
    "ReachabilityWarning",
    "SimResult",
    "StabilityReport",
    "StabilityWarning",
    "StressFeedbackLaw",
    "StressMatrixError",
    "UnknownNameError",
    "UnstableParameterError",
    "affine_targets",
    "c2d_zoh",
    "check_stress",
    "condition_number",
    "dare",
    "design_stress",
    "dlqr",
    "equilibrium_stress_basis",
    "extreme_eigenvalues",
    "follower_targets",
    "hold",
    "make_law",
    "paper_example",
    "paper_omega",
    "project_stress",
    "riccati_gain",
    "rotate",
    "rotation",
    "scale",
    "scaling",
    "shear",
    "shear_matrix",
    "simulate",
    "stability_report",
    "stress_from_weights",
    "translate",
]
