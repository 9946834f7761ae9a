"""The suite's registration table: one row per environment id."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym

__all__ = ["ENV_TABLE", "EnvRow", "register_all"]


@dataclass(frozen=True)
class EnvRow:
    """One registered environment: id, entry point, constructor kwargs and episode length."""

    env_id: str
    entry_point: str
    max_episode_steps: int
    kwargs: dict[str, Any] = field(default_factory=dict)


ENV_TABLE: tuple[EnvRow, ...] = (
    EnvRow("pcc/Planar-v0", "pcc_envs.planar:PlanarEnv", 40),
    EnvRow("pcc/PendulumSwingUp-v0", "pcc_envs.pendulum:PendulumEnv", 400, {"task": "swingup"}),
    EnvRow("pcc/PendulumBalance-v0", "pcc_envs.pendulum:PendulumEnv", 400, {"task": "balance"}),
    EnvRow("pcc/CartPole-v0", "pcc_envs.cartpole:CartPoleEnv", 200),
    EnvRow("pcc/CartPole-v1", "pcc_envs.cartpole:CartPoleEnv", 200, {"picture": "schematic"}),
    EnvRow("pcc/TwoLink-v0", "pcc_envs.manipulator:ManipulatorEnv", 400, {"num_links": 2}),
    EnvRow("pcc/ThreeLink-v0", "pcc_envs.manipulator:ManipulatorEnv", 400, {"num_links": 3}),
    EnvRow("pcc/ThreeLink-v1", "pcc_envs.manipulator:ManipulatorEnv", 400,
           {"num_links": 3, "domain": "pc3"}),
    EnvRow("pcc/LaneKeeping-v0", "pcc_envs.lane_keeping:LaneKeepingEnv", 200),
)


def register_all() -> None:
    """Register every row of :data:`ENV_TABLE` with Gymnasium (idempotent)."""
    for row in ENV_TABLE:
        if row.env_id in gym.registry:
            continue
        gym.register(
            id=row.env_id,
            entry_point=row.entry_point,
            max_episode_steps=row.max_episode_steps,
            kwargs=dict(row.kwargs),
        )
