"""Oracle and invariant tests of the latent iLQR planner (pcc_agent.planning)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from reference_riccati import backward_pass_reference

from pcc_agent.planning import (
    FunctionDynamics,
    LatentMPC,
    MLPDynamics,
    PlannerConfig,
    QuadraticCost,
    Status,
    ilqr_solve,
    plan,
    shift_plan,
)
from pcc_agent.planning.ilqr import backward_pass, rollout
from pcc_agent.planning.kernels import box_qp

DTYPE = torch.float64


def random_linear_system(nz: int, nu: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    A = np.eye(nz) + 0.3 * rng.standard_normal((nz, nz))
    B = rng.standard_normal((nz, nu))
    return A, B


def linear_dynamics(A: np.ndarray, B: np.ndarray) -> FunctionDynamics:
    A_t, B_t = torch.from_numpy(A), torch.from_numpy(B)
    return FunctionDynamics(lambda z, u: z @ A_t.T + u @ B_t.T)


def random_weights(nz: int, nu: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    M = rng.standard_normal((nz, nz))
    N = rng.standard_normal((nu, nu))
    return M @ M.T + 0.1 * np.eye(nz), N @ N.T + 0.5 * np.eye(nu), 2.0 * np.eye(nz)


def riccati_plan(A, B, Q, R, Q_T, z0, horizon):
    """Finite-horizon LQR (independent numpy implementation): optimal open-loop actions."""
    P = Q_T
    gains = []
    for _ in range(horizon):
        K = -np.linalg.solve(R + B.T @ P @ B, B.T @ P @ A)
        P = Q + A.T @ P @ A + A.T @ P @ B @ K
        gains.append(K)
    gains.reverse()
    z, actions = z0, []
    for K in gains:
        u = K @ z
        actions.append(u)
        z = A @ z + B @ u
    return np.stack(actions)


def condensed_qp(A, B, Q, R, Q_T, z0, horizon):
    """J(U) = U^T H U + 2 f^T U + c for the stacked action vector U (linear dynamics)."""
    nz, nu = B.shape
    # z_t = Phi_t z0 + G_t U
    Phi, G = [np.eye(nz)], [np.zeros((nz, horizon * nu))]
    for t in range(horizon):
        Phi.append(A @ Phi[-1])
        G_next = A @ G[-1]
        G_next[:, t * nu:(t + 1) * nu] += B
        G.append(G_next)
    H = np.kron(np.eye(horizon), R)
    f = np.zeros(horizon * nu)
    for t in range(1, horizon + 1):
        W = Q_T if t == horizon else Q
        H += G[t].T @ W @ G[t]
        f += G[t].T @ W @ (Phi[t] @ z0)
    return H, f


def projected_gradient(H, f, low, high, iterations=20000):
    step = 0.5 / np.linalg.eigvalsh(H).max()
    U = np.zeros_like(f)
    for _ in range(iterations):
        U = np.clip(U - step * 2.0 * (H @ U + f), low, high)
    return U


@pytest.mark.parametrize("nz,nu", [(3, 1), (4, 2)])
def test_one_iteration_equals_lqr(nz: int, nu: int) -> None:
    A, B = random_linear_system(nz, nu, seed=nz)
    Q, R, Q_T = random_weights(nz, nu, seed=nu)
    horizon = 6
    z0 = np.random.default_rng(1).standard_normal(nz)
    config = PlannerConfig(plan_length=horizon, iterations=1, mu_init=0.0, action_low=-1e3,
                           action_high=1e3, tolerance=0.0)
    cost = QuadraticCost(*(torch.from_numpy(m) for m in (Q, R, Q_T)), torch.zeros(nz, dtype=DTYPE))
    u_init = torch.randn(1, horizon, nu, dtype=DTYPE, generator=torch.Generator().manual_seed(0))
    result = ilqr_solve(linear_dynamics(A, B), cost, torch.from_numpy(z0)[None], u_init, config)
    expected = riccati_plan(A, B, Q, R, Q_T, z0, horizon)
    np.testing.assert_allclose(result.u[0].numpy(), expected, atol=1e-8, rtol=1e-8)
    assert result.iterations.tolist() == [1]


@pytest.mark.parametrize("nz,nu,horizon", [(2, 1, 3), (3, 2, 2), (2, 2, 3)])
def test_tight_bounds_match_brute_force_qp(nz: int, nu: int, horizon: int) -> None:
    A, B = random_linear_system(nz, nu, seed=10 + nz)
    Q, R, Q_T = random_weights(nz, nu, seed=20 + nu)
    z0 = 2.0 * np.ones(nz)
    low, high = -0.3, 0.3
    config = PlannerConfig(plan_length=horizon, iterations=30, mu_init=0.0, action_low=low,
                           action_high=high, tolerance=1e-14)
    cost = QuadraticCost(*(torch.from_numpy(m) for m in (Q, R, Q_T)), torch.zeros(nz, dtype=DTYPE))
    u_init = torch.zeros(1, horizon, nu, dtype=DTYPE)
    result = ilqr_solve(linear_dynamics(A, B), cost, torch.from_numpy(z0)[None], u_init, config)
    H, f = condensed_qp(A, B, Q, R, Q_T, z0, horizon)
    expected = projected_gradient(H, f, low, high).reshape(horizon, nu)
    u = result.u[0].numpy()
    assert (u >= low).all() and (u <= high).all()
    assert np.isclose(np.abs(expected), high).any(), "the test problem should hit a bound"
    np.testing.assert_allclose(u, expected, atol=1e-6)


def test_box_qp_matches_projected_gradient() -> None:
    rng = np.random.default_rng(0)
    n, batch = 3, 8
    M = rng.standard_normal((batch, n, n))
    H = M @ np.swapaxes(M, 1, 2) + 0.3 * np.eye(n)
    g = 3.0 * rng.standard_normal((batch, n))
    lower, upper = -np.ones((batch, n)), 0.5 * np.ones((batch, n))
    x, free = box_qp(H, g, lower, upper, np.zeros((batch, n)))
    for b in range(batch):
        expected = projected_gradient(0.5 * H[b], 0.5 * g[b], lower[b], upper[b])
        np.testing.assert_allclose(x[b], expected, atol=1e-7)
    at_bound = np.isclose(x, lower) | np.isclose(x, upper)
    assert not (free & at_bound & ~np.isclose(g + np.einsum("bij,bj->bi", H, x), 0)).any()


def pendulum_like(seed: int = 0) -> MLPDynamics:
    return MLPDynamics.random(3, 1, (30, 30), torch.Generator().manual_seed(seed),
                              activation="tanh", residual=True, dtype=DTYPE)


def test_cost_never_increases_on_nonlinear_system() -> None:
    dynamics = pendulum_like()
    config = PlannerConfig(plan_length=15, tolerance=0.0)
    cost = QuadraticCost.from_config(config, torch.tensor([1.0, -0.5, 0.3], dtype=DTYPE), 1)
    z0 = torch.zeros(3, 3, dtype=DTYPE)
    u_init = torch.rand(3, 15, 1, dtype=DTYPE, generator=torch.Generator().manual_seed(1)) * 2 - 1
    costs = [ilqr_solve(dynamics, cost, z0, u_init, config, iterations=i).cost
             for i in range(0, 7)]
    stacked = torch.stack(costs)
    assert torch.isfinite(stacked).all()
    assert (stacked[1:] <= stacked[:-1]).all()
    assert (stacked[-1] < stacked[0]).all()


def test_batched_and_unbatched_solves_agree() -> None:
    dynamics = pendulum_like(seed=3)
    config = PlannerConfig(plan_length=8, iterations=5)
    goals = torch.randn(4, 3, dtype=DTYPE, generator=torch.Generator().manual_seed(2))
    z0 = torch.randn(4, 3, dtype=DTYPE, generator=torch.Generator().manual_seed(3))
    u_init = torch.rand(4, 8, 1, dtype=DTYPE, generator=torch.Generator().manual_seed(4)) * 2 - 1
    cost = QuadraticCost.from_config(config, goals, 1)
    batched = ilqr_solve(dynamics, cost, z0, u_init, config)
    for b in range(4):
        single = ilqr_solve(dynamics, cost.with_goal(goals[b]), z0[b:b + 1], u_init[b:b + 1],
                            config)
        torch.testing.assert_close(batched.u[b], single.u[0], atol=1e-9, rtol=1e-9)
        torch.testing.assert_close(batched.cost[b], single.cost[0])
        assert batched.status[b] == single.status[0]


def test_jacobians_match_finite_differences() -> None:
    mlp = pendulum_like(seed=5)

    def fn(z: torch.Tensor, u: torch.Tensor) -> torch.Tensor:
        x = torch.cat([z, u], -1)
        for i, (w, b) in enumerate(zip(mlp.weights, mlp.biases)):
            x = torch.nn.functional.linear(x if i == 0 else torch.tanh(x), w, b)
        return z + x

    generator = torch.Generator().manual_seed(6)
    z = torch.randn(5, 3, dtype=DTYPE, generator=generator)
    u = torch.randn(5, 1, dtype=DTYPE, generator=generator)
    A, B = FunctionDynamics(fn).jacobians(z, u)
    eps = 1e-6
    A_fd = torch.stack([(fn(z + eps * e, u) - fn(z - eps * e, u)) / (2 * eps)
                        for e in torch.eye(3, dtype=DTYPE)], -1)
    B_fd = ((fn(z, u + eps) - fn(z, u - eps)) / (2 * eps)).unsqueeze(-1)
    torch.testing.assert_close(A, A_fd, atol=1e-7, rtol=1e-6)
    torch.testing.assert_close(B, B_fd, atol=1e-7, rtol=1e-6)
    A_mlp, B_mlp = mlp.jacobians(z, u)
    torch.testing.assert_close(A_mlp, A, atol=1e-12, rtol=1e-10)
    torch.testing.assert_close(B_mlp, B, atol=1e-12, rtol=1e-10)
    torch.testing.assert_close(mlp.step(z, u), fn(z, u))


def exploding_dynamics() -> FunctionDynamics:
    """Finite for u < 0.5, +inf beyond (and NaN Jacobians with nan_jacobians)."""

    def fn(z: torch.Tensor, u: torch.Tensor) -> torch.Tensor:
        finite = u.sum(-1, keepdim=True) < 0.5
        return torch.where(finite, 0.9 * z + 0.2 * u.sum(-1, keepdim=True),
                           torch.full_like(z, float("inf")))

    return FunctionDynamics(fn)


def test_non_finite_dynamics_give_status_not_nan() -> None:
    dynamics = exploding_dynamics()
    config = PlannerConfig(plan_length=5)
    cost = QuadraticCost.from_config(config, torch.full((2,), 2.0, dtype=DTYPE), 1)
    z0 = torch.ones(2, 2, dtype=DTYPE)
    # Problem 0 diverges on its initial plan, problem 1 starts finite.
    u_init = torch.stack([torch.ones(5, 1), torch.zeros(5, 1)]).to(DTYPE)
    result = ilqr_solve(dynamics, cost, z0, u_init, config)
    assert not torch.isnan(result.u).any() and not torch.isnan(result.cost).any()
    assert ((result.u >= -1) & (result.u <= 1)).all()
    assert torch.isfinite(result.cost[1]) and result.status[1] != Status.NON_FINITE
    assert (result.u[1] < 0.5).all(), "line search must reject steps into the diverging region"
    # Problem 0 recovers: zero-gain steps towards lower action cost leave the region.
    assert torch.isfinite(result.cost[0]) and (result.u[0] < 0.5).all()
    # Dynamics that stay infinite give a status, not NaN.
    always_inf = FunctionDynamics(lambda z, u: z * float("inf") + u.sum())
    stuck = ilqr_solve(always_inf, cost, z0, u_init, config)
    assert (stuck.status == Status.NON_FINITE).all() and torch.isinf(stuck.cost).all()
    assert not torch.isnan(stuck.u).any()
    # Planning from scratch: the extreme candidate at +1 diverges and must lose.
    best = plan(dynamics, cost, z0, config, torch.Generator().manual_seed(0))
    assert torch.isfinite(best.cost).all() and torch.isfinite(best.z).all()


def test_mpc_warm_start_shifts_plan() -> None:
    dynamics = pendulum_like(seed=7)
    config = PlannerConfig(plan_length=6, iterations=3, mpc_iterations=1, num_candidates=4)
    cost = QuadraticCost.from_config(config, torch.tensor([0.5, 0.0, -0.5], dtype=DTYPE), 1)
    mpc = LatentMPC(dynamics, cost, config, seed=0)
    z0 = torch.zeros(3, dtype=DTYPE)
    action, warm = mpc.plan_step(z0)
    assert action.shape == (1,) and warm.shape == (6, 1)
    first_plan = mpc.last_result.u[0]
    torch.testing.assert_close(warm[:-1], first_plan[1:])
    torch.testing.assert_close(warm[-1], first_plan[-1])
    torch.testing.assert_close(action, first_plan[0])
    z1 = dynamics.step(z0[None], action[None])[0]
    mpc.plan_step(z1, warm)
    assert mpc.last_result.iterations.item() <= config.mpc_iterations
    # The stateful variant carries the same warm start.
    mpc.reset()
    torch.testing.assert_close(mpc.act(z0), action)
    torch.testing.assert_close(mpc.warm_start, warm)
    mpc.reset()
    assert mpc.warm_start is None


def test_mpc_batched_over_problems() -> None:
    dynamics = pendulum_like(seed=8)
    config = PlannerConfig(plan_length=5)
    goals = torch.randn(3, 3, dtype=DTYPE, generator=torch.Generator().manual_seed(9))
    mpc = LatentMPC(dynamics, QuadraticCost.from_config(config, goals, 1), config)
    z = torch.zeros(3, 3, dtype=DTYPE)
    for _ in range(3):
        action = mpc.act(z)
        assert action.shape == (3, 1) and ((action >= -1) & (action <= 1)).all()
        z = dynamics.step(z, action)
    assert mpc.warm_start.shape == (3, 5, 1)


def test_same_seed_same_plan() -> None:
    dynamics = pendulum_like(seed=10)
    config = PlannerConfig(plan_length=7)
    cost = QuadraticCost.from_config(config, torch.ones(3, dtype=DTYPE), 1)
    z0 = torch.zeros(2, 3, dtype=DTYPE)
    first = plan(dynamics, cost, z0, config, torch.Generator().manual_seed(42))
    second = plan(dynamics, cost, z0, config, torch.Generator().manual_seed(42))
    torch.testing.assert_close(first.u, second.u, rtol=0, atol=0)
    assert LatentMPC(dynamics, cost, config, seed=1).act(z0[0]).item() == \
        LatentMPC(dynamics, cost, config, seed=1).act(z0[0]).item()


def test_rollout_and_plan_shapes_float32() -> None:
    dynamics = MLPDynamics.random(8, 3, (40, 40), torch.Generator().manual_seed(0))
    config = PlannerConfig(plan_length=4, iterations=2)
    cost = QuadraticCost.from_config(config, torch.zeros(8), 3)
    z0 = torch.randn(2, 8, generator=torch.Generator().manual_seed(1))
    z = rollout(dynamics, z0, torch.zeros(2, 4, 3))
    assert z.shape == (2, 5, 8)
    result = plan(dynamics, cost, z0, config, torch.Generator().manual_seed(0))
    assert result.u.shape == (2, 4, 3) and result.u.dtype == torch.float32
    assert result.z.shape == (2, 5, 8) and result.cost.shape == (2,)
    assert ((result.u >= -1) & (result.u <= 1)).all()
    with pytest.raises(ValueError, match="warm_start has shape"):
        plan(dynamics, cost, z0, config, torch.Generator(), warm_start=torch.zeros(2, 3, 3))


def test_shift_plan_repeats_last_action() -> None:
    u = torch.arange(6.0).view(1, 3, 2)
    assert shift_plan(u).tolist() == [[[2.0, 3.0], [4.0, 5.0], [4.0, 5.0]]]


class _TorchOnly:
    """The same dynamics without ``packed_mlp``: forces the planner's torch loops."""

    def __init__(self, dynamics: MLPDynamics) -> None:
        self.step, self.jacobians = dynamics.step, dynamics.jacobians


@pytest.mark.parametrize("activation", ["relu", "tanh"])
def test_compiled_loops_match_torch_loops(activation: str) -> None:
    dynamics = MLPDynamics.random(4, 2, (20, 20), torch.Generator().manual_seed(7),
                                  activation=activation, residual=True, dtype=DTYPE)
    z0 = torch.randn(3, 4, dtype=DTYPE, generator=torch.Generator().manual_seed(8))
    u = torch.rand(3, 12, 2, dtype=DTYPE, generator=torch.Generator().manual_seed(9)) * 2 - 1
    torch.testing.assert_close(rollout(dynamics, z0, u), rollout(_TorchOnly(dynamics), z0, u))
    config = PlannerConfig(plan_length=12, iterations=4, action_low=-0.5, action_high=0.5)
    cost = QuadraticCost.from_config(config, torch.ones(4, dtype=DTYPE), 2)
    fast = ilqr_solve(dynamics, cost, z0, u, config)
    slow = ilqr_solve(_TorchOnly(dynamics), cost, z0, u, config)
    torch.testing.assert_close(fast.u, slow.u, atol=1e-10, rtol=1e-10)
    torch.testing.assert_close(fast.cost, slow.cost)
    assert torch.equal(fast.status, slow.status)


@pytest.mark.parametrize("nu", [1, 2, 3])
def test_compiled_riccati_matches_numpy_reference(nu: int) -> None:
    rng = np.random.default_rng(nu)
    n_b, horizon, nz = 6, 9, 4
    A = np.eye(nz) + 0.3 * rng.standard_normal((n_b, horizon, nz, nz))
    B = rng.standard_normal((n_b, horizon, nz, nu))
    l_z = 3.0 * rng.standard_normal((n_b, horizon + 1, nz))
    l_u = rng.standard_normal((n_b, horizon, nu))
    l_zz = 2.0 * np.eye(nz)
    u = rng.uniform(-1, 1, (n_b, horizon, nu))
    mu = np.array([0.0, 1e-6, 1.0, 0.0, 0.0, 10.0])
    # a positive action cost, then a strongly negative one (Q_uu + mu I indefinite somewhere)
    for l_uu in (0.2 * np.eye(nu), -50.0 * np.eye(nu)):
        fast = backward_pass(A, B, l_z, l_u, l_zz, l_uu, l_zz, u, mu, -0.5, 0.5)
        k, K, decrease, ok = backward_pass_reference(A, B, l_z, l_u, l_zz, l_uu, l_zz, u, mu,
                                                     -0.5, 0.5)
        np.testing.assert_array_equal(fast.ok, ok)
        np.testing.assert_allclose(fast.k[ok], k[ok], rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(fast.K[ok], K[ok], rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(fast.expected_decrease[ok], decrease[ok], rtol=1e-9)
        if l_uu[0, 0] > 0:  # clamped (zero gain rows) and free steps are both exercised
            assert ok.all() and 0 < (fast.K == 0).all(-1).sum() < n_b * horizon * nu
            assert (fast.k >= -0.5 - u - 1e-12).all() and (fast.k <= 0.5 - u + 1e-12).all()
        else:
            assert not ok.all()


def test_compiled_loops_check_shapes_and_keep_autograd() -> None:
    from pcc_agent.planning.kernels import closed_loop_rollout, riccati

    dynamics = MLPDynamics.random(2, 1, (8,), torch.Generator().manual_seed(0), dtype=DTYPE)
    with pytest.raises(ValueError, match="Shapes do not fit"):
        closed_loop_rollout(dynamics.packed_mlp, np.zeros((1, 3)), np.zeros((1, 4, 1)),
                            np.zeros((1, 4, 1, 3)), -1.0, 1.0)
    with pytest.raises(ValueError, match="l_z has shape"):
        riccati(np.zeros((1, 4, 2, 2)), np.zeros((1, 4, 2, 1)), np.zeros((1, 4, 2)),
                np.zeros((1, 4, 1)), np.eye(2), np.eye(1), np.eye(2), -np.ones((1, 4, 1)),
                np.ones((1, 4, 1)), 0.0)
    # a gradient through the initial state takes the torch loops and reaches z0
    z0 = torch.zeros(1, 2, dtype=DTYPE, requires_grad=True)
    rollout(dynamics, z0, torch.ones(1, 3, 1, dtype=DTYPE))[:, -1].sum().backward()
    assert z0.grad is not None and torch.isfinite(z0.grad).all()


def test_initial_plans_hold_constant_and_bang_bang_extremes_then_uniform():
    from pcc_agent.planning.ilqr import initial_plans

    config = PlannerConfig(plan_length=7, num_candidates=6, num_extreme=3, action_low=-0.5,
                           action_high=2.0)
    plans = initial_plans(4, config, 2, torch.Generator().manual_seed(0), torch.float64)
    assert plans.shape == (4, 6, 7, 2)
    assert torch.all(plans[:, 0] == -0.5) and torch.all(plans[:, 1] == 2.0)
    assert torch.all((plans[:, 2] == -0.5) | (plans[:, 2] == 2.0))  # bang-bang
    assert not torch.all(plans[:, 2] == plans[:, 2, :1])  # not constant
    inside = plans[:, 3:]
    assert torch.all((inside > -0.5) & (inside < 2.0))  # uniform, strictly inside
    # Default (2 extremes) keeps the earlier draws bit for bit.
    two = initial_plans(1, PlannerConfig(plan_length=3), 1, torch.Generator().manual_seed(1))
    old = -1 + 2 * torch.rand((1, 6, 3, 1), generator=torch.Generator().manual_seed(1))
    torch.testing.assert_close(two[:, 2:], old[:, 2:], rtol=0, atol=0)


def test_mpc_replans_every_k_steps_and_executes_the_plan_in_between():
    config = PlannerConfig(plan_length=6, iterations=2, mpc_iterations=1, replan_every=3)
    dynamics = MLPDynamics.random(2, 1, (8,), torch.Generator().manual_seed(0))
    mpc = LatentMPC(dynamics, QuadraticCost.from_config(config, torch.zeros(2), 1), config)
    z = torch.ones(2)
    planned = []
    for _ in range(7):
        before = mpc.last_result
        action = mpc.act(z)
        planned.append(mpc.last_result is not before)
        z = dynamics.step(z[None], action[None])[0]
    assert planned == [True, False, False, True, False, False, True]


def test_replan_every_beyond_the_plan_is_refused():
    with pytest.raises(ValueError, match="replan_every"):
        PlannerConfig(plan_length=4, replan_every=5)
