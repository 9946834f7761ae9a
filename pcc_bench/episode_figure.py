"""A picture of one controlled episode: what the agent saw, step by step, and when it was in goal.

The main job (``pcc reproduce``) draws one for the best model of each row, so that a user sees
a controller working, not only a percentage. The strip shows the current camera frame at
evenly spaced steps (a green border when the true state is in the goal region, red when not),
the goal image last, and the episode's percentage of steps in goal in the title.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from pcc_agent.io import atomic_save_figure


def run_episode(agent: Any, env_id: str, seed: int,
                env_kwargs: dict[str, Any] | None = None) -> tuple[list[np.ndarray], list[bool]]:
    """One episode of ``agent`` on task ``seed``: the current frame and ``in_goal`` per step.

    The first entry is the start (before any action), so there is one frame more than steps.
    """
    if env_id.startswith("pcc/"):
        import pcc_envs  # noqa: F401  (registers the pcc/ ids)

    env = gym.make(env_id, **(env_kwargs or {}))
    try:
        obs, info = env.reset(seed=int(seed))
        frames, in_goal = [np.asarray(obs)[-1]], [bool(info.get("in_goal", False))]
        state, start, done = None, True, False
        while not done:
            action, state = agent.predict(obs, state=state, episode_start=np.array([start]),
                                          deterministic=True)
            start = False
            obs, _reward, terminated, truncated, info = env.step(action)
            frames.append(np.asarray(obs)[-1])
            in_goal.append(bool(info["in_goal"]))
            done = terminated or truncated
    finally:
        env.close()
    return frames, in_goal


def plot_controlled_episode(agent: Any, env_id: str, seed: int, path: str | Path,
                            num_frames: int = 8,
                            env_kwargs: dict[str, Any] | None = None) -> float:
    """Draw one controlled episode of ``agent`` to ``path``; return its % of steps in goal.

    Args:
        agent: A trained agent with SB3's ``predict`` and a ``goal_observation``.
        env_id: The env to run (a registered id).
        seed: The task seed (the start state).
        path: PNG file to write (atomically).
        num_frames: Frames of the strip (evenly spaced over the episode, first and last kept).
        env_kwargs: Keyword arguments of ``gym.make``.
    """
    if num_frames < 2:
        raise ValueError(f"num_frames must be at least 2, got {num_frames}.")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    frames, in_goal = run_episode(agent, env_id, seed, env_kwargs)
    steps = len(frames) - 1
    percent = 100.0 * sum(in_goal[1:]) / max(steps, 1)
    shown = sorted({int(round(i)) for i in np.linspace(0, steps, num_frames)})
    goal = getattr(agent, "goal_observation", None)
    panels = len(shown) + (goal is not None)
    fig, axes = plt.subplots(1, panels, figsize=(1.6 * panels, 2.1), squeeze=False)
    for ax, t in zip(axes[0], shown):
        ax.imshow(frames[t], cmap="gray", vmin=0, vmax=255)
        colour = "tab:green" if in_goal[t] else "tab:red"
        ax.set_title(f"step {t}", fontsize=8, color=colour)
        for spine in ax.spines.values():
            spine.set_edgecolor(colour)
            spine.set_linewidth(3)
    if goal is not None:
        ax = axes[0][-1]
        ax.imshow(np.asarray(goal)[-1], cmap="gray", vmin=0, vmax=255)
        ax.set_title("goal", fontsize=8)
    for ax in axes[0]:
        ax.set_xticks([])
        ax.set_yticks([])
    fig.suptitle(f"{env_id}, task seed {seed}: {percent:.1f}% of steps in goal "
                 "(green: in goal, red: not)", fontsize=9)
    fig.tight_layout()
    atomic_save_figure(fig, path, dpi=110)
    plt.close(fig)
    return percent
