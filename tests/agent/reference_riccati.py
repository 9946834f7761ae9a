"""Reference implementation of the control-limited Riccati recursion in batched numpy.

This was the planner's backward pass before the compiled kernel
(:func:`pcc_agent.planning.kernels.riccati`), less its closed-form branch for one action
dimension (equivalent); the tests check that both agree. Its positive-definiteness test
differs in one corner: with a Cholesky failure in the batch it also rejects matrices whose
eigenvalues span more than 1e12, which the kernel accepts (the gains then overflow and the
finiteness check rejects them). Quadratic models
are kept in homogeneous form, ``1/2 [x; 1]^T M [x; 1]``, so that each step is
``Q = G^T W G + L`` (``G = [[A, B, 0], [0, 0, 1]]``) and ``W = P^T Q P`` with the affine
policy ``P = [[I, 0], [K, k], [0, 1]]``; the corner of ``W_0`` accumulates the predicted change.
"""

from __future__ import annotations

import numpy as np


def box_qp(
    H: np.ndarray,
    g: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    x0: np.ndarray,
    max_iterations: int = 20,
) -> tuple[np.ndarray, np.ndarray]:
    """Batched numpy projected-Newton box-QP (the reference of ``kernels.box_qp``)."""
    n = H.shape[-1]
    eye = np.eye(n, dtype=bool)
    steps = 0.5 ** np.arange(12.0)
    x = np.clip(x0, lower, upper)
    free = np.ones_like(x, dtype=bool)
    for _ in range(max_iterations):
        grad = g + np.einsum("bij,bj->bi", H, x)
        clamped = ((x <= lower) & (grad > 0)) | ((x >= upper) & (grad < 0))
        free = ~clamped
        both_free = free[:, :, None] & free[:, None, :]
        H_free = np.where(both_free, H, eye)
        dx = -np.linalg.solve(H_free, (grad * free)[..., None])[..., 0]
        candidates = np.clip(x[:, None] + steps[None, :, None] * dx[:, None], lower[:, None],
                             upper[:, None])
        f0 = np.einsum("bi,bi->b", x, 0.5 * (grad + g))
        f = np.einsum("bsi,bsi->bs", candidates,
                      0.5 * np.einsum("bij,bsj->bsi", H, candidates) + g[:, None])
        armijo = f <= f0[:, None] + 0.1 * np.einsum("bi,bsi->bs", grad,
                                                    candidates - x[:, None]) + 1e-15
        has_step = armijo.any(1)
        first = np.argmax(armijo, axis=1)
        x_new = candidates[np.arange(len(x)), first]
        moved = np.where(has_step, np.abs(x_new - x).max(-1), 0.0)
        x = np.where(has_step[:, None], x_new, x)
        if moved.max(initial=0.0) < 1e-12:
            break
    grad = g + np.einsum("bij,bj->bi", H, x)
    free = ~(((x <= lower) & (grad > 0)) | ((x >= upper) & (grad < 0)))
    return x, free


def backward_pass_reference(
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
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The recursion for a batch of problems; returns ``k, K, expected_decrease, ok``."""
    n_b, horizon, nz, nu = B.shape
    nx = nz + nu
    G = np.zeros((n_b, horizon, nz + 1, nx + 1))
    G[..., :nz, :nz] = A
    G[..., :nz, nz:nx] = B
    G[..., nz, nx] = 1.0
    G_T = np.ascontiguousarray(np.swapaxes(G, -1, -2))
    L = np.zeros((n_b, horizon, nx + 1, nx + 1))
    L[..., :nz, :nz] = l_zz
    L[..., nz:nx, nz:nx] = l_uu
    L[..., :nz, nx] = l_z[:, :-1]
    L[..., nz:nx, nx] = l_u
    L[..., nx, :nz] = l_z[:, :-1]
    L[..., nx, nz:nx] = l_u
    P = np.zeros((n_b, horizon, nx + 1, nz + 1))
    P[..., :nz, :nz] = np.eye(nz)
    P[..., nx, nz] = 1.0
    P_T = np.swapaxes(P, -1, -2)
    W = np.zeros((n_b, nz + 1, nz + 1))
    W[:, :nz, :nz] = l_zz_terminal
    W[:, :nz, nz] = l_z[:, -1]
    W[:, nz, :nz] = l_z[:, -1]
    ok = np.ones(n_b, dtype=bool)
    lower_all = action_low - u
    upper_all = action_high - u
    eye_u = np.eye(nu)
    gain_columns = np.r_[:nz, nx]
    for t in range(horizon - 1, -1, -1):
        Q = G_T[:, t] @ W @ G[:, t] + L[:, t]
        Q_uz, Q_uu, Q_u = Q[:, nz:nx, :nz], Q[:, nz:nx, nz:nx], Q[:, nz:nx, nx]
        lower, upper = lower_all[:, t], upper_all[:, t]
        H = Q_uu + mu[:, None, None] * eye_u
        try:
            np.linalg.cholesky(H)
        except np.linalg.LinAlgError:
            H, good = _positive_definite_or_identity(H)
            ok &= good
        try:
            gains = -np.linalg.solve(H, Q[:, nz:nx][..., gain_columns])
        except np.linalg.LinAlgError:
            # Positive definite in floating point yet numerically singular (e.g. huge
            # finite-difference Jacobians): such problems count as a failed pass.
            H, good = _positive_definite_or_identity(H)
            ok &= good
            gains = -np.linalg.solve(H, Q[:, nz:nx][..., gain_columns])
        k_t, K_t = gains[..., nz], gains[..., :nz]
        if ((k_t < lower) | (k_t > upper)).any():
            k_t, free = box_qp(H, Q_u, lower, upper, k_t)
            both_free = free[:, :, None] & free[:, None, :]
            H_free = np.where(both_free, H, eye_u)
            K_t = -np.linalg.solve(H_free, Q_uz * free[:, :, None])
        P[:, t, nz:nx, :nz] = K_t
        P[:, t, nz:nx, nz] = k_t
        W = P_T[:, t] @ Q @ P[:, t]
        W = 0.5 * (W + np.swapaxes(W, -1, -2))
    k = np.ascontiguousarray(P[..., nz:nx, nz])
    K = np.ascontiguousarray(P[..., nz:nx, :nz])
    return k, K, -0.5 * W[:, nz, nz], ok


def _positive_definite_or_identity(H: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Replace the matrices of ``H`` that are not safely positive definite by the identity.

    Safe means finite, with the smallest eigenvalue above ``1e-12`` times the largest, so that
    a linear solve with it is well conditioned. Returns the matrices and which were kept.
    """
    finite = np.isfinite(H).all((-1, -2))
    eig = np.linalg.eigvalsh(np.where(finite[:, None, None], H, np.eye(H.shape[-1])))
    good = finite & (eig[:, 0] > 1e-12 * np.maximum(eig[:, -1], 1.0))
    return np.where(good[:, None, None], H, np.eye(H.shape[-1])), good
