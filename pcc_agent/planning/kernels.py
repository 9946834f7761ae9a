"""Compiled (numba) inner loops of the planner for MLP latent dynamics on the CPU.

A plan is a chain of ``T`` dependent steps, and an MLP transition of the paper's size is a
few hundred multiply-adds per step: in eager torch or numpy the cost is the per-call overhead
(several microseconds per tiny matrix product, a dozen products per step), which made a
200-step MPC step cost ~40 ms. These kernels run the same arithmetic as
:meth:`~pcc_agent.planning.dynamics.MLPDynamics.step` in float64 machine code.

The MLP is passed as :class:`PackedMLP`: the layers' weights zero-padded into one array
``weights (L, width, width)`` (layer ``l`` maps ``sizes[l]`` inputs to ``sizes[l + 1]``
outputs; the first layer's inputs are ``[z; u]``), biases ``(L, width)``, the activation code
(:data:`RELU` or :data:`TANH`, after every layer but the last) and whether the network
predicts the change of state.

Functions compile on first use and are cached on disk (``numba`` ``cache=True``).
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

__all__ = ["RELU", "TANH", "PackedMLP", "box_qp", "closed_loop_rollout", "pack_mlp", "riccati"]

RELU = 0
TANH = 1


class PackedMLP(NamedTuple):
    """An MLP transition in the kernels' format (see the module docstring)."""

    weights: np.ndarray
    biases: np.ndarray
    sizes: np.ndarray
    activation: int
    residual: bool


def pack_mlp(
    weights: list[np.ndarray], biases: list[np.ndarray], activation: int, residual: bool
) -> PackedMLP:
    """Pack float64 weight matrices ``(out, in)`` and biases into a :class:`PackedMLP`."""
    sizes = np.array([weights[0].shape[1]] + [w.shape[0] for w in weights], dtype=np.int64)
    width = int(sizes.max())
    packed_w = np.zeros((len(weights), width, width))
    packed_b = np.zeros((len(weights), width))
    for layer, (w, b) in enumerate(zip(weights, biases)):
        packed_w[layer, : w.shape[0], : w.shape[1]] = w
        packed_b[layer, : b.shape[0]] = b
    return PackedMLP(packed_w, packed_b, sizes, int(activation), bool(residual))


@numba.njit(cache=True)
def _mlp_step(z, u, weights, biases, sizes, activation, residual, x, y, out):
    """``out = f(z, u)`` for one state; ``x``, ``y`` are scratch vectors of the padded width."""
    nz = z.shape[0]
    nu = u.shape[0]
    for i in range(nz):
        x[i] = z[i]
    for i in range(nu):
        x[nz + i] = u[i]
    n_layers = weights.shape[0]
    for layer in range(n_layers):
        n_in = sizes[layer]
        n_out = sizes[layer + 1]
        for o in range(n_out):
            acc = biases[layer, o]
            for i in range(n_in):
                acc += weights[layer, o, i] * x[i]
            if layer < n_layers - 1:
                if activation == RELU:
                    acc = acc if acc > 0.0 else 0.0
                else:
                    acc = np.tanh(acc)
            y[o] = acc
        for o in range(n_out):
            x[o] = y[o]
    for i in range(nz):
        out[i] = x[i] + z[i] if residual else x[i]


@numba.njit(cache=True)
def _closed_loop(z0, c, K, low, high, weights, biases, sizes, activation, residual,
                 states, actions):
    """Fill ``states`` and ``actions`` with the rollouts of ``u = clip(c + K z)``."""
    n, horizon, nu = c.shape
    nz = z0.shape[1]
    width = weights.shape[1]
    x = np.empty(width)
    y = np.empty(width)
    u = np.empty(nu)
    for p in range(n):
        for i in range(nz):
            states[p, 0, i] = z0[p, i]
        for t in range(horizon):
            for j in range(nu):
                acc = c[p, t, j]
                for i in range(nz):
                    acc += K[p, t, j, i] * states[p, t, i]
                if acc < low:
                    acc = low
                elif acc > high:
                    acc = high
                u[j] = acc
                actions[p, t, j] = acc
            _mlp_step(states[p, t], u, weights, biases, sizes, activation, residual, x, y,
                      states[p, t + 1])


def closed_loop_rollout(
    mlp: PackedMLP, z0: np.ndarray, c: np.ndarray, K: np.ndarray, low: float, high: float
) -> tuple[np.ndarray, np.ndarray]:
    """Rollout of ``u_t = clip(c_t + K_t z_t, low, high)``, ``z_{t+1} = f(z_t, u_t)``.

    With ``K = 0`` this is the open-loop rollout of the actions ``clip(c)``.

    Args:
        mlp: The transition.
        z0: Initial states ``(N, nz)``.
        c: Feed-forward terms ``(N, T, nu)``.
        K: Feedback gains ``(N, T, nu, nz)``.
        low: Lower action bound.
        high: Upper action bound.

    Returns:
        States ``(N, T + 1, nz)`` and actions ``(N, T, nu)``, float64. A diverging rollout
        yields inf or NaN (the caller rejects it).

    Raises:
        ValueError: Shapes that do not fit together or do not fit the MLP (the compiled loop
            does not check bounds).
    """
    n, horizon, nu = c.shape
    nz = z0.shape[1] if z0.ndim == 2 else -1
    if (z0.shape[0] != n or nz != mlp.sizes[-1] or nz + nu != mlp.sizes[0]
            or K.shape != (n, horizon, nu, nz)):
        raise ValueError(
            f"Shapes do not fit an MLP with {mlp.sizes[0]} inputs and {mlp.sizes[-1]} outputs: "
            f"z0 {z0.shape}, c {c.shape}, K {K.shape} (expected (N, nz), (N, T, nu), "
            "(N, T, nu, nz) with nz + nu inputs)."
        )
    states = np.empty((n, horizon + 1, z0.shape[1]))
    actions = np.empty((n, horizon, nu))
    _closed_loop(
        np.ascontiguousarray(z0, dtype=np.float64), np.ascontiguousarray(c, dtype=np.float64),
        np.ascontiguousarray(K, dtype=np.float64), float(low), float(high), mlp.weights,
        mlp.biases, mlp.sizes, mlp.activation, mlp.residual, states, actions,
    )
    return states, actions


@numba.njit(cache=True)
def _cholesky(H, L):
    """Lower Cholesky factor of ``H`` into ``L``; False when ``H`` is not positive definite."""
    n = H.shape[0]
    for j in range(n):
        diag = H[j, j]
        for m in range(j):
            diag -= L[j, m] * L[j, m]
        if not diag > 0.0:  # also catches NaN
            return False
        L[j, j] = np.sqrt(diag)
        for i in range(j + 1, n):
            acc = H[i, j]
            for m in range(j):
                acc -= L[i, m] * L[j, m]
            L[i, j] = acc / L[j, j]
        for i in range(j):
            L[i, j] = 0.0
    return True


@numba.njit(cache=True)
def _cholesky_solve(L, b, x):
    """Solve ``L L^T x = b``."""
    n = L.shape[0]
    for i in range(n):
        acc = b[i]
        for m in range(i):
            acc -= L[i, m] * x[m]
        x[i] = acc / L[i, i]
    for i in range(n - 1, -1, -1):
        acc = x[i]
        for m in range(i + 1, n):
            acc -= L[m, i] * x[m]
        x[i] = acc / L[i, i]


@numba.njit(cache=True)
def _gradient_and_free(H, g, x, lower, upper, grad, free):
    """``grad = g + H x``; ``free[i]`` unless ``x_i`` sits at a bound its gradient pushes on."""
    n = H.shape[0]
    for i in range(n):
        acc = g[i]
        for j in range(n):
            acc += H[i, j] * x[j]
        grad[i] = acc
    for i in range(n):
        free[i] = not ((x[i] <= lower[i] and grad[i] > 0.0)
                       or (x[i] >= upper[i] and grad[i] < 0.0))


@numba.njit(cache=True)
def _set_identity(M):
    for i in range(M.shape[0]):
        for j in range(M.shape[1]):
            M[i, j] = 1.0 if i == j else 0.0


@numba.njit(cache=True)
def _free_block(H, free, out):
    """``H`` on the free dimensions, the identity on the clamped ones."""
    n = H.shape[0]
    for i in range(n):
        for j in range(n):
            out[i, j] = H[i, j] if (free[i] and free[j]) else (1.0 if i == j else 0.0)


@numba.njit(cache=True)
def _box_qp(H, g, lower, upper, x, free, max_iterations):
    """Projected-Newton box-QP in place on ``x`` (the start); ``free`` gets the free dims."""
    n = H.shape[0]
    grad = np.empty(n)
    H_free = np.empty((n, n))
    L = np.empty((n, n))
    rhs = np.empty(n)
    dx = np.empty(n)
    candidate = np.empty(n)
    for i in range(n):
        x[i] = min(max(x[i], lower[i]), upper[i])
    for _ in range(max_iterations):
        _gradient_and_free(H, g, x, lower, upper, grad, free)
        _free_block(H, free, H_free)
        for i in range(n):
            rhs[i] = -grad[i] if free[i] else 0.0
        if not _cholesky(H_free, L):
            break
        _cholesky_solve(L, rhs, dx)
        f0 = 0.0
        for i in range(n):
            f0 += x[i] * 0.5 * (grad[i] + g[i])
        step = 1.0
        moved = 0.0
        for _ in range(12):
            f = 0.0
            slope = 0.0
            for i in range(n):
                candidate[i] = min(max(x[i] + step * dx[i], lower[i]), upper[i])
            for i in range(n):
                h_c = 0.0
                for j in range(n):
                    h_c += H[i, j] * candidate[j]
                f += candidate[i] * (0.5 * h_c + g[i])
                slope += grad[i] * (candidate[i] - x[i])
            if f <= f0 + 0.1 * slope + 1e-15:
                for i in range(n):
                    moved = max(moved, abs(candidate[i] - x[i]))
                    x[i] = candidate[i]
                break
            step *= 0.5
        if moved < 1e-12:
            break
    _gradient_and_free(H, g, x, lower, upper, grad, free)


@numba.njit(cache=True)
def _riccati(A, B, l_z, l_u, l_zz, l_uu, l_zz_terminal, lower, upper, mu,
             k, K, decrease, ok):
    """Fill ``k``, ``K``, ``decrease`` and ``ok`` (see :func:`riccati`)."""
    n_b, horizon, nz, nu = B.shape
    V_z = np.empty(nz)
    V_zz = np.empty((nz, nz))
    VA = np.empty((nz, nz))
    VB = np.empty((nz, nu))
    Q_z = np.empty(nz)
    Q_u = np.empty(nu)
    Q_zz = np.empty((nz, nz))
    Q_uz = np.empty((nu, nz))
    Q_uu = np.empty((nu, nu))
    H = np.empty((nu, nu))
    H_free = np.empty((nu, nu))
    L = np.empty((nu, nu))
    k_t = np.empty(nu)
    quu_k = np.empty(nu)
    K_t = np.empty((nu, nz))
    rhs = np.empty(nu)
    col = np.empty(nu)
    free = np.empty(nu, dtype=np.bool_)
    for p in range(n_b):
        for i in range(nz):
            V_z[i] = l_z[p, horizon, i]
            for j in range(nz):
                V_zz[i, j] = l_zz_terminal[i, j]
        change = 0.0
        good = True
        for t in range(horizon - 1, -1, -1):
            for i in range(nz):
                for j in range(nz):
                    acc = 0.0
                    for m in range(nz):
                        acc += V_zz[i, m] * A[p, t, m, j]
                    VA[i, j] = acc
                for j in range(nu):
                    acc = 0.0
                    for m in range(nz):
                        acc += V_zz[i, m] * B[p, t, m, j]
                    VB[i, j] = acc
            for i in range(nz):
                acc = l_z[p, t, i]
                for m in range(nz):
                    acc += A[p, t, m, i] * V_z[m]
                Q_z[i] = acc
                for j in range(nz):
                    acc = l_zz[i, j]
                    for m in range(nz):
                        acc += A[p, t, m, i] * VA[m, j]
                    Q_zz[i, j] = acc
            for a in range(nu):
                acc = l_u[p, t, a]
                for m in range(nz):
                    acc += B[p, t, m, a] * V_z[m]
                Q_u[a] = acc
                for j in range(nz):
                    acc = 0.0
                    for m in range(nz):
                        acc += B[p, t, m, a] * VA[m, j]
                    Q_uz[a, j] = acc
                for b in range(nu):
                    acc = l_uu[a, b]
                    for m in range(nz):
                        acc += B[p, t, m, a] * VB[m, b]
                    Q_uu[a, b] = acc
            # Gains from the regularized Hessian (the identity when it is not positive definite).
            for a in range(nu):
                for b in range(nu):
                    H[a, b] = Q_uu[a, b] + (mu[p] if a == b else 0.0)
            if not _cholesky(H, L):
                good = False
                _set_identity(H)
                _cholesky(H, L)
            for a in range(nu):
                rhs[a] = -Q_u[a]
            _cholesky_solve(L, rhs, k_t)
            inside = True
            for a in range(nu):
                if k_t[a] < lower[p, t, a] or k_t[a] > upper[p, t, a]:
                    inside = False
            if inside:
                for a in range(nu):
                    free[a] = True
            else:
                _box_qp(H, Q_u, lower[p, t], upper[p, t], k_t, free, 20)
            # K = -(H_ff)^{-1} Q_uz,f on the free rows, zero on the clamped ones.
            _free_block(H, free, H_free)
            if not _cholesky(H_free, L):  # PD in exact arithmetic; lost only to rounding
                good = False
                _set_identity(H_free)
                _cholesky(H_free, L)
            for j in range(nz):
                for a in range(nu):
                    rhs[a] = -Q_uz[a, j] if free[a] else 0.0
                _cholesky_solve(L, rhs, col)
                for a in range(nu):
                    K_t[a, j] = col[a]
            # V_z = Q_z + K^T Q_uu k + K^T Q_u + Q_uz^T k
            # V_zz = Q_zz + K^T Q_uu K + K^T Q_uz + Q_uz^T K (symmetrized)
            for a in range(nu):
                acc = 0.0
                for b in range(nu):
                    acc += Q_uu[a, b] * k_t[b]
                quu_k[a] = acc
            for i in range(nz):
                acc = Q_z[i]
                for a in range(nu):
                    acc += K_t[a, i] * (quu_k[a] + Q_u[a]) + Q_uz[a, i] * k_t[a]
                V_z[i] = acc
                for j in range(nz):
                    acc = Q_zz[i, j]
                    for a in range(nu):
                        quu_K = 0.0
                        for b in range(nu):
                            quu_K += Q_uu[a, b] * K_t[b, j]
                        acc += K_t[a, i] * (quu_K + Q_uz[a, j]) + Q_uz[a, i] * K_t[a, j]
                    V_zz[i, j] = acc
            for i in range(nz):
                for j in range(i + 1, nz):
                    sym = 0.5 * (V_zz[i, j] + V_zz[j, i])
                    V_zz[i, j] = sym
                    V_zz[j, i] = sym
            for a in range(nu):
                change += k_t[a] * (Q_u[a] + 0.5 * quu_k[a])
                k[p, t, a] = k_t[a]
                for j in range(nz):
                    K[p, t, a, j] = K_t[a, j]
        decrease[p] = -change
        ok[p] = good


def box_qp(  # the planner calls the compiled solver inside the recursion; this is for tests
    H: np.ndarray,
    g: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    x0: np.ndarray,
    max_iterations: int = 20,
) -> tuple[np.ndarray, np.ndarray]:
    """Projected-Newton solver of small box-constrained quadratic programs, one per row.

    Solves ``min_x 1/2 x^T H x + g^T x`` subject to ``lower <= x <= upper`` for each problem,
    as in Tassa, Mansard & Todorov (2014): at each iteration the dimensions at a bound whose
    gradient pushes outwards are clamped, a Newton step is taken on the free dimensions, and
    a projected Armijo backtracking line search picks the step.

    Args:
        H: Positive definite Hessians ``(B, n, n)``.
        g: Gradients ``(B, n)``.
        lower: Lower bounds ``(B, n)`` (``lower <= upper``).
        upper: Upper bounds ``(B, n)``.
        x0: Starting points ``(B, n)`` (projected onto the box first).
        max_iterations: Maximum number of Newton iterations.

    Returns:
        The solutions ``(B, n)`` and the free-dimension mask ``(B, n)`` at the solutions.
    """
    x = np.array(x0, dtype=np.float64)
    free = np.empty(x.shape, dtype=np.bool_)
    for b in range(x.shape[0]):
        _box_qp(np.ascontiguousarray(H[b], dtype=np.float64),
                np.ascontiguousarray(g[b], dtype=np.float64),
                np.ascontiguousarray(lower[b], dtype=np.float64),
                np.ascontiguousarray(upper[b], dtype=np.float64), x[b], free[b],
                max_iterations)
    return x, free


def riccati(
    A: np.ndarray,
    B: np.ndarray,
    l_z: np.ndarray,
    l_u: np.ndarray,
    l_zz: np.ndarray,
    l_uu: np.ndarray,
    l_zz_terminal: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    mu: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Control-limited Riccati recursion of iLQR, compiled (see :mod:`pcc_agent.planning.ilqr`).

    At each step the action deviation solves the box-QP with ``H = Q_uu + mu I`` (Cholesky;
    the identity stands in, and the problem is marked failed, when a pivot is not positive),
    the feedback gain acts on the free dimensions only, and the value function is propagated
    with the unregularized ``Q_uu``. The kernel never raises on numbers: a NaN or an overflow
    ends as non-finite gains or a failed factorization, which the caller
    (:func:`pcc_agent.planning.ilqr.backward_pass`) turns into a failed problem.

    The arguments are those of :func:`pcc_agent.planning.ilqr.backward_pass`, except that
    ``lower`` and ``upper`` ``(B, T, nu)`` bound the action deviation ``k`` (not the action).

    Returns:
        ``k`` ``(B, T, nu)``, ``K`` ``(B, T, nu, nz)``, the predicted decrease
        ``-sum_t (k^T Q_u + 1/2 k^T Q_uu k)`` ``(B,)`` and whether ``Q_uu + mu I`` was positive
        definite at every step ``(B,)``.
    """
    n_b, horizon, nz, nu = B.shape
    expected = {"A": (A, (n_b, horizon, nz, nz)), "l_z": (l_z, (n_b, horizon + 1, nz)),
                "l_u": (l_u, (n_b, horizon, nu)), "l_zz": (l_zz, (nz, nz)),
                "l_uu": (l_uu, (nu, nu)), "l_zz_terminal": (l_zz_terminal, (nz, nz)),
                "lower": (lower, (n_b, horizon, nu)), "upper": (upper, (n_b, horizon, nu))}
    for name, (array, shape) in expected.items():
        if np.shape(array) != shape:
            raise ValueError(f"{name} has shape {np.shape(array)}, expected {shape}.")
    mu = np.broadcast_to(np.asarray(mu, dtype=np.float64), (n_b,))
    k = np.empty((n_b, horizon, nu))
    K = np.empty((n_b, horizon, nu, nz))
    decrease = np.empty(n_b)
    ok = np.empty(n_b, dtype=np.bool_)
    args = [np.ascontiguousarray(a, dtype=np.float64)
            for a in (A, B, l_z, l_u, l_zz, l_uu, l_zz_terminal, lower, upper, mu)]
    _riccati(*args, k, K, decrease, ok)
    return k, K, decrease, ok
