"""Quadratic tracking cost of the latent planning problem.

Notation (shared with :mod:`pcc_agent.planning.ilqr`): batch ``B``, horizon ``T``, latent
dimension ``nz``, action dimension ``nu``; states ``z`` with shape ``(B, T + 1, nz)`` and
actions ``u`` with shape ``(B, T, nu)``. The cost of a trajectory is

    J = sum_{t<T} (z_t - g)^T Q (z_t - g) + u_t^T R u_t  +  (z_T - g)^T Q_T (z_T - g),

as in the paper's latent control problem (Q = kappa * I). It is exactly quadratic, so its
derivatives are exact: ``l_z = 2 Q (z - g)``, ``l_u = 2 R u``, ``l_zz = 2 Q``, ``l_uu = 2 R``,
``l_uz = 0`` and, at the end, ``2 Q_T (z_T - g)`` and ``2 Q_T``.
"""

from __future__ import annotations

from typing import NamedTuple

import torch
from torch import Tensor

from pcc_agent.config import PlannerConfig


class CostDerivatives(NamedTuple):
    """First and second derivatives of a quadratic cost along a trajectory.

    Attributes:
        l_z: State gradients ``(B, T + 1, nz)``; the last row is the terminal gradient.
        l_u: Action gradients ``(B, T, nu)``.
        l_zz: Stage state Hessian ``(nz, nz)`` (the same at every step).
        l_uu: Action Hessian ``(nu, nu)``.
        l_zz_terminal: Terminal state Hessian ``(nz, nz)``.
    """

    l_z: Tensor
    l_u: Tensor
    l_zz: Tensor
    l_uu: Tensor
    l_zz_terminal: Tensor


class QuadraticCost:
    """Quadratic cost ``(z - g)^T Q (z - g) + u^T R u`` with terminal ``(z_T - g)^T Q_T (z_T - g)``.

    Args:
        Q: Stage state weight, symmetric positive semi-definite ``(nz, nz)``.
        R: Action weight, symmetric positive semi-definite ``(nu, nu)``.
        Q_terminal: Terminal state weight ``(nz, nz)``.
        goal: Goal latent state ``(nz,)``, or one goal per problem ``(B, nz)``.

    Example:
        >>> import torch
        >>> cost = QuadraticCost(torch.eye(2), torch.eye(1), torch.eye(2), torch.zeros(2))
        >>> z, u = torch.ones(1, 3, 2), torch.zeros(1, 2, 1)
        >>> cost.trajectory_cost(z, u)
        tensor([6.])
    """

    def __init__(self, Q: Tensor, R: Tensor, Q_terminal: Tensor, goal: Tensor) -> None:
        nz, nu = Q.shape[-1], R.shape[-1]
        if Q.shape != (nz, nz) or Q_terminal.shape != (nz, nz) or R.shape != (nu, nu):
            raise ValueError(
                f"Q and Q_terminal must be (nz, nz) and R (nu, nu); got {tuple(Q.shape)}, "
                f"{tuple(Q_terminal.shape)} and {tuple(R.shape)}."
            )
        if goal.shape[-1] != nz or goal.dim() not in (1, 2):
            raise ValueError(
                f"goal must be (nz,) or (B, nz) with nz={nz}, got {tuple(goal.shape)}."
            )
        self.Q = Q
        self.R = R
        self.Q_terminal = Q_terminal
        self.goal = goal

    @classmethod
    def from_config(cls, config: PlannerConfig, goal: Tensor, action_dim: int) -> QuadraticCost:
        """Build the paper's cost ``Q = kappa I``, ``R = r_weight I``, ``Q_T = terminal_weight Q``.

        Args:
            config: Planner settings (``kappa``, ``r_weight``, ``terminal_weight``).
            goal: Goal latent state ``(nz,)`` or ``(B, nz)``.
            action_dim: Action dimension ``nu``.

        Returns:
            The cost, with weights of the goal's dtype and device.
        """
        nz = goal.shape[-1]
        eye_z = torch.eye(nz, dtype=goal.dtype, device=goal.device)
        eye_u = torch.eye(action_dim, dtype=goal.dtype, device=goal.device)
        Q = config.kappa * eye_z
        return cls(Q, config.r_weight * eye_u, config.terminal_weight * Q, goal)

    @property
    def state_dim(self) -> int:
        """Latent dimension ``nz``."""
        return self.Q.shape[-1]

    @property
    def action_dim(self) -> int:
        """Action dimension ``nu``."""
        return self.R.shape[-1]

    def with_goal(self, goal: Tensor) -> QuadraticCost:
        """Return the same weights with another goal ``(nz,)`` or ``(B, nz)``."""
        return QuadraticCost(self.Q, self.R, self.Q_terminal, goal)

    def _goal_for(self, z: Tensor) -> Tensor:
        """Goal broadcastable against ``z`` of shape ``(B, ..., nz)``."""
        goal = self.goal.to(dtype=z.dtype, device=z.device)
        if goal.dim() == 2:
            if goal.shape[0] != z.shape[0] and goal.shape[0] != 1:
                raise ValueError(
                    f"The cost has {goal.shape[0]} goals but the batch has {z.shape[0]} "
                    "problems; pass one goal, or one per problem."
                )
            goal = goal.reshape(goal.shape[0], *([1] * (z.dim() - 2)), goal.shape[-1])
        return goal

    def trajectory_cost(self, z: Tensor, u: Tensor) -> Tensor:
        """Total cost of trajectories.

        Args:
            z: States ``(B, T + 1, nz)``.
            u: Actions ``(B, T, nu)``.

        Returns:
            Costs ``(B,)`` in the dtype of ``z``.
        """
        e = z - self._goal_for(z)
        e_stage, e_final = e[:, :-1], e[:, -1]
        stage = ((e_stage @ self.Q.to(e)) * e_stage).sum((1, 2))
        terminal = ((e_final @ self.Q_terminal.to(e)) * e_final).sum(1)
        action = ((u @ self.R.to(u)) * u).sum((1, 2)).to(e.dtype)
        return stage + terminal + action

    def derivatives(self, z: Tensor, u: Tensor) -> CostDerivatives:
        """Exact derivatives of the cost along trajectories.

        Args:
            z: States ``(B, T + 1, nz)``.
            u: Actions ``(B, T, nu)``.

        Returns:
            The gradients along the trajectory and the constant Hessians, in ``z``'s dtype.
        """
        e = z - self._goal_for(z)
        Q, Q_T, R = self.Q.to(e), self.Q_terminal.to(e), self.R.to(e)
        l_z = torch.cat([2.0 * e[:, :-1] @ Q, (2.0 * e[:, -1:] @ Q_T)], dim=1)
        l_u = 2.0 * u.to(e.dtype) @ R
        return CostDerivatives(l_z, l_u, 2.0 * Q, 2.0 * R, 2.0 * Q_T)
