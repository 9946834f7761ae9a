"""Latent-space planning: quadratic cost, batched box-constrained iLQR and MPC (pure torch)."""

from pcc_agent.planning.config import PlannerConfig

__all__ = ["PlannerConfig"]
