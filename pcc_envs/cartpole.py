"""Cart-pole balancing from pixels (paper, Appendix "Domains")."""

from __future__ import annotations

import numpy as np

from pcc_envs.core import ImageControlEnv, wrap_angle
from pcc_envs.physics import CartPoleParams, cartpole_xdot
from pcc_envs.rendering import SCHEMATIC_CARTPOLE_VIEW, CartPoleView, render_cartpole

__all__ = ["PICTURES", "CartPoleEnv"]

#: The cart-pole pictures, by name (the env's ``picture`` argument).
PICTURES: dict[str, CartPoleView] = {
    "physical": CartPoleView(),
    "schematic": SCHEMATIC_CARTPOLE_VIEW,
}

GOAL_ANGLE = np.pi / 10
"""Success when ``|theta| <= pi / 10`` with the cart on the track."""
START_ANGLE = np.pi / 6
"""Episodes start with ``theta`` uniform in ``[-pi/6, pi/6]``."""
SAMPLER_ANGLE = np.pi / 2
"""The data sampler draws ``theta`` in ``[-pi/2, pi/2]`` (the upper half plane)."""
SAMPLER_OMEGA = 2.0 * np.pi
"""... ``theta_dot`` in ``[-2 pi, 2 pi]`` rad/s ..."""
SAMPLER_VELOCITY = 3.0
"""... and the cart velocity in ``[-3, 3]`` m/s."""


class CartPoleEnv(ImageControlEnv):
    r"""Balance a pole on a cart from pixels (``pcc/CartPole-v0``, ``pcc/CartPole-v1``).

    ## Description
    A uniform pole (0.1 kg, half-length 0.5 m) is hinged on a cart (1.0 kg) that moves without
    friction on a horizontal track ``[-2.4, 2.4]`` m; g = 9.81 m/s^2. The frictionless
    Barto-Sutton-Anderson equations (Florian's corrected form,
    :func:`pcc_envs.physics.cartpole_xdot`) are integrated by RK4 at 50 Hz (``dt = 0.02`` s,
    one substep). The hidden state is ``(theta, theta_dot, x, x_dot)``: pole angle from
    upright (wrapped to ``[-pi, pi)``), its rate, cart position and velocity (not clipped).

    ## Action Space
    ``Box(-1, 1, (1,), float32)``: the horizontal force on the cart is ``max_force * action``
    N (default 10 N).

    ## Observation Space
    ``Box(0, 255, (2, 80, 80), uint8)``: previous and current frame from a fixed camera
    (:func:`pcc_envs.rendering.render_cartpole`). Two pictures (``picture``):

    * ``"physical"`` (``pcc/CartPole-v0``): everything to one scale, 15 pixels per metre: a
      7 x 5 pixel cart whose centre moves across columns 4..76 and a 15-pixel pole 2.5 pixels
      wide.
    * ``"schematic"`` (``pcc/CartPole-v1``): the PCC authors' picture: a 52-pixel pole 6
      pixels wide (0.65 of the frame) on a 16 x 8 pixel cart whose centre moves across
      columns 8..72. The paper gives only the frame size; its authors' code draws this.
      Near upright the pole's tip moves 3.5 times as far per step as in the physical
      picture, so the pole's rate shows in two frames.

    ## Rewards
    Dense (default): ``-(theta^2 + 0.1 theta_dot^2 + 0.1 x^2 + 0.01 x_dot^2)`` with ``theta``
    wrapped. Sparse: ``1`` in the goal region (``|theta| <= pi/10``, ``|x| <= 2.4``).

    ## Starting State
    ``theta`` uniform in ``[-pi/6, pi/6]``, everything else 0 (the paper's start state). The
    data sampler draws uniformly from ``theta`` in ``[-pi/2, pi/2]``, ``theta_dot`` in
    ``[-2 pi, 2 pi]``, ``x`` in ``[-2.4, 2.4]``, ``x_dot`` in ``[-3, 3]``.

    Why these data ranges: the paper samples "uniformly from the state-action space" and
    gives no ranges. The PC3 reference code samples ``theta`` in ``[-pi/10, pi/10]``, which is
    narrower than the paper's own start states (``pi/6``): a model trained on it never sees
    the first frames of a task. ``[-pi/2, pi/2]`` covers every start state and a falling pole
    down to horizontal; its cost is data density near upright (about a fifth of the samples
    lie inside the goal band ``pi/10``). The track limit is the terminal bound ``2.4``;
    ``theta_dot`` and ``x_dot`` bound what the 10 N force produces from the start states.

    ## Episode End
    Terminates when the cart leaves the track (``|x| > 2.4``); a fallen pole does not end the
    episode (it just stays out of the goal). Truncation after 200 steps.

    ## Arguments
    ``max_force`` (N), ``noise_std``, ``reward_type``, ``render_mode``, ``picture``
    (``"physical"`` or ``"schematic"``), ``sampler_angle`` (the data sampler's pole angle
    range ``[-a, a]``, default ``pi/2``; the PC3 reference code's is ``pi/10``).

    >>> import gymnasium as gym
    >>> import pcc_envs  # noqa: F401
    >>> env = gym.make("pcc/CartPole-v0")
    >>> obs, info = env.reset(seed=0)
    >>> obs.shape
    (2, 80, 80)
    >>> obs, reward, terminated, truncated, info = env.step(np.zeros(1, dtype=np.float32))
    >>> bool(terminated)
    False
    """

    num_frames = 2
    frame_shape = (80, 80)
    dt = 0.02
    substeps = 1
    render_scale = 4
    reward_weights = np.array([1.0, 0.1, 0.1, 0.01])
    goal_state = np.zeros(4)

    def __init__(
        self,
        max_force: float = 10.0,
        noise_std: float = 0.0,
        reward_type: str = "dense",
        render_mode: str | None = None,
        picture: str = "physical",
        sampler_angle: float = SAMPLER_ANGLE,
    ) -> None:
        if not max_force > 0:
            raise ValueError(f"max_force must be > 0 N, got {max_force!r}")
        if picture not in PICTURES:
            raise ValueError(f"picture must be one of {sorted(PICTURES)}, got {picture!r}")
        if not 0 < sampler_angle <= np.pi:
            raise ValueError(f"sampler_angle must be in (0, pi] rad, got {sampler_angle!r}")
        self.params = CartPoleParams(max_force=float(max_force))
        self.picture = picture
        self.view = PICTURES[picture]
        self.action_scale = (self.params.max_force,)
        limit = self.params.track_limit
        self.state_low = np.array([-sampler_angle, -SAMPLER_OMEGA, -limit, -SAMPLER_VELOCITY])
        self.state_high = -self.state_low
        super().__init__(noise_std=noise_std, reward_type=reward_type, render_mode=render_mode)

    def _xdot(self, state: np.ndarray, action: np.ndarray) -> np.ndarray:
        return cartpole_xdot(state, action, self.params)

    def _postprocess(self, state: np.ndarray) -> np.ndarray:
        out = np.array(state, dtype=np.float64)
        out[..., 0] = wrap_angle(out[..., 0])
        return out

    def _sample_start_state(self, rng: np.random.Generator) -> np.ndarray:
        return np.array([rng.uniform(-START_ANGLE, START_ANGLE), 0.0, 0.0, 0.0])

    def _is_terminal(self, state: np.ndarray) -> bool:
        return bool(abs(state[2]) > self.params.track_limit)

    def state_error(self, state: np.ndarray, goal: np.ndarray | None = None) -> np.ndarray:
        """``state - goal`` with the pole angle wrapped to ``[-pi, pi)`` (batched)."""
        err = super().state_error(state, goal)
        err[..., 0] = wrap_angle(err[..., 0])
        return err

    def in_goal(self, state: np.ndarray) -> bool:
        """Pole within ``pi/10`` of upright and cart on the track."""
        return bool(
            abs(wrap_angle(state[0])) <= GOAL_ANGLE and abs(state[2]) <= self.params.track_limit
        )

    def render_states(self, states: np.ndarray) -> np.ndarray:
        """Render ``(N, 4)`` states to ``uint8 (N, 80, 80)`` frames."""
        return render_cartpole(states, self.params, self.view)
