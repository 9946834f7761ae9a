"""Lane keeping from road images: the PCC paper's TORCS task, rebuilt on PyBullet's racecar.

The paper steers a TORCS car on a straight stretch of road from two 80x80 binary road images.
Here the car is PyBullet's MIT racecar (``pybullet_data/racecar/racecar.urdf``) on a flat,
straight, single-lane road; Bullet simulates the car (tyre contacts, wheel motors, steering
servos) and a car-mounted pinhole camera sees the road ahead (:mod:`pcc_envs.lane_render`).

Scale. The racecar is about 0.5 m long with a 0.325 m wheelbase. The lane is 3.6 m wide,
so one paper "unit" (the paper's lane is about 18 units wide) is 0.2 m: the goal band
``|offset| <= 1`` unit is ``|offset| <= 0.2`` m, and the target speed of 2 m/s is the
paper's "around 10" units per second.

Markov re-posing. The true state is ``(lateral offset, heading, speed)``. Every control
period starts from the car placed at that pose (the chassis at its settled height, the body
moving along its heading at the state's speed, the wheels rolling, the steering servos at the
commanded angle, a yaw rate of ``yaw_rate_gain`` times the kinematic bicycle rate) and then
Bullet integrates ``frames_per_step`` frames. ``step`` and ``transition`` are therefore the
same deterministic map of the 3-d state, which keeps the paper's sampled data set and the
controlled task consistent; the re-posing drops fast hidden variables (slip, suspension
settling) that a continuous Bullet run would carry over (it tracks such a run within about
10% in heading over 20 full-lock steps).
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from pcc_envs.core import ImageControlEnv, _start_option, wrap_angle
from pcc_envs.lane_render import CameraParams, camera_frames, render_road_masks

__all__ = ["LaneKeepingEnv", "LaneKeepingParams"]


@dataclass(frozen=True)
class LaneKeepingParams:
    """Physical and camera settings of the lane-keeping domain (SI units).

    Attributes:
        lane_width: Full road (lane) width, metres; the paper's lane is about 18 units wide,
            so one unit is ``lane_width / 18``.
        target_speed: Speed the wheel servos hold, m/s.
        max_steering: Steering angle of a full action ``|a| = 1``, radians. The URDF allows
            1 rad, which turns the car on a circle about its own length across at 2 m/s;
            0.07 rad makes the paper's 20 full-lock start steps a drift of about 3.5 units
            and 25 to 30 degrees that stays recoverable inside the lane.
        frame_dt: One simulator frame (one Bullet step), seconds.
        frames_per_step: Frames per control period; the two images of an observation are
            this many frames apart (the paper: 7).
        drift_steps: Forced full-lock steps that :meth:`LaneKeepingEnv.reset` rolls before
            the agent takes over (the paper: 20).
        validation_drift_steps: The drift lengths a validation task draws from
            (``reset(options={"start": "validation"})``): near ``drift_steps`` but never
            equal, since the tasks have only two starts (full left or full right) and
            choosing anything on those starts would be choosing on the evaluation tasks.
        wheel_force: Torque limit of the wheel velocity servos, N m.
        steering_force: Torque limit of the steering position servos, N m.
        yaw_rate_gain: Yaw rate at the start of a period as a fraction of the kinematic
            bicycle rate ``v tan(steering) / wheelbase``; 0.2 makes the re-posed dynamics
            track a continuous Bullet rollout closely (the racecar understeers).
        road_start: World ``x`` where the road begins (the car is posed at ``x = 0``).
        road_end: World ``x`` where the road ends.
        camera: The car-mounted camera that takes the observation.
    """

    lane_width: float = 3.6
    target_speed: float = 2.0
    max_steering: float = 0.07
    frame_dt: float = 0.01
    frames_per_step: int = 7
    drift_steps: int = 20
    validation_drift_steps: tuple[int, ...] = (14, 15, 16, 17, 18, 22, 23, 24, 25, 26)
    wheel_force: float = 10.0
    steering_force: float = 10.0
    yaw_rate_gain: float = 0.2
    road_start: float = -5.0
    road_end: float = 200.0
    camera: CameraParams = field(default_factory=CameraParams)

    def __post_init__(self) -> None:
        lengths = self.validation_drift_steps
        if not lengths or self.drift_steps in lengths or min(lengths) < 0:
            raise ValueError(
                "validation_drift_steps must be non-negative step counts that leave out "
                f"drift_steps ({self.drift_steps}), got {lengths!r}"
            )

    @property
    def unit(self) -> float:
        """One paper unit in metres (``lane_width / 18``): the goal band half-width."""
        return self.lane_width / 18.0

    @property
    def control_dt(self) -> float:
        """Control period in seconds."""
        return self.frame_dt * self.frames_per_step


DEFAULT_PARAMS = LaneKeepingParams()

_WHEEL_JOINTS = (
    "left_rear_wheel_joint",
    "right_rear_wheel_joint",
    "left_front_wheel_joint",
    "right_front_wheel_joint",
)
_STEERING_JOINTS = ("left_steering_hinge_joint", "right_steering_hinge_joint")
_WHEEL_RADIUS = 0.05
_WHEELBASE = 0.325
_ROAD_RGBA = (0.35, 0.35, 0.38, 1.0)
_MARKING_RGBA = (1.0, 1.0, 1.0, 1.0)


def _import_pybullet() -> tuple[Any, Any]:
    try:
        import pybullet
        import pybullet_data
    except ImportError as exc:  # pragma: no cover - pybullet is a core dependency
        raise ImportError(
            "pcc/LaneKeeping-v0 needs PyBullet: install it with `pip install pybullet` "
            "(it is a dependency of pcc-control)."
        ) from exc
    return pybullet, pybullet_data


def _disconnect(pybullet: Any, client: int) -> None:
    try:
        pybullet.disconnect(physicsClientId=client)
    except pybullet.error:  # already gone
        pass


class _RacecarWorld:
    """One private Bullet world (DIRECT client) holding the road and the racecar.

    Every method passes ``physicsClientId``: nothing touches Bullet's default client, so any
    number of worlds live side by side in one process. The world is built once; each
    simulated period starts from :meth:`restoreState` of the snapshot taken after the car
    settled on the ground, so no URDF is ever reloaded.
    """

    def __init__(self, params: LaneKeepingParams) -> None:
        pb, pybullet_data = _import_pybullet()
        self._pb = pb
        self.params = params
        self.client = pb.connect(pb.DIRECT)
        self._finalizer = weakref.finalize(self, _disconnect, pb, self.client)
        cid = self.client
        pb.resetSimulation(physicsClientId=cid)
        pb.setPhysicsEngineParameter(
            fixedTimeStep=params.frame_dt, deterministicOverlappingPairs=1, physicsClientId=cid
        )
        pb.setGravity(0.0, 0.0, -9.81, physicsClientId=cid)
        data = pybullet_data.getDataPath()
        self.plane = pb.loadURDF(f"{data}/plane.urdf", physicsClientId=cid)
        self.road_ids = self._build_road()
        self.car = pb.loadURDF(
            f"{data}/racecar/racecar.urdf", [0.0, 0.0, 0.05], physicsClientId=cid
        )
        names = {
            pb.getJointInfo(self.car, j, physicsClientId=cid)[1].decode(): j
            for j in range(pb.getNumJoints(self.car, physicsClientId=cid))
        }
        self.wheels = [names[n] for n in _WHEEL_JOINTS]
        self.steering = [names[n] for n in _STEERING_JOINTS]
        for joint in names.values():  # no default joint motors: only our servos act
            pb.setJointMotorControl2(
                self.car,
                joint,
                pb.VELOCITY_CONTROL,
                targetVelocity=0.0,
                force=0.0,
                physicsClientId=cid,
            )
        for _ in range(100):
            pb.stepSimulation(physicsClientId=cid)
        position, orientation = pb.getBasePositionAndOrientation(self.car, physicsClientId=cid)
        self.rest_height = float(position[2])
        self.rest_roll, self.rest_pitch, _ = pb.getEulerFromQuaternion(orientation)
        self.snapshot = pb.saveState(physicsClientId=cid)

    def _build_road(self) -> list[int]:
        """A visual-only road slab with white edge lines (the car drives on the plane)."""
        pb, cid, p = self._pb, self.client, self.params
        length = p.road_end - p.road_start
        center_x = 0.5 * (p.road_start + p.road_end)
        slabs = [(0.0, 0.5 * p.lane_width, 0.001, _ROAD_RGBA)]
        line = 0.06
        for side in (-1.0, 1.0):
            y = side * (0.5 * p.lane_width - 1.5 * line)
            slabs.append((y, 0.5 * line, 0.0025, _MARKING_RGBA))
        ids = []
        for y, half_width, z, rgba in slabs:
            visual = pb.createVisualShape(
                pb.GEOM_BOX,
                halfExtents=[0.5 * length, half_width, 0.0005],
                rgbaColor=rgba,
                physicsClientId=cid,
            )
            ids.append(
                pb.createMultiBody(
                    baseMass=0.0,
                    baseCollisionShapeIndex=-1,
                    baseVisualShapeIndex=visual,
                    basePosition=[center_x, y, z],
                    physicsClientId=cid,
                )
            )
        return ids

    @property
    def closed(self) -> bool:
        """Whether the Bullet client was disconnected."""
        return not self._finalizer.alive

    def close(self) -> None:
        """Disconnect the Bullet client (idempotent)."""
        self._finalizer()

    def pose_car(self, state: np.ndarray, steering: float) -> None:
        """Restore the snapshot and place the car at ``state`` with its wheels rolling."""
        pb, cid = self._pb, self.client
        offset, heading, speed = (float(v) for v in state)
        pb.restoreState(stateId=self.snapshot, physicsClientId=cid)
        orientation = pb.getQuaternionFromEuler(
            [self.rest_roll, self.rest_pitch, heading], physicsClientId=cid
        )
        pb.resetBasePositionAndOrientation(
            self.car, [0.0, offset, self.rest_height], orientation, physicsClientId=cid
        )
        yaw_rate = self.params.yaw_rate_gain * speed * np.tan(steering) / _WHEELBASE
        pb.resetBaseVelocity(
            self.car,
            [speed * np.cos(heading), speed * np.sin(heading), 0.0],
            [0.0, 0.0, yaw_rate],
            physicsClientId=cid,
        )
        for joint in self.wheels:
            pb.resetJointState(self.car, joint, 0.0, speed / _WHEEL_RADIUS, physicsClientId=cid)
        for joint in self.steering:
            pb.resetJointState(self.car, joint, steering, 0.0, physicsClientId=cid)

    def simulate(self, state: np.ndarray, steering: float) -> np.ndarray:
        """One control period from ``state`` with the steering servos at ``steering`` rad."""
        pb, cid, p = self._pb, self.client, self.params
        self.pose_car(state, steering)
        pb.setJointMotorControlArray(
            self.car,
            self.wheels,
            pb.VELOCITY_CONTROL,
            targetVelocities=[p.target_speed / _WHEEL_RADIUS] * len(self.wheels),
            forces=[p.wheel_force] * len(self.wheels),
            physicsClientId=cid,
        )
        pb.setJointMotorControlArray(
            self.car,
            self.steering,
            pb.POSITION_CONTROL,
            targetPositions=[steering] * len(self.steering),
            forces=[p.steering_force] * len(self.steering),
            physicsClientId=cid,
        )
        for _ in range(p.frames_per_step):
            pb.stepSimulation(physicsClientId=cid)
        return self.read_state()

    def read_state(self) -> np.ndarray:
        """``(lateral offset, heading, forward speed)`` of the car now."""
        pb, cid = self._pb, self.client
        position, orientation = pb.getBasePositionAndOrientation(self.car, physicsClientId=cid)
        velocity, _ = pb.getBaseVelocity(self.car, physicsClientId=cid)
        heading = pb.getEulerFromQuaternion(orientation, physicsClientId=cid)[2]
        speed = velocity[0] * np.cos(heading) + velocity[1] * np.sin(heading)
        return np.array([position[1], heading, speed], dtype=np.float64)

    def camera_masks(self, states: np.ndarray) -> np.ndarray:
        """Road masks from Bullet's TinyRenderer segmentation buffer (slow reference path)."""
        pb, cid, camera = self._pb, self.client, self.params.camera
        height, width = camera.image_shape
        eye, forward, _, _ = camera_frames(states[:, 0], states[:, 1], camera)
        projection = pb.computeProjectionMatrixFOV(
            camera.fov, width / height, camera.near, camera.far, physicsClientId=cid
        )
        masks = np.zeros((len(states), height, width), dtype=np.uint8)
        # The mask is a function of the pose alone: park the car (whatever pose the last
        # simulated period left it in) out of sight; the next period restores it anyway.
        pb.resetBasePositionAndOrientation(
            self.car, [-1000.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0], physicsClientId=cid
        )
        for i in range(len(states)):
            view = pb.computeViewMatrix(
                eye[i].tolist(),
                (eye[i] + forward[i]).tolist(),
                [0.0, 0.0, 1.0],
                physicsClientId=cid,
            )
            _, _, _, _, segmentation = pb.getCameraImage(
                width,
                height,
                view,
                projection,
                renderer=pb.ER_TINY_RENDERER,
                physicsClientId=cid,
            )
            road = np.isin(np.asarray(segmentation).reshape(height, width), self.road_ids)
            masks[i] = np.where(road, 255, 0)
        return masks

    def chase_view(self, state: np.ndarray, size: tuple[int, int] = (240, 320)) -> np.ndarray:
        """An RGB picture ``(H, W, 3)`` from behind and above the car posed at ``state``."""
        pb, cid = self._pb, self.client
        self.pose_car(state, 0.0)
        offset, heading = float(state[0]), float(state[1])
        direction = np.array([np.cos(heading), np.sin(heading), 0.0])
        car = np.array([0.0, offset, 0.0])
        eye = car - 1.6 * direction + np.array([0.0, 0.0, 0.9])
        target = car + 2.0 * direction
        view = pb.computeViewMatrix(eye.tolist(), target.tolist(), [0, 0, 1], physicsClientId=cid)
        projection = pb.computeProjectionMatrixFOV(
            60.0, size[1] / size[0], 0.05, 100.0, physicsClientId=cid
        )
        _, _, rgba, _, _ = pb.getCameraImage(
            size[1],
            size[0],
            view,
            projection,
            renderer=pb.ER_TINY_RENDERER,
            flags=pb.ER_NO_SEGMENTATION_MASK,
            physicsClientId=cid,
        )
        return np.asarray(rgba, dtype=np.uint8).reshape(size[0], size[1], 4)[:, :, :3].copy()


class LaneKeepingEnv(ImageControlEnv):
    """Keep PyBullet's racecar in the middle of a straight lane, steering from road images.

    ## Description
    The paper's TORCS lane-keeping task (Levine et al., ICLR 2020, Appendix: "TORCS
    Simulator"), rebuilt on PyBullet. The car drives at a held speed of about 2 m/s along a
    straight road 3.6 m (18 paper units) wide; the agent only steers. Each episode opens with
    20 control steps of full-lock steering to the left or right (drawn per episode), which
    leaves the car drifting away from the middle at about 3.5 units and 25 to 30 degrees (the
    racecar turns slightly harder to the right); the agent
    must bring it back to the middle and keep it there. Bullet simulates the car; see the
    module docstring for the scale and for how each control period is simulated.

    ## Action Space
    ``Box(-1, 1, (1,), float32)``: the steering command, ``+1`` full left, ``-1`` full right,
    scaled to ``max_steering = 0.07`` rad at the front wheels. Wheel servos hold the speed
    (a torque-limited proportional velocity controller on the four wheel motors).

    ## Observation Space
    ``Box(0, 255, (2, 80, 80), uint8)``: two binary images (road 255, everything else 0)
    from a camera on a 1 m mast at the car's nose, tilted 31.5 degrees down with a 100
    degree field of view (:class:`pcc_envs.lane_render.CameraParams`); the older image
    first, taken one control period (7 simulator frames of 10 ms) before the newer one.
    The images are the exact projection of the flat road (the same picture Bullet's
    TinyRenderer segmentation draws for that camera; pass ``renderer="bullet"`` to use
    Bullet's renderer itself).

    The true state (``info["state"]``) is ``(lateral offset [m], heading [rad], speed
    [m/s])``: offset positive to the left of the lane centre, heading from the road direction,
    positive turning left. ``goal_state = (0, 0, 2)``.

    ## Rewards
    Dense (default): ``-(offset / unit)**2 - heading**2`` with ``unit = 0.2`` m (speed is not
    penalized). Sparse: ``1`` while ``|offset| <= unit``, else ``0``.

    ## Starting State
    :meth:`reset` places the car on the centre line, heading along the road at 2 m/s, and
    rolls the forced drift (``drift_steps = 20`` full-lock steps) inside ``reset``, so the
    first observation shows the drifted car and all ``max_episode_steps = 200`` steps are
    controlled. ``options={"drift": +1 | -1}`` picks the drift direction (left / right);
    ``options={"state": s}`` instead places the car at ``s`` with no drift.

    The paper's data sampler draws states uniformly from ``state_low = (-1.8, -pi/4, 1.5)``
    to ``state_high = (1.8, pi/4, 2.5)``: the whole lane, headings up to 45 degrees and
    speeds around the held one.

    ## Episode End
    Truncation after 200 steps (registry). No termination: a car that leaves the lane keeps
    driving on the ground next to it.

    ## Arguments
    * ``noise_std``: Gaussian process noise added to the next true state (metres, radians,
      m/s); the car is re-posed at the noisy state.
    * ``reward_type``: ``"dense"`` or ``"sparse"``.
    * ``render_mode``: ``None`` or ``"rgb_array"`` (a 320x240 chase-camera picture).
    * ``renderer``: ``"analytic"`` (default, fast) or ``"bullet"`` (TinyRenderer
      segmentation masks, about 4 ms a frame).

    The environment holds a private Bullet client: call :meth:`close` (or let it be garbage
    collected) to free it. :meth:`transition` accepts batches but loops over them in Bullet
    (about 1 ms a state), hence ``supports_oracle = False``.

    >>> import gymnasium as gym
    >>> import pcc_envs  # noqa: F401
    >>> env = gym.make("pcc/LaneKeeping-v0")
    >>> obs, info = env.reset(seed=0)
    >>> obs.shape, obs.dtype
    ((2, 80, 80), dtype('uint8'))
    >>> bool(abs(info["state"][0]) > 0.2)  # drifted out of the goal band
    True
    >>> obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
    >>> env.close()
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array"], "render_fps": 14}

    num_frames: ClassVar[int] = 2
    frame_shape: ClassVar[tuple[int, int]] = DEFAULT_PARAMS.camera.image_shape
    action_scale: ClassVar[tuple[float, ...]] = (DEFAULT_PARAMS.max_steering,)
    dt: ClassVar[float] = DEFAULT_PARAMS.control_dt
    substeps: ClassVar[int] = DEFAULT_PARAMS.frames_per_step
    supports_oracle: ClassVar[bool] = False

    state_low = np.array([-0.5 * DEFAULT_PARAMS.lane_width, -np.pi / 4, 1.5])
    state_high = np.array([0.5 * DEFAULT_PARAMS.lane_width, np.pi / 4, 2.5])
    goal_state = np.array([0.0, 0.0, DEFAULT_PARAMS.target_speed])
    reward_weights = np.array([1.0 / DEFAULT_PARAMS.unit**2, 1.0, 0.0])

    def __init__(
        self,
        noise_std: float = 0.0,
        reward_type: str = "dense",
        render_mode: str | None = None,
        renderer: str = "analytic",
    ) -> None:
        if renderer not in ("analytic", "bullet"):
            raise ValueError(f"renderer must be 'analytic' or 'bullet', got {renderer!r}")
        super().__init__(noise_std=noise_std, reward_type=reward_type, render_mode=render_mode)
        self.params = DEFAULT_PARAMS
        self.renderer = renderer
        self._world: _RacecarWorld | None = _RacecarWorld(self.params)

    # ------------------------------------------------------------------ resources
    @property
    def world(self) -> _RacecarWorld:
        """The private Bullet world (raises once the env is closed)."""
        if self._world is None or self._world.closed:
            raise RuntimeError("This LaneKeepingEnv is closed; make a new one.")
        return self._world

    @property
    def physics_client_id(self) -> int:
        """The id of this env's own Bullet client."""
        return self.world.client

    def close(self) -> None:
        """Disconnect the Bullet client (idempotent)."""
        if self._world is not None:
            self._world.close()
            self._world = None
        super().close()

    # ------------------------------------------------------------------ domain hooks
    def _dynamics(self, state: np.ndarray, action: np.ndarray) -> np.ndarray:
        """One control period in Bullet for physical steering angles (loops over batches)."""
        state = np.asarray(state, dtype=np.float64)
        action = np.asarray(action, dtype=np.float64)
        batch = np.broadcast_shapes(state.shape[:-1], action.shape[:-1])
        states = np.broadcast_to(state, (*batch, self.state_dim)).reshape(-1, self.state_dim)
        steering = np.broadcast_to(action, (*batch, 1)).reshape(-1)
        world = self.world
        out = np.stack([world.simulate(s, float(d)) for s, d in zip(states, steering)])
        return self._postprocess(out.reshape(*batch, self.state_dim))

    def _postprocess(self, state: np.ndarray) -> np.ndarray:
        """Wrap the heading to ``[-pi, pi)`` and keep the speed non-negative."""
        state = np.array(state, dtype=np.float64)
        state[..., 1] = wrap_angle(state[..., 1])
        state[..., 2] = np.maximum(state[..., 2], 0.0)
        return state

    def _previous_state(self, state: np.ndarray) -> np.ndarray:
        """The pose one period earlier when driving straight (zero steering) at ``speed``.

        Batched over ``(..., 3)``. Zero steering starts a period with no yaw rate, so the
        car keeps its heading and (to within the speed servo's small correction) its speed.
        """
        previous = np.array(state, dtype=np.float64)
        back = previous[..., 2] * self.params.control_dt
        previous[..., 0] -= back * np.sin(previous[..., 1])
        return previous

    def _sample_start_state(self, rng: np.random.Generator) -> np.ndarray:
        """On the centre line at the held speed (the drift is rolled in :meth:`reset`)."""
        return self.goal_state.copy()

    def render_states(self, states: np.ndarray) -> np.ndarray:
        """Camera road masks ``(N, 80, 80)`` for true states ``(N, 3)`` (no stepping)."""
        states = np.asarray(states, dtype=np.float64).reshape(-1, self.state_dim)
        if self.renderer == "bullet":
            return self.world.camera_masks(states)
        return render_road_masks(
            states[:, 0],
            states[:, 1],
            0.5 * self.params.lane_width,
            self.params.camera,
            road_start=self.params.road_start,
            road_end=self.params.road_end,
        )

    def in_goal(self, state: np.ndarray) -> bool:
        """Within one paper unit (``lane_width / 18`` = 0.2 m) of the lane centre."""
        return bool(abs(float(np.asarray(state)[0])) <= self.params.unit)

    def state_error(self, state: np.ndarray, goal: np.ndarray | None = None) -> np.ndarray:
        """``state - goal`` with the heading wrapped to ``[-pi, pi)`` (batched)."""
        err = super().state_error(state, goal).copy()
        err[..., 1] = wrap_angle(err[..., 1])
        return err

    # ------------------------------------------------------------------ gymnasium API
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start an episode: the forced drift, or the pose ``options["state"]``.

        Args:
            seed: Seeds ``self.np_random`` (drift direction and process noise).
            options: ``{"state": s}`` places the car at ``s = (offset, heading, speed)``
                with no drift; ``{"drift": +1 | -1}`` fixes the drift direction (full left
                or full right) instead of drawing it; ``{"start": "validation"}`` draws the
                drift's length from ``params.validation_drift_steps``.

        Returns:
            The first observation (after the drift) and the ``info`` dict.
        """
        obs, info = super().reset(seed=seed, options=options)
        if options is not None and "state" in options:
            return obs, info
        direction = (options or {}).get("drift")
        if direction is None:
            direction = float(self.np_random.choice([-1.0, 1.0]))
        elif direction not in (-1, 1):
            raise ValueError(f"options['drift'] must be +1 (left) or -1 (right), got {direction!r}")
        steps = self.params.drift_steps
        if _start_option(options) == "validation":
            steps = int(self.np_random.choice(self.params.validation_drift_steps))
        for _ in range(steps):
            obs, *_ = self.step(np.array([direction], dtype=np.float32))
        self._steps = 0
        self._steps_in_goal = 0
        return obs, self._info(self.in_goal(self.state))

    def render_rgb(self, state: np.ndarray) -> np.ndarray:
        """A 320x240 RGB chase-camera picture of the car posed at ``state``."""
        return self.world.chase_view(np.asarray(state, dtype=np.float64))
