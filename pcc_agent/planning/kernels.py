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

__all__ = ["RELU", "TANH", "PackedMLP", "closed_loop_rollout", "pack_mlp"]

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


@numba.njit(cache=True, fastmath=False)
def _mlp_step(z, u, weights, biases, sizes, activation, residual, x, y, out):  # noqa: D103
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
                if activation == 0:
                    acc = acc if acc > 0.0 else 0.0
                else:
                    acc = np.tanh(acc)
            y[o] = acc
        for o in range(n_out):
            x[o] = y[o]
    for i in range(nz):
        out[i] = x[i] + z[i] if residual else x[i]


@numba.njit(cache=True, fastmath=False)
def _closed_loop(z0, c, K, low, high, weights, biases, sizes, activation, residual,
                 states, actions):  # noqa: D103
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
    """
    n, horizon, nu = c.shape
    states = np.empty((n, horizon + 1, z0.shape[1]))
    actions = np.empty((n, horizon, nu))
    _closed_loop(
        np.ascontiguousarray(z0, dtype=np.float64), np.ascontiguousarray(c, dtype=np.float64),
        np.ascontiguousarray(K, dtype=np.float64), float(low), float(high), mlp.weights,
        mlp.biases, mlp.sizes, mlp.activation, mlp.residual, states, actions,
    )
    return states, actions


@numba.njit(cache=True, fastmath=False)
def _riccati_one_action(A, B, l_z, l_u, l_zz, l_uu, l_zz_terminal, lower, upper, mu,
                        k, K, decrease, ok):  # noqa: D103
    n_b, horizon, nz, _ = A.shape
    V_z = np.empty(nz)
    V_zz = np.empty((nz, nz))
    VA = np.empty((nz, nz))
    Vb = np.empty(nz)
    Q_z = np.empty(nz)
    Q_zz = np.empty((nz, nz))
    Q_uz = np.empty(nz)
    for p in range(n_b):
        for i in range(nz):
            V_z[i] = l_z[p, horizon, i]
            for j in range(nz):
                V_zz[i, j] = l_zz_terminal[i, j]
        change = 0.0
        good = True
        for t in range(horizon - 1, -1, -1):
            # V_zz A and V_zz b (b = B_t, one column)
            for i in range(nz):
                acc_b = 0.0
                for m in range(nz):
                    acc_b += V_zz[i, m] * B[p, t, m, 0]
                Vb[i] = acc_b
                for j in range(nz):
                    acc = 0.0
                    for m in range(nz):
                        acc += V_zz[i, m] * A[p, t, m, j]
                    VA[i, j] = acc
            Q_u = l_u[p, t, 0]
            Q_uu = l_uu[0, 0]
            for m in range(nz):
                Q_u += B[p, t, m, 0] * V_z[m]
                Q_uu += B[p, t, m, 0] * Vb[m]
            for j in range(nz):
                acc_z = l_z[p, t, j]
                acc_uz = 0.0
                for m in range(nz):
                    acc_z += A[p, t, m, j] * V_z[m]
                    acc_uz += B[p, t, m, 0] * VA[m, j]
                Q_z[j] = acc_z
                Q_uz[j] = acc_uz
                for i in range(nz):
                    acc = l_zz[i, j]
                    for m in range(nz):
                        acc += A[p, t, m, i] * VA[m, j]
                    Q_zz[i, j] = acc
            h = Q_uu + mu[p]
            if not h > 0.0:
                good = False
                h = 1.0
            k_free = -Q_u / h
            k_t = min(max(k_free, lower[p, t, 0]), upper[p, t, 0])
            free = k_t == k_free
            k[p, t, 0] = k_t
            for j in range(nz):
                K[p, t, 0, j] = -Q_uz[j] / h if free else 0.0
            # V_z = Q_z + K^T Q_uu k + K^T Q_u + Q_uz^T k
            # V_zz = Q_zz + K^T Q_uu K + K^T Q_uz + Q_uz^T K (symmetrized)
            for i in range(nz):
                K_i = K[p, t, 0, i]
                V_z[i] = Q_z[i] + K_i * Q_uu * k_t + K_i * Q_u + Q_uz[i] * k_t
                for j in range(nz):
                    K_j = K[p, t, 0, j]
                    V_zz[i, j] = Q_zz[i, j] + K_i * Q_uu * K_j + K_i * Q_uz[j] + Q_uz[i] * K_j
            for i in range(nz):
                for j in range(i + 1, nz):
                    sym = 0.5 * (V_zz[i, j] + V_zz[j, i])
                    V_zz[i, j] = sym
                    V_zz[j, i] = sym
            change += k_t * Q_u + 0.5 * k_t * Q_uu * k_t
        decrease[p] = -change
        ok[p] = good


def riccati_one_action(
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
    """Control-limited Riccati recursion for one action dimension (``nu = 1``).

    The same recursion as :func:`pcc_agent.planning.ilqr.backward_pass` (see that module's
    docstring), where the box-QP of each step is a clip of the scalar Newton step and the
    feedback gain is zero when the step is clipped. Shapes as there; ``lower``, ``upper`` are
    the bounds of the action deviation ``(B, T, 1)``.

    Returns:
        ``k`` ``(B, T, 1)``, ``K`` ``(B, T, 1, nz)``, the predicted decrease ``(B,)`` and
        whether ``Q_uu + mu > 0`` at every step ``(B,)``.
    """
    n_b, horizon, nz, _ = A.shape
    k = np.empty((n_b, horizon, 1))
    K = np.empty((n_b, horizon, 1, nz))
    decrease = np.empty(n_b)
    ok = np.empty(n_b, dtype=np.bool_)
    c = np.ascontiguousarray
    _riccati_one_action(c(A), c(B), c(l_z), c(l_u), c(l_zz), c(l_uu), c(l_zz_terminal),
                        c(lower), c(upper), c(mu, dtype=np.float64), k, K, decrease, ok)
    return k, K, decrease, ok
