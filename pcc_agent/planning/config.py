"""Typed configuration of the latent-space iLQR planner and its MPC wrapper.

`PlannerConfig` is plain data: per-environment values live in `pcc_agent.presets`, and the
command-line tools build one from their arguments; the planner never sees an argparse
namespace.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class PlannerConfig:
    """Settings of the latent iLQR solver and of receding-horizon (MPC) planning.

    The cost is ``sum_t (z_t - g)^T Q (z_t - g) + u_t^T R u_t + (z_T - g)^T Q_T (z_T - g)``
    with ``Q = kappa * I``, ``R = r_weight * I`` and ``Q_T = terminal_weight * kappa * I``.

    Attributes:
        plan_length: Planning horizon T (number of actions in a plan).
        kappa: State cost weight: ``Q = kappa * I``.
        r_weight: Action cost weight: ``R = r_weight * I``.
        terminal_weight: Multiplier of ``Q`` for the terminal cost: ``Q_T = terminal_weight * Q``.
        iterations: iLQR iterations for a plan computed from scratch (first MPC step).
        mpc_iterations: iLQR iterations per MPC step after a warm start.
        replan_every: Actions executed from one plan before the MPC plans again (1: replan
            at every step). Between replans the carried plan's next action is applied open
            loop; a longer horizon costs less per step when it is replanned less often.
        num_candidates: Initial plans optimized together as a batch when planning from scratch;
            the first ``num_extreme`` are extreme plans and the rest are uniform random in the
            action box (when ``num_candidates <= num_extreme``, all are uniform). The plan with
            the lowest final cost is kept.
        num_extreme: How many of the candidates are extreme plans: the constant plans at
            ``action_low`` and at ``action_high``, then random bang-bang plans (every action
            component drawn from ``{action_low, action_high}``).
        line_search_steps: Step sizes alpha tried, all in one batched rollout, by the forward
            pass; the best one that decreases the cost is accepted.
        mu_init: Initial Levenberg-Marquardt regularization added to ``Q_uu``.
        mu_min: Lower bound of the regularization (below it, mu is set to 0).
        mu_max: Upper bound of the regularization; a problem whose mu would exceed it stops
            with status ``no_improvement``.
        mu_factor: Multiplicative increase (on failure) and decrease (on success) of mu.
        action_low: Lower bound of every action dimension (the envs' normalized range).
        action_high: Upper bound of every action dimension.
        tolerance: Convergence threshold on the relative cost decrease of an accepted step.
    """

    plan_length: int = 10
    kappa: float = 1.0
    r_weight: float = 1.0
    terminal_weight: float = 1.0
    iterations: int = 4
    mpc_iterations: int = 2
    replan_every: int = 1
    num_candidates: int = 6
    num_extreme: int = 2
    line_search_steps: tuple[float, ...] = (1.0, 0.5, 0.25, 0.1, 0.03)
    mu_init: float = 1e-6
    mu_min: float = 1e-6
    mu_max: float = 1e10
    mu_factor: float = 10.0
    action_low: float = -1.0
    action_high: float = 1.0
    tolerance: float = 1e-6

    def __post_init__(self) -> None:
        """Validate the values, with messages that say how to fix them."""
        if self.plan_length < 1:
            raise ValueError(f"plan_length must be >= 1, got {self.plan_length}.")
        if self.iterations < 1 or self.mpc_iterations < 1:
            raise ValueError(
                "iterations and mpc_iterations must be >= 1, got "
                f"{self.iterations} and {self.mpc_iterations}."
            )
        if self.num_candidates < 1:
            raise ValueError(f"num_candidates must be >= 1, got {self.num_candidates}.")
        if self.num_extreme < 0:
            raise ValueError(f"num_extreme must be >= 0, got {self.num_extreme}.")
        if not 1 <= self.replan_every <= self.plan_length:
            raise ValueError(
                f"replan_every must be between 1 and plan_length ({self.plan_length}), got "
                f"{self.replan_every}: a plan cannot be executed for longer than it lasts."
            )
        if not self.line_search_steps or any(a <= 0 for a in self.line_search_steps):
            raise ValueError(
                f"line_search_steps must be non-empty and positive, got {self.line_search_steps}."
            )
        if not self.action_low < self.action_high:
            raise ValueError(
                f"action_low ({self.action_low}) must be below action_high ({self.action_high})."
            )
        if self.kappa < 0 or self.r_weight < 0 or self.terminal_weight < 0:
            raise ValueError("kappa, r_weight and terminal_weight must be non-negative.")
        if self.mu_factor <= 1.0:
            raise ValueError(f"mu_factor must be > 1, got {self.mu_factor}.")
