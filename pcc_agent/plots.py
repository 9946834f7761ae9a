"""Latent maps (paper Figure 2): encode observations of a grid of true states, color by state.

The functions are generic: they take arrays of observations and of the true states they were
rendered from. Building those arrays needs the environment (e.g. ``env.unwrapped.render_state``
and the env's two-frame observation builder); :func:`observations_for_states` wires such
callables without this module importing ``pcc_envs``, and :func:`plot_env_latent_map` uses the
env protocol (``sample_states``, ``observations_of``) directly.

Matplotlib is used with the non-interactive Agg backend.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch

from pcc_agent.model import EmbeddingModel


def planar_grid(low: Sequence[float], high: Sequence[float], num: int = 20) -> np.ndarray:
    """Uniform grid of 2-D positions, ``(num * num, 2)``, row-major over (x, y)."""
    xs = np.linspace(low[0], high[0], num)
    ys = np.linspace(low[1], high[1], num)
    grid = np.stack(np.meshgrid(xs, ys, indexing="ij"), axis=-1)
    return grid.reshape(-1, 2)


def pendulum_grid(
    max_velocity: float, num_angles: int = 30, num_velocities: int = 10
) -> np.ndarray:
    """Grid of (angle, angular velocity) states, angles in [-pi, pi), ``(N, 2)``."""
    angles = np.linspace(-np.pi, np.pi, num_angles, endpoint=False)
    velocities = np.linspace(-max_velocity, max_velocity, num_velocities)
    grid = np.stack(np.meshgrid(angles, velocities, indexing="ij"), axis=-1)
    return grid.reshape(-1, 2)


def observations_for_states(
    states: np.ndarray, make_observation: Callable[[np.ndarray], np.ndarray]
) -> np.ndarray:
    """Render one observation per state with an env-provided callable.

    Args:
        states: ``(N, state_dim)``.
        make_observation: ``state -> uint8 (frames, H, W)`` (e.g. the env's two-frame builder,
            or ``lambda s: env.unwrapped.render_state(s)[None]`` for single-frame envs).

    Returns:
        uint8 ``(N, frames, H, W)``.
    """
    return np.stack([np.asarray(make_observation(s), dtype=np.uint8) for s in states])


def state_colors(states: np.ndarray, columns: Sequence[int] = (0, 1)) -> np.ndarray:
    """RGB colors from up to two state coordinates (hue from the first, brightness second)."""
    from matplotlib.colors import hsv_to_rgb

    def unit(values: np.ndarray) -> np.ndarray:
        span = values.max() - values.min()
        return (values - values.min()) / (span if span > 0 else 1.0)

    hue = unit(states[:, columns[0]]) * 0.85
    value = 0.35 + 0.65 * unit(states[:, columns[1]]) if len(columns) > 1 else np.ones_like(hue)
    return hsv_to_rgb(np.stack([hue, np.full_like(hue, 0.9), value], axis=-1))


@torch.no_grad()
def encode_observations(
    model: EmbeddingModel, observations: np.ndarray, batch_size: int = 512
) -> np.ndarray:
    """Latent means ``(N, n_z)`` of uint8 observations ``(N, frames, H, W)``."""
    device = next(model.parameters()).device
    was_training = model.training
    model.eval()
    means = []
    for start in range(0, len(observations), batch_size):
        batch = torch.from_numpy(np.ascontiguousarray(observations[start:start + batch_size]))
        means.append(model.encode(batch.to(device))[0].cpu().numpy())
    model.train(was_training)
    return np.concatenate(means, axis=0)


def plot_latent_map(
    model: EmbeddingModel,
    observations: np.ndarray,
    colors: np.ndarray,
    path: str | os.PathLike[str],
    title: str = "",
) -> Path:
    """Scatter the latent means of ``observations`` (3-D axes when n_z >= 3) and save a PNG.

    Args:
        model: Trained model.
        observations: uint8 ``(N, frames, H, W)``.
        colors: ``(N, 3)`` RGB in [0, 1] or ``(N,)`` scalars (see :func:`state_colors`).
        path: Output image path (parent directories are created).
        title: Figure title.

    Returns:
        The path written.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    latent = encode_observations(model, observations)
    fig = plt.figure(figsize=(5, 5))
    if latent.shape[1] >= 3:
        ax = fig.add_subplot(projection="3d")
        ax.scatter(latent[:, 0], latent[:, 1], latent[:, 2], c=colors, s=12)
        ax.set_zlabel("z3")
    else:
        ax = fig.add_subplot()
        ys = latent[:, 1] if latent.shape[1] > 1 else np.zeros(len(latent))
        ax.scatter(latent[:, 0], ys, c=colors, s=12)
    ax.set_xlabel("z1")
    ax.set_ylabel("z2")
    ax.set_title(title)
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=100, bbox_inches="tight")
    plt.close(fig)
    return out


def plot_env_latent_map(
    agent: Any,
    path: str | os.PathLike[str],
    title: str = "",
    env: Any = None,
    num_states: int = 800,
    seed: int = 0,
) -> Path:
    """Latent map of an agent's model for its environment (paper Figure 2).

    States are drawn with the environment's own uniform sampler (``env.unwrapped.
    sample_states``, so Planar's obstacles are avoided), rendered with
    ``env.unwrapped.observations_of`` (the env's frame-stacking rule), encoded, and colored by
    their first two coordinates (Planar: x, y; Pendulum: angle, angular velocity).

    Args:
        agent: An object with ``model`` (an :class:`EmbeddingModel`) and ``env`` attributes
            (e.g. ``PCCAgent``), or an :class:`EmbeddingModel` together with ``env``.
        path: Output PNG path.
        title: Figure title.
        env: The environment (defaults to ``agent.env``).
        num_states: Number of states drawn.
        seed: Seed of the state sampler.

    Returns:
        The path written.

    Raises:
        ValueError: The environment does not expose ``sample_states`` / ``observations_of``.
    """
    model = agent if isinstance(agent, EmbeddingModel) else agent.model
    env = env if env is not None else getattr(agent, "env", None)
    core = getattr(env, "unwrapped", env)
    if not (hasattr(core, "sample_states") and hasattr(core, "observations_of")):
        raise ValueError(
            "plot_env_latent_map needs a pcc_envs environment (env.unwrapped.sample_states and "
            "observations_of); for other envs build observations yourself and call "
            "plot_latent_map."
        )
    states = np.asarray(core.sample_states(np.random.default_rng(seed), num_states))
    observations = np.asarray(core.observations_of(states), dtype=np.uint8)
    columns = (0, 1) if states.shape[1] > 1 else (0,)
    return plot_latent_map(model, observations, state_colors(states, columns), path, title)
