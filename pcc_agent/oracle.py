"""The oracle controller: the agents' iLQR-MPC, on the TRUE state and TRUE dynamics.

It runs the planner settings the learned agents of that environment use (the env preset's
:class:`~pcc_agent.planning.config.PlannerConfig`: replanning interval, iterations, initial
plans, cost weights ``kappa``, ``r_weight``, ``terminal_weight``, and the horizon unless the
env's :class:`OracleConfig` names its own), but it plans with the environment's own
deterministic transition (``env.unwrapped.transition``, batched numpy) and central
finite-difference Jacobians, and its state cost is on the true state error. It is the
ceiling the benchmarks report beside the learned models.

Why the horizon may differ: a quadratic cost on the true state is shaped differently from a
learned latent distance. On CartPole-v1, 3-link v1 and lane keeping the agents do best with a
shorter plan than the oracle needs (docs/planner.md); there the oracle keeps the horizon it
was chosen with, so that it stays a ceiling rather than a copy of the agents' trade-off.

The oracle reads the true state from the environment it controls, so it is built for one env
instance: ``evaluate_control(lambda env: OracleController(env), env_id, seeds)``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from torch import Tensor

from pcc_agent.config import PlannerConfig
from pcc_agent.planning.cost import QuadraticCost
from pcc_agent.planning.mpc import LatentMPC

__all__ = [
    "ORACLE_CONFIGS",
    "OracleConfig",
    "OracleController",
    "TrueDynamics",
    "agent_planner_for",
    "oracle_config_for",
    "oracle_planner_for",
]


@dataclass(frozen=True)
class OracleConfig:
    """How the oracle weighs the TRUE state error of one environment.

    The oracle plans with the agents' own planner settings (horizon, replanning, iterations,
    candidates, ``kappa``, ``r_weight``, ``terminal_weight``: the env preset's
    :class:`PlannerConfig`); only the state in the cost differs. Its stage cost is
    ``kappa * (s - g)^T diag(state_weights) (s - g) + r_weight * |u|^2``, where a learned
    agent's is ``kappa * |z - z_goal|^2 + r_weight * |u|^2``.

    Attributes:
        state_weights: Relative weight of each true-state component (the learned agents'
            latent cost weighs all latent components alike; the true state mixes units, so
            angles, rates and positions get their own scale).
        fd_step: Step of the central finite differences of the true dynamics.
        plan_length: The oracle's own horizon, where the true-state cost needs another one
            than the agents' latent cost; ``None``: the agents' horizon.
    """

    state_weights: tuple[float, ...]
    fd_step: float = 1e-5
    plan_length: int | None = None

    def __post_init__(self) -> None:
        if self.plan_length is not None and self.plan_length < 1:
            raise ValueError(f"plan_length must be at least 1 (or None), got {self.plan_length}.")


_CARTPOLE = OracleConfig(state_weights=(1.0, 0.1, 0.1, 0.01))
# CartPole-v1's agents plan 20 steps (learned-model sweep); the oracle needs 50: 98.4% on
# validation tasks against 53.0% at 20 (planner_sweep/oracle_CartPole-v1.json).
_CARTPOLE_V1 = replace(_CARTPOLE, plan_length=50)

#: Per-environment oracle cost weights (data, not branches). Chosen with the true dynamics on
#: validation tasks (task seed 2021, never the evaluation tasks' 2020):
#: results/planner_sweep/oracle_*.json.
ORACLE_CONFIGS: dict[str, OracleConfig] = {
    # Contacts with the obstacles make the displacement map steep near grazing contact: a
    # wide central difference (in world units) gives usable slopes.
    "pcc/Planar-v0": OracleConfig(state_weights=(1.0, 1.0), fd_step=0.05),
    # Angle, angular velocity: a small rate weight lets the pendulum swing up fast.
    "pcc/PendulumSwingUp-v0": OracleConfig(state_weights=(1.0, 0.01)),
    "pcc/PendulumBalance-v0": OracleConfig(state_weights=(1.0, 0.1)),
    # Pole angle, pole rate, cart position, cart velocity (both pictures: the same physics).
    "pcc/CartPole-v0": _CARTPOLE,
    "pcc/CartPole-v1": _CARTPOLE_V1,
    # Joint angles, then joint rates. Rate weight 0.01 against 0.1: 93.5% vs 87.2% (2-link),
    # 91.5% vs 89.0% (3-link) at T = 60; a heavy rate weight slows the pumping swing-up.
    "pcc/TwoLink-v0": OracleConfig(state_weights=(1.0, 1.0, 0.01, 0.01)),
    "pcc/ThreeLink-v0": OracleConfig(state_weights=(1.0, 1.0, 1.0, 0.01, 0.01, 0.01)),
    # v1's agents plan 20 steps (learned-model sweep); the oracle keeps 60: 93.1% against
    # 90.9% at 10 on validation starts (planner_sweep/oracle_ThreeLink-v1.json).
    "pcc/ThreeLink-v1": OracleConfig(state_weights=(1.0, 1.0, 1.0, 0.01, 0.01, 0.01),
                                     plan_length=60),
    # Lateral offset (m), heading (rad), speed (m/s; held by the wheel servos, not steerable).
    # Bullet's contacts make the re-posed map rough at small scales: a 1 mm / 1 mrad step.
    # The agents plan 10 steps (learned-model sweep); the oracle keeps 20: 72.7% against 71.9%.
    "pcc/LaneKeeping-v0": OracleConfig(state_weights=(1.0, 1.0, 0.0), fd_step=1e-3,
                                       plan_length=20),
}


def agent_planner_for(env_id: str) -> PlannerConfig:
    """The planner settings the learned agents of a registered environment use."""
    from pcc_agent.presets import get_preset

    return get_preset(env_id).planner


def oracle_planner_for(env_id: str, config: OracleConfig | None = None) -> PlannerConfig:
    """The planner settings the oracle of a registered environment runs.

    The agents' settings (:func:`agent_planner_for`), with the horizon of ``config`` (default:
    the env's :data:`ORACLE_CONFIGS` entry) where it names one.
    """
    config = oracle_config_for(env_id) if config is None else config
    planner = agent_planner_for(env_id)
    if config.plan_length is None:
        return planner
    return replace(planner, plan_length=config.plan_length)


def oracle_config_for(env_id: str) -> OracleConfig:
    """The oracle settings of a registered environment."""
    try:
        return ORACLE_CONFIGS[env_id]
    except KeyError:
        raise ValueError(
            f"No oracle settings for {env_id!r}; known: {sorted(ORACLE_CONFIGS)}. "
            "Pass an OracleConfig to OracleController for another env."
        ) from None


class TrueDynamics:
    """The env's true transition as planner dynamics, with finite-difference Jacobians.

    Args:
        env: An env following the pcc_envs protocol (``transition`` batched over states,
            ``state_error`` wrapping angles). Envs whose ``transition`` loops over a batch
            in a simulator (``supports_oracle`` False: LaneKeeping's Bullet, about 1 ms a
            state) work too, only slower.
        fd_step: Central-difference step.
    """

    def __init__(self, env: Any, fd_step: float = 1e-5) -> None:
        missing = [name for name in ("transition", "state_error", "goal_state")
                   if not hasattr(env, name)]
        if missing:
            raise ValueError(
                f"{type(env).__name__} lacks {missing} of the pcc_envs protocol; the oracle "
                "needs the env's true transition to plan on it."
            )
        self.env = env
        self.fd_step = fd_step

    def step(self, z: Tensor, u: Tensor) -> Tensor:
        """True next states ``(N, n)`` for states ``(N, n)`` and normalized actions ``(N, m)``."""
        nxt = self.env.transition(
            z.detach().cpu().double().numpy(), u.detach().cpu().double().numpy()
        )
        return torch.as_tensor(nxt, dtype=z.dtype, device=z.device)

    def jacobians(self, z: Tensor, u: Tensor) -> tuple[Tensor, Tensor]:
        """``A = df/ds`` ``(N, n, n)`` and ``B = df/du`` ``(N, n, m)`` by central differences.

        The difference of the two perturbed next states goes through ``state_error``, so a
        wrapped angle never produces a spurious jump.
        """
        s = z.detach().cpu().double().numpy()
        a = u.detach().cpu().double().numpy()
        n, m = s.shape[1], a.shape[1]
        h = self.fd_step
        eye = np.eye(n + m) * h
        # (N, 2(n+m), n+m) perturbations of the stacked (state, action).
        x = np.concatenate([s, a], axis=1)[:, None, :]
        plus, minus = x + eye[None], x - eye[None]
        both = np.concatenate([plus, minus], axis=1).reshape(-1, n + m)
        nxt = self.env.transition(both[:, :n], both[:, n:]).reshape(s.shape[0], 2, n + m, n)
        jac = self.env.state_error(nxt[:, 0], nxt[:, 1]) / (2 * h)  # (N, n+m, n)
        jac = np.swapaxes(jac, 1, 2)
        A = torch.as_tensor(jac[:, :, :n], dtype=z.dtype, device=z.device)
        B = torch.as_tensor(jac[:, :, n:], dtype=z.dtype, device=z.device)
        return A, B


class OracleController:
    """iLQR-MPC on the true state of one env instance (SB3 ``predict`` contract).

    Args:
        env: The environment being controlled (wrappers allowed; the true state is read from
            ``env.unwrapped``).
        config: True-state cost weights; default: :data:`ORACLE_CONFIGS` for the env's id.
        planner: Planner settings; default: :func:`oracle_planner_for` the env's id (the
            agents' own, with the oracle's horizon where ``config`` names one).
        seed: Seed of the planner's random initial plans.
    """

    def __init__(
        self,
        env: gym.Env,
        config: OracleConfig | None = None,
        planner: PlannerConfig | None = None,
        seed: int = 0,
    ) -> None:
        self.env = env
        self.core = env.unwrapped
        env_id = env.spec.id if env.spec else ""
        if config is None:
            config = oracle_config_for(env_id)
        if planner is None:
            planner = oracle_planner_for(env_id, config)
        self.config = config
        self.planner = planner
        weights = torch.tensor(config.state_weights, dtype=torch.float64)
        if weights.numel() != self.core.state_dim:
            raise ValueError(
                f"state_weights has {weights.numel()} entries, the env's state has "
                f"{self.core.state_dim}."
            )
        Q = planner.kappa * torch.diag(weights)
        action_dim = self.core.action_space.shape[0]
        cost = QuadraticCost(
            Q,
            planner.r_weight * torch.eye(action_dim, dtype=torch.float64),
            planner.terminal_weight * Q,
            torch.as_tensor(self.core.goal_state, dtype=torch.float64),
        )
        self.mpc = LatentMPC(TrueDynamics(self.core, config.fd_step), cost, planner, seed=seed)

    def predict(
        self,
        observation: np.ndarray,
        state: Any = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = True,
    ) -> tuple[np.ndarray, Any]:
        """Plan from the env's current TRUE state (the observation is ignored)."""
        if episode_start is not None and bool(np.asarray(episode_start).reshape(-1)[0]):
            self.mpc.reset()
        s = torch.as_tensor(self.core.state, dtype=torch.float64)
        action = self.mpc.act(s).numpy().astype(np.float32)
        batched = np.asarray(observation).ndim == len(self.core.observation_space.shape) + 1
        return (action[None] if batched else action), state
