"""Receding-horizon control (MPC) with the latent iLQR planner.

At the first step of an episode a plan is computed from scratch (several candidate initial
plans, ``config.iterations`` iterations); every ``config.replan_every`` steps after that the
previous plan, shifted by the executed steps with its last action repeated, is refined for
``config.mpc_iterations`` iterations from the new latent state. Every step applies the
carried plan's next action.

This logic lives in one place, :class:`LatentMPC`, used three ways:

* :meth:`LatentMPC.step`: functional and batched, with the carried plan as plain data in
  Stable-Baselines3's ``predict`` state (``PCCAgent.predict`` goes through it);
* :meth:`LatentMPC.act`: the same step, with the carried plan kept inside the object;
* :meth:`LatentMPC.plan_step`: one plan (from scratch or refined) per call, no open loop.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
import torch
from torch import Tensor

from pcc_agent.config import PlannerConfig
from pcc_agent.planning.cost import QuadraticCost
from pcc_agent.planning.dynamics import LatentDynamics, as_dynamics
from pcc_agent.planning.ilqr import ILQRResult, ilqr_solve, plan

#: The carried state of :meth:`LatentMPC.step`: the shifted plans ``(B, T, nu)`` when
#: ``replan_every == 1``, else the pair ``(plans, steps_left)``.
MPCState = Any


def shift_plan(u: Tensor) -> Tensor:
    """Drop the first action of plans ``(B, T, nu)`` and repeat the last one.

    Example:
        >>> shift_plan(torch.tensor([[[1.0], [2.0], [3.0]]])).flatten().tolist()
        [2.0, 3.0, 3.0]
    """
    return torch.cat([u[:, 1:], u[:, -1:]], dim=1)


class MPCStep(NamedTuple):
    """What one batched MPC step returns.

    Attributes:
        action: The actions to apply ``(B, nu)``: the first action of each plan.
        plans: The plans executed from this step ``(B, T, nu)``.
        warm_start: The plans shifted by one step, for the next step ``(B, T, nu)``.
        steps_left: Open-loop steps left before the next replan, per problem ``(B,)``.
    """

    action: Tensor
    plans: Tensor
    warm_start: Tensor
    steps_left: np.ndarray


def check_state(
    state: Any, n: int, config: PlannerConfig, action_dim: int, caller: str = "predict()"
) -> tuple[np.ndarray, np.ndarray]:
    """The warm start and the open-loop steps left from a carried MPC state; ValueError if not.

    With ``config.replan_every == 1`` the state is the plans array alone, float
    ``(n, plan_length, action_dim)``; with more it is the pair ``(plans, steps_left)``,
    ``steps_left`` one integer in ``[0, replan_every - 1]`` per problem. This is the only
    place the carried state is checked.

    Args:
        state: The state the previous step returned.
        n: Number of problems (observations) of this step.
        config: Planner settings (``plan_length``, ``replan_every``).
        action_dim: Action dimension.
        caller: Named in the error messages.

    Returns:
        The plans (float, unchanged dtype) and the steps left (int64).
    """
    replan_every = config.replan_every
    if replan_every == 1:
        plans, left = state, np.zeros(n, dtype=np.int64)
    else:
        if not (isinstance(state, tuple) and len(state) == 2):
            raise ValueError(
                f"{caller}: with replan_every={replan_every} the state is the pair (plans, "
                f"steps_left) that the previous {caller} call returned, or None at the start; "
                f"got {type(state).__name__}."
            )
        plans, left = state[0], np.asarray(state[1])
        if (left.shape != (n,) or not np.issubdtype(left.dtype, np.integer)
                or left.min(initial=0) < 0 or left.max(initial=0) >= replan_every):
            raise ValueError(
                f"{caller}: steps_left must be {n} integers in [0, {replan_every - 1}], got "
                f"{left.dtype} {left.shape}: pass back the state {caller} returned."
            )
    warm = np.asarray(plans.cpu() if isinstance(plans, Tensor) else plans)
    expected = (n, config.plan_length, action_dim)
    if not np.issubdtype(warm.dtype, np.floating):
        raise ValueError(
            f"{caller}: state must be a float array (got dtype {warm.dtype}): pass back the "
            f"state the previous {caller} call returned, or None at the start."
        )
    if warm.shape != expected:
        raise ValueError(
            f"{caller}: state has shape {warm.shape}; expected {expected} (n_envs, "
            f"plan_length, action_dim) for this observation batch: pass back the state the "
            f"previous {caller} call on the same envs returned, or None at the start."
        )
    if not np.all(np.isfinite(warm)):
        raise ValueError(f"{caller}: state has non-finite values (NaN or inf); pass None to "
                         "plan from scratch.")
    return warm, left.astype(np.int64)


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

    def step(
        self,
        z0: Tensor,
        state: MPCState | None = None,
        restart: np.ndarray | None = None,
        caller: str = "step()",
    ) -> tuple[Tensor, MPCState]:
        """One batched MPC step, functional: the actions and the state to pass back next time.

        Args:
            z0: Current latent states ``(B, nz)``.
            state: The state the previous call returned (checked by :func:`check_state`), or
                None at the start: the shifted plans ``(B, T, nu)``, or with
                ``replan_every > 1`` the pair ``(plans, steps_left)``.
            restart: Booleans ``(B,)``: True where an episode starts (its carried plan is
                dropped and it plans from scratch).
            caller: Named in the messages about a malformed ``state``.

        Returns:
            The actions ``(B, nu)`` (a tensor) and the next state (numpy arrays).

        Raises:
            ValueError: A malformed ``state`` (see :func:`check_state`).
        """
        n = z0.shape[0]
        warm, left = (None, None) if state is None else check_state(
            state, n, self.config, self.cost.action_dim, caller)
        result = self.advance(
            z0, None if warm is None else torch.as_tensor(warm, device=z0.device), left, restart)
        plans = result.warm_start.cpu().numpy()
        if self.config.replan_every == 1:
            return result.action, plans
        return result.action, (plans, result.steps_left)

    def advance(
        self,
        z0: Tensor,
        warm_start: Tensor | None = None,
        steps_left: np.ndarray | None = None,
        restart: np.ndarray | None = None,
    ) -> MPCStep:
        """One batched MPC step on checked tensors (what :meth:`step` and :meth:`act` run).

        A problem without a carried plan (or marked in ``restart``) plans from scratch; one
        with ``steps_left > 0`` applies its carried plan open loop; the others refine their
        carried plan from ``z0``. The planned problems start ``replan_every - 1`` open-loop
        steps; the open-loop ones count one down.

        Args:
            z0: Current latent states ``(B, nz)``.
            warm_start: Carried plans ``(B, T, nu)`` or None.
            steps_left: Open-loop steps left per problem ``(B,)`` (default 0: replan all).
            restart: Booleans ``(B,)``: plan these from scratch.

        Returns:
            The actions, the executed plans, their shifted copies and the steps left.
        """
        n = z0.shape[0]
        left = np.zeros(n, dtype=np.int64) if steps_left is None else np.asarray(steps_left)
        fresh = np.full(n, warm_start is None)
        if restart is not None:
            fresh |= np.asarray(restart, dtype=bool).reshape(-1)
        open_loop = ~fresh & (left > 0)
        refine = ~fresh & ~open_loop
        plans = torch.empty(n, self.config.plan_length, self.cost.action_dim, dtype=z0.dtype,
                            device=z0.device)
        with torch.no_grad():
            if fresh.any():
                idx = torch.as_tensor(np.flatnonzero(fresh), device=z0.device)
                result = plan(self.dynamics, self._cost_of(idx, n), z0[idx], self.config,
                              self.generator)
                plans[idx] = result.u.to(plans.dtype)
                self.last_result = result
            if refine.any():
                assert warm_start is not None
                idx = torch.as_tensor(np.flatnonzero(refine), device=z0.device)
                warm = warm_start[idx].to(device=z0.device, dtype=z0.dtype)
                result = ilqr_solve(self.dynamics, self._cost_of(idx, n), z0[idx], warm,
                                    self.config, self.config.mpc_iterations)
                plans[idx] = result.u.to(plans.dtype)
                self.last_result = result
            if open_loop.any():
                assert warm_start is not None
                idx = torch.as_tensor(np.flatnonzero(open_loop), device=z0.device)
                plans[idx] = warm_start[idx].to(plans.dtype)
        next_left = np.where(open_loop, left - 1, self.config.replan_every - 1).astype(np.int64)
        return MPCStep(plans[:, 0], plans, shift_plan(plans), next_left)

    def _cost_of(self, idx: Tensor, n: int) -> QuadraticCost:
        """The cost of the problems ``idx`` of a batch of ``n`` (one goal each, or shared)."""
        goal = self.cost.goal
        if goal.dim() == 2 and goal.shape[0] > 1 and len(idx) != n:
            return self.cost.with_goal(goal[idx.to(goal.device)])
        return self.cost

    def act(self, z0: Tensor) -> Tensor:
        """One MPC step that keeps the plan in this object (call :meth:`reset` per episode).

        Plans (from scratch, or refining the carried plan) every ``config.replan_every``
        calls; in between, the carried plan's next action is applied and ``z0`` is unused.
        The same step as :meth:`step`, with its state kept in ``warm_start`` and
        ``open_loop_left``.

        Args:
            z0: Current latent state ``(nz,)`` or states ``(B, nz)``.

        Returns:
            The action to apply, ``(nu,)`` or ``(B, nu)``.
        """
        single = z0.dim() == 1
        z = z0[None] if single else z0
        warm = self.warm_start
        if warm is not None and single:
            warm = warm[None]
        result = self.advance(z, warm, np.full(z.shape[0], self.open_loop_left))
        self.warm_start = result.warm_start[0] if single else result.warm_start
        self.open_loop_left = int(result.steps_left[0])
        return result.action[0] if single else result.action
