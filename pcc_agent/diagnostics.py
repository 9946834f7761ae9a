"""Diagnostics of a trained embedding, measured on transitions, before any control is run.

Latent iLQR plans by rolling the latent dynamics forward from the encoded observation, so it
needs two things of the model: the dynamics must agree with the encoder along real
transitions (the paper's *consistency*), and they must be close to linear at the scale of a
planning step (the paper's *curvature*). :func:`latent_diagnostics` measures both on held-out
transitions:

* ``consistency_error``: ``|| f(mu(x_t), u_t) - mu(x_{t+1}) ||^2`` averaged over the
  transitions and divided by ``latent_scale^2``, so models with latent spaces of different
  sizes compare. ``f`` is the mean of the latent dynamics and ``mu`` the encoder mean.
* ``curvature``: the curvature loss ``R_LLC`` of the training objective,
  ``|| f(z + e_z, u + e_u) - (A e_z + B e_u) - f(z, u) ||^2`` with ``e ~ N(0, delta^2 I)``
  at ``z = mu(x_t)``. It comes from :func:`pcc_agent.losses.curvature_penalty`, with the true
  Jacobians, for every method.
* ``latent_scale``: the mean per-dimension standard deviation of ``mu(x_t)``.

It also needs the latent code to carry the state. :func:`state_decodability` measures, for
each true-state coordinate, how well the encoder mean determines it (a nearest-neighbour
regression, so any smooth one-to-one code counts, not only a linear one). Image pairs carry
velocities only through small frame-to-frame shifts; a code without them cannot balance a
cart-pole however good its dynamics are.

A balancing task adds one more need. Its goal is an equilibrium of the true system, often an
unstable one (an upright pole is a saddle), and a planner that linearizes the learned dynamics
holds the goal only if they reproduce that. :func:`goal_linearization` linearizes the learned
dynamics at the goal's code with no action; :func:`true_goal_linearization` does the same for
the env's true dynamics, for comparison.

The planner's cost is the squared latent distance to the goal's code, looked at over a short
window. :func:`goal_path_barrier` measures how far that distance climbs along the straight
state-space path from a task's start to the goal: where it climbs, the start looks like a
local minimum to a short window, even when every other diagnostic is good.
:func:`goal_aliasing` asks whether the states coded nearest the goal's code are near the goal
at all: where the latent map folds, a distant state shares the goal's low cost.

On Planar (``pcc_bench/latent_diagnostics.py``, docs/training.md) the consistency error
tells the models that control well from those that do not.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import torch

from pcc_agent.losses import curvature_penalty
from pcc_agent.model import EmbeddingModel

__all__ = [
    "GoalLinearization",
    "GoalPrediction",
    "LatentDiagnostics",
    "goal_linearization",
    "goal_path_barrier",
    "goal_prediction",
    "knn_decodability",
    "largest_climb",
    "latent_diagnostics",
    "state_decodability",
    "true_goal_linearization",
]


@contextlib.contextmanager
def _eval_mode(model: EmbeddingModel) -> Iterator[None]:
    """Run the body with ``model`` in eval mode, restoring its train/eval mode after."""
    was_training = model.training
    model.eval()
    try:
        yield
    finally:
        model.train(was_training)


@dataclass(frozen=True)
class LatentDiagnostics:
    """What :func:`latent_diagnostics` measured (see the module docstring)."""

    latent_scale: float
    consistency_error: float
    curvature: float
    num_samples: int

    def to_dict(self) -> dict[str, Any]:
        """JSON-friendly representation."""
        return asdict(self)


def latent_diagnostics(
    model: EmbeddingModel,
    obs: np.ndarray,
    action: np.ndarray,
    next_obs: np.ndarray,
    delta: float = 0.1,
    seed: int = 0,
    batch_size: int = 500,
) -> LatentDiagnostics:
    """Consistency error, curvature and latent scale of ``model`` on transitions.

    Args:
        model: A trained embedding model (any method).
        obs: Observations ``uint8 (N, *obs_shape)``; best held out from the training data.
        action: Actions ``(N, action_dim)`` in the model's action scale.
        next_obs: Next observations, like ``obs``.
        delta: Standard deviation of the curvature perturbations (the training's 0.1).
        seed: Seed of the perturbations.
        batch_size: Transitions per forward pass.

    Returns:
        The :class:`LatentDiagnostics`.
    """
    if not (len(obs) == len(action) == len(next_obs)) or len(obs) == 0:
        raise ValueError(
            f"Need the same non-zero number of observations, actions and next observations, "
            f"got {len(obs)}, {len(action)} and {len(next_obs)}."
        )
    if tuple(obs.shape[1:]) != model.obs_shape or tuple(next_obs.shape[1:]) != model.obs_shape:
        raise ValueError(
            f"Observations have shapes {obs.shape[1:]} and {next_obs.shape[1:]}, the model "
            f"expects {model.obs_shape}."
        )
    if action.ndim != 2 or action.shape[1] != model.action_dim:
        raise ValueError(f"Actions must be (N, {model.action_dim}), got {action.shape}.")
    device = next(model.parameters()).device
    generator = torch.Generator().manual_seed(seed)
    means, errors, curvatures = [], [], []
    with _eval_mode(model):
        for start in range(0, len(obs), batch_size):
            part = slice(start, start + batch_size)
            x_t = torch.as_tensor(obs[part], device=device)
            x_next = torch.as_tensor(next_obs[part], device=device)
            u = torch.as_tensor(action[part], dtype=torch.float32, device=device)
            with torch.no_grad():
                mu_t = model.encode(x_t)[0]
                mu_next = model.encode(x_next)[0]
                predicted = model.transition_mean(mu_t, u)
            eps_z = delta * torch.randn(mu_t.shape, generator=generator).to(device)
            eps_u = delta * torch.randn(u.shape, generator=generator).to(device)
            residual = curvature_penalty(model.transition_mean, mu_t, u, eps_z, eps_u)
            means.append(mu_t)
            errors.append((predicted - mu_next).pow(2).sum(-1))
            curvatures.append(residual.detach())
    latent = torch.cat(means)
    scale = float(latent.std(dim=0).mean()) if len(latent) > 1 else 1.0
    return LatentDiagnostics(
        latent_scale=scale,
        consistency_error=float(torch.cat(errors).mean()) / max(scale, 1e-12) ** 2,
        curvature=float(torch.cat(curvatures).mean()),
        num_samples=len(obs),
    )


#: Signature of an env's ``state_error(state, reference)``: ``state - reference`` (batched),
#: with angular coordinates wrapped.
StateError = Callable[[np.ndarray, np.ndarray], np.ndarray]


def _subtract(state: np.ndarray, reference: np.ndarray) -> np.ndarray:
    return np.asarray(state, dtype=np.float64) - reference


def knn_decodability(
    latent: np.ndarray,
    states: np.ndarray,
    state_error: StateError | None = None,
    neighbours: int = 10,
    fit_fraction: float = 2.0 / 3.0,
    chunk_size: int = 256,
) -> np.ndarray:
    """Per state coordinate, the R^2 of a k-nearest-neighbour regression from the latent code.

    The first ``fit_fraction`` of the rows are the reference set, the rest are predicted: each
    state is estimated as the mean of the states of its ``neighbours`` nearest reference codes,
    in the whitened latent space (so a coordinate carried by a low-variance latent direction
    still counts). ``R^2 = 1 - mean squared error / variance`` per coordinate: about 1 when the
    code determines the coordinate, about 0 (or below) when it carries nothing of it.

    Args:
        latent: Codes ``(N, n_z)``, e.g. encoder means.
        states: True states ``(N, d)`` of the same rows.
        state_error: ``state_error(a, b)`` = ``a - b`` with angles wrapped (an env's
            ``state_error``); default plain subtraction.
        neighbours: k of the k-NN regression.
        fit_fraction: Fraction of the rows used as the reference set.
        chunk_size: Predicted rows per distance computation (bounds memory).

    Returns:
        ``(d,)`` float64 array of R^2 values.
    """
    latent = np.asarray(latent, dtype=np.float64)
    states = np.asarray(states, dtype=np.float64)
    if latent.ndim != 2 or states.ndim != 2 or len(latent) != len(states):
        raise ValueError(
            f"Need latent codes (N, n_z) and states (N, d) with the same N, got shapes "
            f"{latent.shape} and {states.shape}."
        )
    num_fit = int(len(latent) * fit_fraction)
    if num_fit < neighbours or len(latent) - num_fit < 2 or neighbours < 1:
        raise ValueError(
            f"{len(latent)} rows with fit_fraction {fit_fraction} leave {num_fit} reference and "
            f"{len(latent) - num_fit} predicted rows; need at least neighbours={neighbours} "
            "reference rows and 2 predicted ones."
        )
    error = state_error or _subtract
    centred = latent - latent[:num_fit].mean(axis=0)
    eigval, eigvec = np.linalg.eigh(np.atleast_2d(np.cov(centred[:num_fit].T)))
    keep = eigval > max(eigval.max(), 1e-300) * 1e-10
    white = centred @ eigvec[:, keep] / np.sqrt(eigval[keep])
    reference, query = white[:num_fit], white[num_fit:]
    ref_states, query_states = states[:num_fit], states[num_fit:]
    residuals = []
    for start in range(0, len(query), chunk_size):
        part = query[start:start + chunk_size]
        dist = ((part[:, None, :] - reference[None, :, :]) ** 2).sum(-1)
        nearest = np.argpartition(dist, neighbours - 1, axis=1)[:, :neighbours]
        target = query_states[start:start + chunk_size]
        offsets = error(ref_states[nearest].reshape(-1, states.shape[1]),
                        np.repeat(target, neighbours, axis=0))
        residuals.append(offsets.reshape(len(part), neighbours, -1).mean(axis=1))
    mse = (np.concatenate(residuals) ** 2).mean(axis=0)
    spread = error(query_states, np.broadcast_to(query_states.mean(axis=0), query_states.shape))
    variance = spread.var(axis=0)
    return 1.0 - mse / np.maximum(variance, 1e-300)


def state_decodability(
    model: EmbeddingModel,
    obs: np.ndarray,
    states: np.ndarray,
    state_error: StateError | None = None,
    neighbours: int = 10,
    batch_size: int = 500,
) -> np.ndarray:
    """:func:`knn_decodability` of the true states from the encoder means of ``obs``.

    Args:
        model: A trained embedding model.
        obs: Observations ``uint8 (N, *obs_shape)``, best held out from the training data.
        states: The true states ``(N, d)`` behind them (``TransitionDataset.state``).
        state_error: The env's ``state_error`` (wraps angles); default plain subtraction.
        neighbours: k of the k-NN regression.
        batch_size: Observations per forward pass.

    Returns:
        ``(d,)`` R^2 per state coordinate (1: determined by the code; 0: absent from it).
    """
    return knn_decodability(_encoder_means(model, obs, batch_size), states, state_error,
                            neighbours)


def _encoder_means(model: EmbeddingModel, obs: np.ndarray, batch_size: int = 500) -> np.ndarray:
    """The encoder means of ``obs`` ``(N, *obs_shape)`` as a ``(N, n_z)`` float64 array."""
    if tuple(obs.shape[1:]) != model.obs_shape:
        raise ValueError(f"Observations have shape {obs.shape[1:]}, the model expects "
                         f"{model.obs_shape}.")
    device = next(model.parameters()).device
    with _eval_mode(model), torch.no_grad():
        codes = [model.encode(torch.as_tensor(obs[i:i + batch_size], device=device))[0].cpu()
                 for i in range(0, len(obs), batch_size)]
    return torch.cat(codes).numpy().astype(np.float64)


def goal_aliasing(
    model: EmbeddingModel,
    obs: np.ndarray,
    states: np.ndarray,
    goal_obs: np.ndarray,
    goal_state: np.ndarray,
    state_error: StateError | None = None,
    neighbours: int = 10,
    batch_size: int = 500,
) -> float:
    """How far from the goal, in state space, lie the states whose codes are nearest the goal's.

    The planner steers to the goal's code. If the encoder maps some distant states next to it
    (a fold of the latent map), the planner can settle there: the latent cost is as low as at
    the goal. This takes the ``neighbours`` observations whose encoder means are nearest the
    goal observation's, and returns the largest distance of their true states from the goal
    state, divided by the median distance of all ``states`` from it: near 0 when all the
    goal's latent neighbours are its state neighbours, near 1 or above when one of them is as
    far as a typical state (a fold). Distances are Euclidean norms of
    ``state_error(state, goal_state)``.

    Args:
        model: A trained embedding model.
        obs: Observations ``uint8 (N, *obs_shape)``, e.g. held-out uniform samples.
        states: The true states ``(N, d)`` behind them.
        goal_obs: The goal observation the planner steers to (``agent.goal_observation``).
        goal_state: The env's goal state ``(d,)``.
        state_error: The env's ``state_error`` (wraps angles); default plain subtraction.
        neighbours: How many latent neighbours of the goal to look at.
        batch_size: Observations per forward pass.

    Returns:
        The aliasing ratio, at least 0.
    """
    states = np.asarray(states, dtype=np.float64)
    goal_state = np.asarray(goal_state, dtype=np.float64)
    if states.ndim != 2 or len(states) != len(obs) or states.shape[1:] != goal_state.shape:
        raise ValueError(f"Need states (N, d) for the N={len(obs)} observations and a goal "
                         f"state (d,), got shapes {states.shape} and {goal_state.shape}.")
    if not 1 <= neighbours <= len(obs):
        raise ValueError(f"neighbours must be between 1 and the {len(obs)} observations, got "
                         f"{neighbours}.")
    codes = _encoder_means(model, obs, batch_size)
    goal_code = _encoder_means(model, np.asarray(goal_obs)[None], batch_size)[0]
    nearest = np.argsort(np.linalg.norm(codes - goal_code, axis=1), kind="stable")[:neighbours]
    error = state_error or _subtract
    from_goal = np.linalg.norm(error(states, np.broadcast_to(goal_state, states.shape)), axis=1)
    return float(from_goal[nearest].max() / max(float(np.median(from_goal)), 1e-300))


@dataclass(frozen=True)
class GoalLinearization:
    """Dynamics ``x' = f(x, u)`` linearized at the goal with zero action.

    ``A = df/dx`` and ``B = df/du`` at ``(x_g, 0)``.

    Attributes:
        drift: ``|| f(x_g, 0) - x_g ||`` divided by the given scale: how far one step with no
            action moves the goal (0 at an equilibrium).
        spectral_radius: Largest eigenvalue modulus of ``A``; above 1 the goal is unstable
            (per step, so it depends on the control period).
        eigenvalue_moduli: All eigenvalue moduli of ``A``, largest first.
        controllability: Singular values of ``[B, AB, ..., A^(n-1) B]`` divided by the
            largest, in decreasing order: near-zero values are directions the action
            (almost) cannot move.
    """

    drift: float
    spectral_radius: float
    eigenvalue_moduli: tuple[float, ...]
    controllability: tuple[float, ...]

    def to_dict(self) -> dict[str, Any]:
        """JSON-friendly representation."""
        return asdict(self)


def _linearization(
    drift: float, A: np.ndarray, B: np.ndarray  # noqa: N803 (control notation)
) -> GoalLinearization:
    moduli = np.sort(np.abs(np.linalg.eigvals(A)))[::-1]
    blocks, power = [], np.eye(len(A))
    for _ in range(len(A)):
        blocks.append(power @ B)
        power = A @ power
    singular = np.linalg.svd(np.hstack(blocks), compute_uv=False)
    relative = singular / singular[0] if singular[0] > 0 else singular
    return GoalLinearization(
        drift=float(drift),
        spectral_radius=float(moduli[0]),
        eigenvalue_moduli=tuple(float(v) for v in moduli),
        controllability=tuple(float(v) for v in relative),
    )


def goal_linearization(
    model: EmbeddingModel, goal_obs: np.ndarray, scale: float = 1.0
) -> GoalLinearization:
    """The learned latent dynamics linearized at the goal's code ``z_g = mu(goal_obs)``.

    Args:
        model: A trained embedding model.
        goal_obs: The goal observation ``uint8 obs_shape`` (the agent's or the env's
            ``goal_observation()``).
        scale: Divides the drift, e.g. ``LatentDiagnostics.latent_scale`` so that models
            with latent spaces of different sizes compare.

    Returns:
        The :class:`GoalLinearization` of the latent dynamics' mean at ``(z_g, 0)``.
    """
    goal_obs = np.asarray(goal_obs)
    if tuple(goal_obs.shape) != model.obs_shape:
        raise ValueError(f"The goal observation has shape {goal_obs.shape}, the model expects "
                         f"{model.obs_shape}.")
    if not scale > 0:
        raise ValueError(f"scale must be > 0, got {scale!r}.")
    device = next(model.parameters()).device
    with _eval_mode(model):
        with torch.no_grad():
            goal = model.encode(torch.as_tensor(goal_obs[None], device=device))[0]
            still = torch.zeros(1, model.action_dim, device=device)
            drift = float((model.transition_mean(goal, still) - goal).norm()) / scale
        A, B = model.planner_dynamics().jacobians(goal, still)  # noqa: N806
    return _linearization(drift, A[0].detach().cpu().double().numpy(),
                          B[0].detach().cpu().double().numpy())


def true_goal_linearization(env: Any, fd_step: float = 1e-5) -> GoalLinearization:
    """The env's true dynamics linearized at its goal state (central finite differences).

    Args:
        env: A ``pcc_envs`` env with cheap batched true dynamics (``supports_oracle``),
            wrapped or not.
        fd_step: Central-difference step.

    Returns:
        The :class:`GoalLinearization` of the true one-step map at ``(goal_state, 0)``; its
        drift is in state units.
    """
    from pcc_agent.oracle import TrueDynamics

    base = getattr(env, "unwrapped", env)
    dynamics = TrueDynamics(base, fd_step)
    goal = torch.as_tensor(np.asarray(base.goal_state, dtype=np.float64)[None])
    still = torch.zeros(1, base.action_space.shape[0], dtype=torch.float64)
    moved = base.state_error(dynamics.step(goal, still).numpy(), goal.numpy())
    A, B = dynamics.jacobians(goal, still)  # noqa: N806
    return _linearization(float(np.linalg.norm(moved)), A[0].numpy(), B[0].numpy())


@dataclass(frozen=True)
class GoalPrediction:
    """How well the learned latent dynamics predict, and feel the action, near the goal.

    Attributes:
        error_over_hold: Open-loop prediction error after ``horizon`` steps,
            ``mean || z_hat_k - mu(x_k) ||``, over the error of predicting that nothing
            moves, ``mean || mu(x_0) - mu(x_k) ||``: below 1 the model beats standing still.
        action_effect: The action's one-step effect on the prediction,
            ``mean || f(z_0, u_0) - f(z_0, 0) ||``, over the one-step prediction error
            ``mean || f(z_0, u_0) - mu(x_1) ||``: well below 1, the planner steers a system
            whose response to the action is lost in the model's error.
        horizon: Steps of the open-loop prediction.
        num_starts: Start states the means are over.
    """

    error_over_hold: float
    action_effect: float
    horizon: int
    num_starts: int

    def to_dict(self) -> dict[str, Any]:
        """JSON-friendly representation."""
        return asdict(self)


def goal_prediction(
    model: EmbeddingModel,
    env: Any,
    horizon: int = 10,
    num_starts: int = 200,
    spread: float = 0.1,
    seed: int = 0,
) -> GoalPrediction:
    """Open-loop prediction and the action's effect of the learned dynamics near the goal.

    The starts are the env's goal state moved by ``U(-spread, spread)`` times the half-width
    of its sampler box in every coordinate (kept inside the box); the actions are uniform in
    ``[-1, 1]``. The true
    trajectories come from the env's ``transition`` (its true dynamics, no noise); every
    true state is rendered (``observations_of``) and encoded, and the model's mean dynamics
    roll the start's code forward with the same actions. Near the goal a balancing task's
    states move little per step, so a model that fits the sampler's fast motions can still
    predict worse than standing still there; this measures it.

    Args:
        model: A trained embedding model.
        env: A ``pcc_envs`` environment with cheap true dynamics (``supports_oracle``;
            wrapped or not).
        horizon: Steps of the open-loop prediction.
        num_starts: Start states.
        spread: Size of the start region, as a share of the sampler box's half-width.
        seed: Seed of the starts and actions.

    Returns:
        The :class:`GoalPrediction`.
    """
    core = getattr(env, "unwrapped", env)
    if not getattr(core, "supports_oracle", False) or not all(
            hasattr(core, name) for name in ("goal_state", "state_low", "state_high",
                                             "transition", "observations_of")):
        raise ValueError("goal_prediction needs a pcc_envs environment with cheap true "
                         "dynamics (supports_oracle, goal_state, a sampler box, transition).")
    if horizon < 1 or num_starts < 1 or not spread > 0:
        raise ValueError(f"horizon and num_starts must be >= 1 and spread > 0, got "
                         f"{horizon}, {num_starts}, {spread}.")
    rng = np.random.default_rng(seed)
    low, high = np.asarray(core.state_low), np.asarray(core.state_high)
    goal = np.asarray(core.goal_state, dtype=np.float64)
    offsets = rng.uniform(-spread, spread, (num_starts, goal.size)) * ((high - low) / 2.0)
    states = np.clip(goal + offsets, low, high)
    actions = rng.uniform(-1.0, 1.0, (horizon, num_starts, model.action_dim))
    trajectory = [states]
    for step_actions in actions:
        trajectory.append(core.transition(trajectory[-1], step_actions))
    device = next(model.parameters()).device

    def codes(batch: np.ndarray) -> torch.Tensor:
        obs = torch.as_tensor(core.observations_of(batch), device=device)
        return model.encode(obs)[0]

    with _eval_mode(model), torch.no_grad():
        start = codes(trajectory[0])
        u = torch.as_tensor(actions, dtype=start.dtype, device=device)
        first = model.transition_mean(start, u[0])
        idle = model.transition_mean(start, torch.zeros_like(u[0]))
        one_step_error = (first - codes(trajectory[1])).norm(dim=1).mean()
        action_effect = float((first - idle).norm(dim=1).mean() / one_step_error)
        predicted = start
        for k in range(horizon):
            predicted = model.transition_mean(predicted, u[k])
        last = codes(trajectory[-1])
        error = (predicted - last).norm(dim=1).mean()
        hold = (start - last).norm(dim=1).mean()
    return GoalPrediction(error_over_hold=float(error / hold), action_effect=action_effect,
                          horizon=horizon, num_starts=num_starts)


def largest_climb(values: Any) -> float:
    """The largest rise of a sequence above its running minimum (0 if it never rises)."""
    x = np.asarray(values, dtype=np.float64).ravel()
    return float((x - np.minimum.accumulate(x)).max()) if x.size else 0.0


def goal_path_barrier(
    model: EmbeddingModel,
    env: Any,
    start_state: np.ndarray,
    goal_obs: np.ndarray,
    scale: float = 1.0,
    num_points: int = 41,
) -> float:
    """How far the latent distance to the goal climbs on the way from a start to the goal.

    The states ``s(a) = start + a * d``, ``a`` in ``[0, 1]``, form a straight path in state
    space from the start to the goal (all coordinates, velocities included, interpolated).
    ``d`` is ``state_error(goal_state, start)``; an angular coordinate (one the env's
    ``state_error`` wraps) can also go the other way round, and every combination of ways
    is tried. Each path is rendered with the env's ``observations_of`` and encoded; its
    barrier is :func:`largest_climb` of ``|| mu(x(s(a))) - mu(goal_obs) ||`` along it. The
    result is the lowest barrier of the paths, divided by ``scale``: 0 means the planner's
    cost falls all the way to the goal on some path; a value near 1 means a hill of the
    latent scale's size on every one, which a short planning window does not see past.

    Args:
        model: A trained embedding model.
        env: A ``pcc_envs`` environment (``goal_state``, ``state_error``, ``observations_of``
            on it or on ``env.unwrapped``).
        start_state: The task's start state ``(d,)``.
        goal_obs: The goal observation the planner steers to (``agent.goal_observation``).
        scale: Divides the result (e.g. :attr:`LatentDiagnostics.latent_scale`).
        num_points: States on each path, both ends included.

    Returns:
        The barrier height in units of ``scale``.
    """
    core = getattr(env, "unwrapped", env)
    if not all(hasattr(core, name) for name in ("goal_state", "state_error",
                                                "observations_of")):
        raise ValueError("goal_path_barrier needs a pcc_envs environment (goal_state, "
                         "state_error and observations_of).")
    if num_points < 2:
        raise ValueError(f"num_points must be at least 2, got {num_points}.")
    goal_state = np.asarray(core.goal_state, dtype=np.float64)
    start = np.asarray(start_state, dtype=np.float64)
    if start.shape != goal_state.shape:
        raise ValueError(f"The start state has shape {start.shape}, the env's states "
                         f"{goal_state.shape}.")
    short_way = core.state_error(goal_state[None], start[None])[0]
    turns = 2.0 * np.pi * np.eye(goal_state.size)
    angular = np.abs(np.diagonal(core.state_error(goal_state[None] + turns, goal_state[None])))
    ways = [short_way]
    for i in np.flatnonzero(angular < 1e-9):  # the other way round each angle
        turn = np.zeros_like(short_way)
        turn[i] = -2.0 * np.pi * np.sign(short_way[i]) if short_way[i] else 2.0 * np.pi
        ways += [way + turn for way in ways]
    fractions = np.linspace(0.0, 1.0, num_points)[:, None]
    paths = np.concatenate([start + fractions * way for way in ways])
    observations = np.asarray(core.observations_of(paths), dtype=np.uint8)
    device = next(model.parameters()).device
    with _eval_mode(model), torch.no_grad():
        codes = model.encode(torch.as_tensor(observations, device=device))[0]
        goal = model.encode(torch.as_tensor(np.asarray(goal_obs)[None], device=device))[0]
    distances = (codes - goal).norm(dim=-1).cpu().numpy().reshape(len(ways), num_points)
    return min(largest_climb(path) for path in distances) / scale
