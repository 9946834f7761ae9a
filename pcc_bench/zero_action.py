"""The controller that always applies a zero action: the floor beside the oracle's ceiling."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np


def contains_zero_action(action_space: gym.spaces.Box) -> bool:
    """Whether the zero action lies inside the bounds of ``action_space``."""
    return bool(np.all((action_space.low <= 0.0) & (action_space.high >= 0.0)))


class ZeroActionPolicy:
    """An SB3-style policy that always returns the zero action (batched, like a VecEnv's)."""

    def __init__(self, action_space: gym.spaces.Box) -> None:
        if not contains_zero_action(action_space):
            raise ValueError(f"the zero action is outside the action space {action_space}")
        self.action_shape = action_space.shape

    def predict(self, observation: Any, state: Any = None, episode_start: Any = None,
                deterministic: bool = True) -> tuple[np.ndarray, None]:
        """Zeros for each observation of the batch (SB3's ``predict`` signature)."""
        batch = len(observation) if isinstance(observation, np.ndarray) else 1
        return np.zeros((batch, *self.action_shape), dtype=np.float32), None


def zero_action_percentages(env_id: str, task_seed_list: Sequence[int],
                            noise_std: float = 0.0) -> list[float]:
    """Per-task percentage of steps in goal with zero actions, one per task seed.

    Raises ``ValueError`` if the env's action space does not contain the zero action.
    """
    from pcc_agent.evaluation import evaluate_control

    env_kwargs = {"noise_std": noise_std} if noise_std else None
    ev = evaluate_control(lambda env: ZeroActionPolicy(env.action_space), env_id,
                          list(task_seed_list), env_kwargs=env_kwargs, record_states=False)
    return ev.percentages.tolist()
