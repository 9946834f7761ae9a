"""Batched, control-limited iLQR in the latent space.

Notation and shapes (as in the paper's appendix "The Latent Space iLQR Algorithm"):

* ``B``: number of independent problems solved together (initial-plan candidates, several
  environments, or both); ``T``: horizon (number of actions); ``nz``: latent dimension;
  ``nu``: action dimension; ``nx = nz + nu``.
* ``z``: latent states ``(B, T + 1, nz)``, ``z[:, 0] = z0``; ``u``: actions ``(B, T, nu)``,
  every entry inside the box ``[action_low, action_high]``.
* Dynamics ``z_{t+1} = f(z_t, u_t)`` (:class:`~pcc_agent.planning.dynamics.LatentDynamics`),
  linearized along the nominal trajectory: ``A_t = df/dz`` ``(B, T, nz, nz)``,
  ``B_t = df/du`` ``(B, T, nz, nu)``.
* Cost ``J = sum_t c(z_t, u_t) + c_T(z_T)``
  (:class:`~pcc_agent.planning.cost.QuadraticCost`) with derivatives ``l_z, l_u, l_zz, l_uu``.
* Backward pass (Gauss-Newton: second derivatives of ``f`` are dropped), with value
  function derivatives ``V_z, V_zz`` starting from the terminal cost::

      Q_z  = l_z  + A^T V_z          Q_u  = l_u  + B^T V_z
      Q_zz = l_zz + A^T V_zz A       Q_uz = B^T V_zz A       Q_uu = l_uu + B^T V_zz B

  The action deviation solves the box-constrained quadratic program
  ``min_du 1/2 du^T (Q_uu + mu I) du + Q_u^T du`` subject to ``u_low <= u + du <= u_high``
  (Tassa, Mansard & Todorov 2014, "Control-limited differential dynamic programming"):
  ``k`` is its solution and the feedback gain ``K = -(Q_uu + mu I)_ff^{-1} Q_uz,f`` acts on
  the free (not clamped) action dimensions only; clamped rows of ``K`` are zero. ``mu`` is
  the Levenberg-Marquardt regularization, one per problem. Then::

      V_z  = Q_z  + K^T Q_uu k + K^T Q_u + Q_uz^T k
      V_zz = Q_zz + K^T Q_uu K + K^T Q_uz + Q_uz^T K

  This pass runs in float64 as compiled loops (:mod:`pcc_agent.planning.kernels`).
* Forward pass: for every step size ``alpha`` of ``config.line_search_steps`` at once (one
  batched rollout of ``B * n_alpha`` trajectories),
  ``u_t = clip(u_bar_t + alpha k_t + K_t (z_t - z_bar_t))``; each problem keeps the step with
  the lowest cost if it is lower than the current cost. Non-finite rollouts are rejected.

Regularization: ``mu`` grows by ``mu_factor`` (at least to ``mu_min``) when ``Q_uu + mu I``
is not positive definite or no step size decreases the cost, and shrinks by ``mu_factor``
(to 0 below ``mu_min``) after an accepted step. A problem stops as ``CONVERGED`` when the
predicted or the achieved decrease is below ``tolerance`` times its cost, and as
``NO_IMPROVEMENT`` when ``mu`` exceeds ``mu_max``.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor

from pcc_agent.config import PlannerConfig
from pcc_agent.planning.cost import QuadraticCost
from pcc_agent.planning.dynamics import LatentDynamics
from pcc_agent.planning.kernels import PackedMLP, closed_loop_rollout, riccati


class Status(enum.IntEnum):
    """Why a problem's iterations stopped (``ILQRResult.status`` holds these values)."""

    CONVERGED = 0
    MAX_ITERATIONS = 1
    NO_IMPROVEMENT = 2
    NON_FINITE = 3


@dataclass
class ILQRResult:
    """Solution of a batch of latent planning problems.

    ``u`` is always finite and inside the action box. ``cost`` is ``+inf`` (never NaN) and
    ``z`` may hold non-finite values only for problems whose status is ``NON_FINITE`` (the
    dynamics diverged along the initial plan and no finite improvement was found).

    Attributes:
        u: Planned actions ``(B, T, nu)``.
        z: Predicted latent states ``(B, T + 1, nz)``.
        cost: Cost of each plan ``(B,)`` (float64).
        iterations: Backward passes made for each problem ``(B,)`` (int64).
        status: :class:`Status` value of each problem ``(B,)`` (int64).
    """

    u: Tensor
    z: Tensor
    cost: Tensor
    iterations: Tensor
    status: Tensor


@dataclass
class BackwardPassResult:
    """Output of :func:`backward_pass` (numpy float64 arrays).

    Attributes:
        k: Feed-forward action deviations ``(B, T, nu)``; ``u + k`` is inside the box.
        K: Feedback gains ``(B, T, nu, nz)``, zero on clamped action dimensions.
        expected_decrease: Predicted cost decrease of the full step ``(B,)``:
            ``-sum_t (k^T Q_u + 1/2 k^T Q_uu k)``.
        ok: Whether ``Q_uu + mu I`` was positive definite at every step ``(B,)``.
    """

    k: np.ndarray
    K: np.ndarray
    expected_decrease: np.ndarray
    ok: np.ndarray


def rollout(dynamics: LatentDynamics, z0: Tensor, u: Tensor) -> Tensor:
    """Open-loop states of action sequences.

    Args:
        dynamics: Latent dynamics.
        z0: Initial states ``(B, nz)``.
        u: Actions ``(B, T, nu)``.

    Returns:
        States ``(B, T + 1, nz)``, starting with ``z0``.
    """
    mlp = _compiled_mlp(dynamics, z0)
    if mlp is not None:
        n_b, horizon, nu = u.shape
        no_feedback = np.zeros((n_b, horizon, nu, z0.shape[-1]))
        states, _ = closed_loop_rollout(mlp, _to_numpy(z0), _to_numpy(u), no_feedback,
                                        -np.inf, np.inf)
        return torch.from_numpy(states).to(z0)
    states = [z0]
    for u_t in u.unbind(1):
        states.append(dynamics.step(states[-1], u_t))
    return torch.stack(states, 1)


def _compiled_mlp(dynamics: LatentDynamics, z: Tensor) -> PackedMLP | None:
    """The dynamics' ``packed_mlp`` for the compiled loops, or None for the torch loops.

    The compiled loops run in float64 on the CPU and carry no autograd graph: they are used
    when the dynamics offer them, ``z`` is on the CPU and no gradient is being recorded
    through ``z`` (results then match the torch loops to float64 rounding, or to ~1e-7 for
    float32 inputs).
    """
    if z.device.type != "cpu" or (z.requires_grad and torch.is_grad_enabled()):
        return None
    return getattr(dynamics, "packed_mlp", None)


def linearize(dynamics: LatentDynamics, z: Tensor, u: Tensor) -> tuple[Tensor, Tensor]:
    """Jacobians along trajectories, in one batched call of ``dynamics.jacobians``.

    Args:
        dynamics: Latent dynamics.
        z: States ``(B, T + 1, nz)`` (the last one is not used).
        u: Actions ``(B, T, nu)``.

    Returns:
        ``A`` ``(B, T, nz, nz)`` and ``B`` ``(B, T, nz, nu)``.
    """
    n_b, horizon, nu = u.shape
    nz = z.shape[-1]
    A, B = dynamics.jacobians(z[:, :-1].reshape(-1, nz), u.reshape(-1, nu))
    return A.reshape(n_b, horizon, nz, nz), B.reshape(n_b, horizon, nz, nu)


def backward_pass(
    A: np.ndarray,
    B: np.ndarray,
    l_z: np.ndarray,
    l_u: np.ndarray,
    l_zz: np.ndarray,
    l_uu: np.ndarray,
    l_zz_terminal: np.ndarray,
    u: np.ndarray,
    mu: np.ndarray,
    action_low: float,
    action_high: float,
) -> BackwardPassResult:
    """Control-limited Riccati recursion of iLQR (see the module docstring), in float64.

    Runs as compiled loops (:func:`pcc_agent.planning.kernels.riccati`): per step the
    recursion is a few hundred scalar operations, which as batched numpy calls cost ~50 us of
    call overhead per step. Non-finite gains (overflowing Jacobians) mark the problem failed.

    Args:
        A: State Jacobians ``(B, T, nz, nz)``.
        B: Action Jacobians ``(B, T, nz, nu)``.
        l_z: Cost state gradients ``(B, T + 1, nz)``.
        l_u: Cost action gradients ``(B, T, nu)``.
        l_zz: Stage cost state Hessian ``(nz, nz)``.
        l_uu: Cost action Hessian ``(nu, nu)``.
        l_zz_terminal: Terminal cost Hessian ``(nz, nz)``.
        u: Nominal actions ``(B, T, nu)`` (inside the box).
        mu: Levenberg-Marquardt regularization ``(B,)``.
        action_low: Lower action bound.
        action_high: Upper action bound.

    Returns:
        Gains, predicted decrease, and which problems had a positive definite ``Q_uu + mu I``
        everywhere. Gains of problems that did not are meaningless (but finite).
    """
    k, K, decrease, ok = riccati(
        A, B, l_z, l_u, l_zz, l_uu, l_zz_terminal, action_low - u, action_high - u, mu)
    finite = np.isfinite(k).all((1, 2)) & np.isfinite(K).all((1, 2, 3)) & np.isfinite(decrease)
    ok &= finite
    k[~finite] = 0.0
    K[~finite] = 0.0
    decrease[~finite] = 0.0
    return BackwardPassResult(k, K, decrease, ok)


def line_search(
    dynamics: LatentDynamics,
    cost: QuadraticCost,
    z: Tensor,
    u: Tensor,
    k: Tensor,
    K: Tensor,
    alphas: Tensor,
    action_low: float,
    action_high: float,
) -> tuple[Tensor, Tensor, Tensor]:
    """Closed-loop forward pass for every step size at once; the best one per problem.

    Args:
        dynamics: Latent dynamics.
        cost: Cost of the problems (one goal, or one per problem).
        z: Nominal states ``(B, T + 1, nz)``.
        u: Nominal actions ``(B, T, nu)``.
        k: Feed-forward deviations ``(B, T, nu)`` (dtype of ``z``).
        K: Feedback gains ``(B, T, nu, nz)`` (dtype of ``z``).
        alphas: Step sizes ``(n_alpha,)``.
        action_low: Lower action bound.
        action_high: Upper action bound.

    Returns:
        For each problem, the states ``(B, T + 1, nz)``, actions ``(B, T, nu)`` and cost
        ``(B,)`` (float64; ``+inf`` when every step size diverged) of its best step size.
    """
    n_b, horizon, nu = u.shape
    nz = z.shape[-1]
    n_a = alphas.shape[0]
    n = n_b * n_a
    # u_t = u_bar_t + alpha k_t + K_t (z_t - z_bar_t) = c_t + K_t z_t, c_t precomputed.
    z_bar = torch.nan_to_num(z[:, :-1], nan=0.0, posinf=0.0, neginf=0.0)
    c = u - (K @ z_bar.unsqueeze(-1)).squeeze(-1)  # (B, T, nu)
    c = (c.unsqueeze(1) + alphas.view(1, n_a, 1, 1) * k.unsqueeze(1)).reshape(n, horizon, nu, 1)
    K_all = K.unsqueeze(1).expand(n_b, n_a, horizon, nu, nz).reshape(n, horizon, nu, nz)
    z_t = z[:, 0].repeat_interleave(n_a, 0)
    mlp = _compiled_mlp(dynamics, z)
    if mlp is not None:
        z_new, u_new = closed_loop_rollout(mlp, _to_numpy(z_t), _to_numpy(c[..., 0]),
                                           _to_numpy(K_all), action_low, action_high)
        z_new, u_new = torch.from_numpy(z_new).to(z), torch.from_numpy(u_new).to(z)
    else:
        states, actions = [z_t], []
        for c_t, K_t in zip(c.unbind(1), K_all.unbind(1)):
            u_t = torch.baddbmm(c_t, K_t, z_t.unsqueeze(-1)).squeeze_(-1)
            u_t = u_t.clamp_(action_low, action_high)
            z_t = dynamics.step(z_t, u_t)
            states.append(z_t)
            actions.append(u_t)
        z_new = torch.stack(states, 1)
        u_new = torch.stack(actions, 1)
    costs = _finite_cost(cost, z_new, u_new, repeats=n_a).view(n_b, n_a)
    best_cost, best = costs.min(1)
    index = torch.arange(n_b, device=z.device) * n_a + best.to(z.device)
    return z_new[index], u_new[index], best_cost


def _finite_cost(cost: QuadraticCost, z: Tensor, u: Tensor, repeats: int = 1) -> Tensor:
    """Float64 trajectory costs with NaN and overflow mapped to ``+inf``.

    ``repeats`` expands per-problem goals when each problem appears ``repeats`` times in a row.
    """
    if repeats > 1 and cost.goal.dim() == 2 and cost.goal.shape[0] > 1:
        cost = cost.with_goal(cost.goal.repeat_interleave(repeats, 0))
    value = cost.trajectory_cost(z.double(), u.double())
    return torch.where(torch.isfinite(value), value, torch.full_like(value, float("inf")))


def _to_numpy(x: Tensor) -> np.ndarray:
    """Float64 numpy copy (or view) of a tensor."""
    return x.detach().to(device="cpu", dtype=torch.float64).numpy()


def ilqr_solve(
    dynamics: LatentDynamics,
    cost: QuadraticCost,
    z0: Tensor,
    u_init: Tensor,
    config: PlannerConfig,
    iterations: int | None = None,
) -> ILQRResult:
    """Improve a batch of action sequences with control-limited iLQR.

    Never raises on numerical trouble: problems whose regularization runs out or whose
    dynamics diverge are reported in ``status`` (see :class:`Status`).

    Args:
        dynamics: Latent dynamics (see :func:`~pcc_agent.planning.dynamics.as_dynamics`).
        cost: Quadratic cost, with one goal or one goal per problem.
        z0: Initial states ``(B, nz)``.
        u_init: Initial action sequences ``(B, T, nu)``; they are clipped to the box.
        config: Solver settings (bounds, regularization, line search, tolerance).
        iterations: Maximum iterations; ``config.iterations`` when None.

    Returns:
        The improved plans.
    """
    max_iterations = config.iterations if iterations is None else iterations
    low, high = config.action_low, config.action_high
    with torch.no_grad():
        u = u_init.to(z0.dtype).clamp(low, high)
        n_b = u.shape[0]
        z = rollout(dynamics, z0, u)
        J = _finite_cost(cost, z, u)
        alphas = torch.tensor(config.line_search_steps, dtype=z0.dtype, device=z0.device)
        mu = np.full(n_b, config.mu_init, dtype=np.float64)
        status = np.full(n_b, int(Status.MAX_ITERATIONS))
        active = np.ones(n_b, dtype=bool)
        count = np.zeros(n_b, dtype=np.int64)
        for _ in range(max_iterations):
            if not active.any():
                break
            A, B = linearize(dynamics, z, u)
            derivatives = cost.derivatives(z.double(), u.double())
            A_np, B_np = _to_numpy(A), _to_numpy(B)
            l_z, l_u = _to_numpy(derivatives.l_z), _to_numpy(derivatives.l_u)
            finite_nominal = np.isfinite(_to_numpy(J))
            bad = ~(finite_nominal & np.isfinite(A_np).all((1, 2, 3))
                    & np.isfinite(B_np).all((1, 2, 3)) & np.isfinite(l_z).all((1, 2)))
            if bad.any():
                # Diverged nominal: step towards lower action cost only (zero gains), which
                # can bring the plan back to where the dynamics are finite.
                A_np[bad], B_np[bad], l_z[bad] = 0.0, 0.0, 0.0
                # Finite plan with non-finite Jacobians: nothing trustworthy to improve with.
                broken = bad & finite_nominal & active
                status[broken] = int(Status.NO_IMPROVEMENT)
                active &= ~broken
            u_np = _to_numpy(u)
            while True:
                result = backward_pass(
                    A_np, B_np, l_z, l_u, _to_numpy(derivatives.l_zz),
                    _to_numpy(derivatives.l_uu), _to_numpy(derivatives.l_zz_terminal),
                    u_np, mu, low, high,
                )
                failed = active & ~result.ok
                if not failed.any():
                    break
                mu[failed] = np.maximum(mu[failed] * config.mu_factor, config.mu_min)
                exhausted = failed & (mu > config.mu_max)
                status[exhausted] = int(Status.NO_IMPROVEMENT)
                active &= ~exhausted
            count += active
            J_np = _to_numpy(J)
            predicted_small = (
                active & finite_nominal
                & (result.expected_decrease <= config.tolerance * np.abs(J_np))
            )
            k = torch.from_numpy(result.k).to(z)
            K = torch.from_numpy(result.K).to(z)
            z_new, u_new, J_new = line_search(dynamics, cost, z, u, k, K, alphas, low, high)
            J_new_np = _to_numpy(J_new)
            accept = active & ~predicted_small & (J_new_np < J_np)
            with np.errstate(invalid="ignore"):  # inf - inf when recovering from divergence
                small_step = J_np - J_new_np <= config.tolerance * np.abs(J_np)
            achieved_small = accept & np.isfinite(J_np) & small_step
            accept_t = torch.from_numpy(accept).to(z.device)
            z = torch.where(accept_t[:, None, None], z_new, z)
            u = torch.where(accept_t[:, None, None], u_new, u)
            J = torch.where(accept_t, J_new, J)
            rejected = active & ~predicted_small & ~accept
            mu[accept] = mu[accept] / config.mu_factor
            mu[accept & (mu < config.mu_min)] = 0.0
            mu[rejected] = np.maximum(mu[rejected] * config.mu_factor, config.mu_min)
            exhausted = rejected & (mu > config.mu_max)
            converged = predicted_small | achieved_small
            status[converged] = int(Status.CONVERGED)
            status[exhausted] = int(Status.NO_IMPROVEMENT)
            active &= ~(converged | exhausted)
        status[~np.isfinite(_to_numpy(J))] = int(Status.NON_FINITE)
    return ILQRResult(
        u=u,
        z=z,
        cost=J,
        iterations=torch.from_numpy(count),
        status=torch.from_numpy(status.astype(np.int64)),
    )


def initial_plans(
    num_problems: int,
    config: PlannerConfig,
    action_dim: int,
    generator: torch.Generator,
    dtype: torch.dtype = torch.float32,
) -> Tensor:
    """Candidate initial plans: extreme plans and uniform random sequences.

    With ``C = config.num_candidates`` greater than ``E = config.num_extreme``, the first
    ``E`` candidates of each problem are extreme: the constant plans at ``action_low`` and at
    ``action_high``, then random bang-bang plans (every component ``action_low`` or
    ``action_high``); the other ``C - E`` are uniform in the box. With ``C <= E`` all are
    uniform, so at least one candidate explores the inside of the box.

    Args:
        num_problems: Number of problems ``B``.
        config: Planner settings (``num_candidates``, ``num_extreme``, ``plan_length``,
            bounds).
        action_dim: Action dimension ``nu``.
        generator: Source of randomness (a CPU generator).
        dtype: Dtype of the plans.

    Returns:
        Plans ``(B, C, T, nu)``.
    """
    low, high = config.action_low, config.action_high
    shape = (num_problems, config.num_candidates, config.plan_length, action_dim)
    plans = low + (high - low) * torch.rand(shape, generator=generator, dtype=dtype)
    n_extreme = config.num_extreme if config.num_candidates > config.num_extreme else 0
    if n_extreme >= 1:
        plans[:, 0] = low
    if n_extreme >= 2:
        plans[:, 1] = high
    if n_extreme >= 3:
        bang = torch.rand((num_problems, n_extreme - 2, *shape[2:]), generator=generator)
        plans[:, 2:n_extreme] = torch.where(bang < 0.5, low, high).to(dtype)
    return plans


def plan(
    dynamics: LatentDynamics,
    cost: QuadraticCost,
    z0: Tensor,
    config: PlannerConfig,
    generator: torch.Generator,
    warm_start: Tensor | None = None,
    iterations: int | None = None,
) -> ILQRResult:
    """Plan from scratch with several candidates, or refine a warm start.

    Without ``warm_start``, ``config.num_candidates`` initial plans per problem
    (:func:`initial_plans`) are optimized as one batch for ``config.iterations`` iterations and
    the cheapest is kept. With ``warm_start``, only that plan is refined, for
    ``config.mpc_iterations`` iterations.

    Args:
        dynamics: Latent dynamics.
        cost: Quadratic cost (one goal, or one per problem).
        z0: Initial states ``(B, nz)``.
        config: Planner settings.
        generator: Source of randomness for the candidate plans (unused with a warm start).
        warm_start: Plans ``(B, T, nu)`` to start from, or None.
        iterations: Overrides the number of iterations chosen above.

    Returns:
        The best plan of each problem.
    """
    n_b = z0.shape[0]
    nu = cost.action_dim
    if warm_start is not None:
        expected = (n_b, config.plan_length, nu)
        if tuple(warm_start.shape) != expected:
            raise ValueError(
                f"warm_start has shape {tuple(warm_start.shape)} but the planner expects "
                f"{expected} (batch, plan_length, action_dim); pass None to plan from scratch."
            )
        n_iter = config.mpc_iterations if iterations is None else iterations
        return ilqr_solve(dynamics, cost, z0, warm_start, config, n_iter)
    n_c = config.num_candidates
    u_init = initial_plans(n_b, config, nu, generator, z0.dtype).to(z0.device)
    z0_all = z0.repeat_interleave(n_c, 0)
    cost_all = cost
    if cost.goal.dim() == 2 and cost.goal.shape[0] > 1:
        cost_all = cost.with_goal(cost.goal.repeat_interleave(n_c, 0))
    result = ilqr_solve(
        dynamics, cost_all, z0_all, u_init.reshape(n_b * n_c, config.plan_length, nu), config,
        iterations,
    )
    best = result.cost.view(n_b, n_c).argmin(1)
    index = torch.arange(n_b) * n_c + best
    return ILQRResult(
        u=result.u[index.to(result.u.device)],
        z=result.z[index.to(result.z.device)],
        cost=result.cost[index],
        iterations=result.iterations[index],
        status=result.status[index],
    )
