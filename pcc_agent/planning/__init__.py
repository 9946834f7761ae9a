"""Latent-space planning: quadratic cost, batched box-constrained iLQR and MPC (pure torch).

Nothing here knows about images or environments: the planner works on latent states ``z``,
actions ``u`` in a box, a :class:`LatentDynamics` and a :class:`QuadraticCost`.
"""

from pcc_agent.planning.config import PlannerConfig
from pcc_agent.planning.cost import CostDerivatives, QuadraticCost
from pcc_agent.planning.dynamics import (
    FunctionDynamics,
    LatentDynamics,
    MLPDynamics,
    ModelDynamics,
    as_dynamics,
)
from pcc_agent.planning.ilqr import ILQRResult, Status, ilqr_solve, plan
from pcc_agent.planning.mpc import LatentMPC, shift_plan

__all__ = [
    "CostDerivatives",
    "FunctionDynamics",
    "ILQRResult",
    "LatentDynamics",
    "LatentMPC",
    "MLPDynamics",
    "ModelDynamics",
    "PlannerConfig",
    "QuadraticCost",
    "Status",
    "as_dynamics",
    "ilqr_solve",
    "plan",
    "shift_plan",
]
