"""Planar navigation among obstacles from a top-view image (paper, Appendix "Domains")."""

from __future__ import annotations

import math

import numpy as np

from pcc_envs.core import ImageControlEnv
from pcc_envs.physics import PlanarParams, planar_in_collision, planar_move
from pcc_envs.rendering import PlanarView, render_planar

__all__ = ["PlanarEnv"]

GOAL = (37.0, 37.0)
"""Goal position: the bottom-right corner."""
GOAL_RADIUS = 2.0
"""Success when the agent centre is within distance 2 of the goal."""
STARTS = ((3.0, 3.0), (3.0, 37.0), (37.0, 3.0))
"""Start corners: top-left, bottom-left, top-right."""
START_JITTER = 0.5
"""Each start coordinate gets uniform noise in ``[-0.5, 0.5]``."""


class PlanarEnv(ImageControlEnv):
    r"""Navigate a disk agent across a walled world with six obstacles (``pcc/Planar-v0``).

    ## Description
    The hidden state is the agent centre ``(x, y)`` (``x`` = image column, ``y`` = image
    row, one world unit per pixel), kept in ``[1.5, 38.5]`` so the agent disk (radius 1.5)
    stays inside the world. Six obstacles, drawn as disks of radius 2.5, sit at (20.5, 5.5),
    (20.5, 13.5), (20.5, 27.5), (20.5, 35.5), (10.5, 20.5), (30.5, 20.5). As in the paper's
    reference code, only their cores block: the agent centre may not come closer than
    ``obstacle_clearance`` (default 1) to an obstacle centre, so the agent can pass over the
    drawn rim (``obstacle_clearance=4.0`` makes the drawn disks solid, a harder variant; see
    :class:`pcc_envs.physics.PlanarParams` for why the default follows the reference code).
    The action is a displacement; the move is collision-checked in closed form
    (:func:`pcc_envs.physics.planar_move`): the target is clipped to the world (sliding
    along walls), and if the straight path then enters an obstacle core the agent stops at
    the first contact point. There is no velocity; one frame is Markovian.

    ## Action Space
    ``Box(-1, 1, (2,), float32)``: the displacement is ``3 * action`` per axis.

    ## Observation Space
    ``Box(0, 255, (1, 40, 40), uint8)``: the top view, obstacles in grey (level 100) and the
    agent as a white antialiased disk (:func:`pcc_envs.rendering.render_planar`).

    ## Rewards
    Dense (default): ``-((x - 37)^2 + (y - 37)^2) / 100``. Sparse: ``1`` within distance 2 of
    the goal.

    ## Starting State
    One of the three corners other than the goal, (3, 3), (3, 37), (37, 3), chosen
    uniformly, plus uniform jitter in ``[-0.5, 0.5]`` per axis. The data sampler draws
    uniformly over the free positions (rejection sampling in ``[1.5, 38.5]^2``).

    ## Episode End
    Truncation after 40 steps. Never terminates.

    ## Arguments
    ``noise_std`` (Gaussian noise added to the position, applied as a collision-checked
    move), ``reward_type``, ``render_mode``, ``obstacle_clearance`` (smallest distance between
    the agent centre and an obstacle centre, default 1).

    >>> import gymnasium as gym
    >>> import pcc_envs  # noqa: F401
    >>> env = gym.make("pcc/Planar-v0")
    >>> obs, info = env.reset(seed=0, options={"state": np.array([30.0, 36.0])})
    >>> obs, reward, terminated, truncated, info = env.step(np.ones(2, dtype=np.float32))
    >>> info["state"].tolist(), info["in_goal"]
    ([33.0, 38.5], False)
    """

    num_frames = 1
    frame_shape = (40, 40)
    action_scale = (3.0, 3.0)
    dt = 1.0
    render_scale = 6
    reward_weights = np.array([0.01, 0.01])
    goal_state = np.array(GOAL)

    def __init__(
        self,
        noise_std: float = 0.0,
        reward_type: str = "dense",
        render_mode: str | None = None,
        obstacle_clearance: float = PlanarParams.collision_clearance,
    ) -> None:
        self.params = PlanarParams(collision_clearance=obstacle_clearance)
        self.view = PlanarView()
        self.action_scale = (self.params.max_step, self.params.max_step)
        self.state_low = np.full(2, self.params.low)
        self.state_high = np.full(2, self.params.high)
        super().__init__(noise_std=noise_std, reward_type=reward_type, render_mode=render_mode)

    def _dynamics(self, state: np.ndarray, action: np.ndarray) -> np.ndarray:
        return planar_move(state, action, self.params)

    def _previous_state(self, state: np.ndarray) -> np.ndarray:
        return state

    def add_process_noise(self, state: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Move by Gaussian noise (``noise_std``) with the same collision checks as actions."""
        if self.noise_std == 0.0:
            return state
        return planar_move(state, self.noise_std * rng.standard_normal(state.shape), self.params)

    def sample_states(self, rng: np.random.Generator, num_states: int) -> np.ndarray:
        """Uniform draws over the free positions (rejection sampling), ``(num_states, 2)``."""
        out = np.empty((0, 2))
        while len(out) < num_states:
            need = num_states - len(out)
            draw = rng.uniform(self.state_low, self.state_high, (int(need * 1.3) + 8, 2))
            out = np.concatenate([out, draw[~planar_in_collision(draw, self.params)]])
        return out[:num_states]

    def _sample_start_state(self, rng: np.random.Generator) -> np.ndarray:
        corner = np.array(STARTS[rng.integers(len(STARTS))])
        return corner + rng.uniform(-START_JITTER, START_JITTER, 2)

    def in_goal(self, state: np.ndarray) -> bool:
        """Whether the agent centre is within distance 2 of the goal (37, 37)."""
        x, y = np.asarray(state, dtype=np.float64).tolist()
        return math.hypot(x - GOAL[0], y - GOAL[1]) <= GOAL_RADIUS

    def render_states(self, states: np.ndarray) -> np.ndarray:
        """Render ``(N, 2)`` positions to ``uint8 (N, 40, 40)`` frames."""
        return render_planar(states, self.params, self.view)
