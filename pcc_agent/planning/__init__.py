"""Latent-space planning: quadratic cost, batched box-constrained iLQR and MPC.

Nothing here knows about images or environments: the planner works on latent states ``z``,
actions ``u`` in a box, a :class:`LatentDynamics` and a :class:`QuadraticCost`.
"""

from pcc_agent.config import PlannerConfig
from pcc_agent.planning.cost import CostDerivatives, QuadraticCost
from pcc_agent.planning.dynamics import (
    FunctionDynamics,
    LatentDynamics,
    MLPDynamics,
    ModelDynamics,
    as_dynamics,
)
from pcc_agent.planning.ilqr import ILQRResult, Status, ilqr_solve, plan
from pcc_agent.planning.mpc import LatentMPC, MPCStep, check_state, shift_plan

#: Revision of the planner's numerics, written beside every benchmark evaluation. Bump it
#: whenever a change can alter the actions planned for the same model and settings (closed-loop
#: outcomes near obstacles can flip on small differences), so that the reproduction pipeline
#: re-evaluates records of an older planner from their saved agents. 1: torch float32 loops;
#: 2: compiled float64 loops (re-evaluating the Planar records gave the same per-task results);
#: 3: per-domain planner settings chosen with the oracle (horizons, 3 uniform + 3 extreme
#: initial plans), an oracle that runs the agents' settings, ``replan_every``. Summaries keep
#: older records in rows labelled ``[planner rN]``.
PLANNER_REVISION = 3

__all__ = [
    "CostDerivatives",
    "FunctionDynamics",
    "ILQRResult",
    "LatentDynamics",
    "LatentMPC",
    "MLPDynamics",
    "MPCStep",
    "PLANNER_REVISION",
    "ModelDynamics",
    "PlannerConfig",
    "QuadraticCost",
    "Status",
    "as_dynamics",
    "check_state",
    "ilqr_solve",
    "plan",
    "shift_plan",
]
