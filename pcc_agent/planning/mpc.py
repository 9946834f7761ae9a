"""Receding-horizon control (MPC) with the latent iLQR planner.

At the first step of an episode a plan is computed from scratch (several candidate initial
plans, ``config.iterations`` iterations); every ``config.replan_every`` steps after that the
previous plan, shifted by the executed steps with its last action repeated, is refined for
``config.mpc_iterations`` iterations from the new latent state. Every step applies the
carried plan's next action.

The warm start is plain data (a tensor ``(B, T, nu)``), so a policy can carry it between
calls, e.g. in the ``state`` of Stable-Baselines3's ``predict``: use
:meth:`LatentMPC.plan_step` (functional), or :meth:`LatentMPC.act`, which keeps it inside
the object.
"""

from __future__ import annotations

import torch
from torch import Tensor

from pcc_agent.planning.config import PlannerConfig
from pcc_agent.planning.cost import QuadraticCost
from pcc_agent.planning.dynamics import LatentDynamics, as_dynamics
from pcc_agent.planning.ilqr import ILQRResult, plan


def shift_plan(u: Tensor) -> Tensor:
    """Drop the first action of plans ``(B, T, nu)`` and repeat the last one.

    Example:
        >>> shift_plan(torch.tensor([[[1.0], [2.0], [3.0]]])).flatten().tolist()
        [2.0, 3.0, 3.0]
    """
    return torch.cat([u[:, 1:], u[:, -1:]], dim=1)


class LatentMPC:
    """iLQR model predictive control in a learned latent space, batched over problems.

    Args:
        dynamics: Latent dynamics: a :class:`~pcc_agent.planning.dynamics.LatentDynamics`,
            a model with ``transition_mean`` and ``linearize``, or a function ``fn(z, u)``.
        cost: Quadratic cost; its goal is ``(nz,)`` or one per problem ``(B, nz)``.
        config: Planner settings.
        generator: Source of randomness for the initial plans; a generator seeded with
            ``seed`` is made when None.
        seed: Seed of the generator made when ``generator`` is None.

    Example:
        >>> import torch
        >>> from pcc_agent.planning import MLPDynamics, PlannerConfig, QuadraticCost
        >>> config = PlannerConfig(plan_length=5)
        >>> dynamics = MLPDynamics.random(2, 1, (16,), torch.Generator().manual_seed(0))
        >>> mpc = LatentMPC(dynamics, QuadraticCost.from_config(config, torch.zeros(2), 1), config)
        >>> mpc.act(torch.ones(2)).shape
        torch.Size([1])
    """

    def __init__(
        self,
        dynamics: LatentDynamics | object,
        cost: QuadraticCost,
        config: PlannerConfig,
        generator: torch.Generator | None = None,
        seed: int = 0,
    ) -> None:
        self.dynamics = as_dynamics(dynamics)
        self.cost = cost
        self.config = config
        self.generator = generator if generator is not None else torch.Generator()
        if generator is None:
            self.generator.manual_seed(seed)
        self.warm_start: Tensor | None = None
        self.last_result: ILQRResult | None = None
        #: Actions of the carried plan still to execute before the next replan.
        self.open_loop_left = 0

    def reset(self) -> None:
        """Forget the carried plan: the next call plans from scratch."""
        self.warm_start = None
        self.last_result = None
        self.open_loop_left = 0

    def set_goal(self, goal: Tensor) -> None:
        """Change the goal latent state ``(nz,)`` or ``(B, nz)`` (keeps the weights)."""
        self.cost = self.cost.with_goal(goal)

    def plan_step(
        self, z0: Tensor, warm_start: Tensor | None = None
    ) -> tuple[Tensor, Tensor]:
        """One MPC step, functional: the action to apply and the next step's warm start.

        Args:
            z0: Current latent state ``(nz,)`` or states of several problems ``(B, nz)``.
            warm_start: The warm start returned by the previous call (same batch layout as
                ``z0``), or None at the start of an episode.

        Returns:
            The first planned action ``(nu,)`` or ``(B, nu)``, and the plan shifted by one
            step ``(T, nu)`` or ``(B, T, nu)`` to pass as ``warm_start`` next time.
        """
        single = z0.dim() == 1
        z_batch = z0.unsqueeze(0) if single else z0
        warm = None
        if warm_start is not None:
            warm = warm_start.unsqueeze(0) if single else warm_start
            warm = warm.to(device=z_batch.device, dtype=z_batch.dtype)
        with torch.no_grad():
            result = plan(self.dynamics, self.cost, z_batch, self.config, self.generator, warm)
        self.last_result = result
        action, next_warm = result.u[:, 0], shift_plan(result.u)
        if single:
            return action[0], next_warm[0]
        return action, next_warm

    def act(self, z0: Tensor) -> Tensor:
        """One MPC step that keeps the plan in this object (call :meth:`reset` per episode).

        Plans (from scratch, or refining the carried plan) every ``config.replan_every``
        calls; in between, the carried plan's next action is applied and ``z0`` is unused.

        Args:
            z0: Current latent state ``(nz,)`` or states ``(B, nz)``.

        Returns:
            The action to apply, ``(nu,)`` or ``(B, nu)``.
        """
        if self.warm_start is not None and self.open_loop_left > 0:
            self.open_loop_left -= 1
            batched = self.warm_start.dim() == 3
            plans = self.warm_start if batched else self.warm_start[None]
            self.warm_start = shift_plan(plans) if batched else shift_plan(plans)[0]
            return plans[:, 0] if batched else plans[0, 0]
        action, self.warm_start = self.plan_step(z0, self.warm_start)
        self.open_loop_left = self.config.replan_every - 1
        return action
