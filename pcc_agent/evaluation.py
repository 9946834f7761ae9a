"""One evaluation function for every controller: the paper's percentage of steps in goal.

Every method (a :class:`~pcc_agent.agent.PCCAgent`, any Stable-Baselines3 model, the oracle
controller) is evaluated by :func:`evaluate_control`, which runs SB3's ``evaluate_policy`` on
the task's environment and reads the env's ``in_goal`` info key at every step. The numbers
are therefore comparable by construction.

The metric (paper, Section 6): the percentage of the episode's steps whose TRUE state is in
the goal region. The denominator is the episode length of the task (``max_episode_steps``):
if an episode terminates early (e.g. the cart leaves the track) the remaining steps count as
not in goal.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import DummyVecEnv

__all__ = [
    "EVALUATION_TASK_SEED",
    "VALIDATION_TASK_SEED",
    "ControlEvaluation",
    "GoalHold",
    "TaskResult",
    "evaluate_control",
    "evaluate_goal_hold",
    "evaluate_on_validation_tasks",
    "format_mean_se",
    "goal_hold_starts",
    "standard_error",
    "task_seeds",
]

#: Base task seed of the evaluation tasks every committed row reports (the paper's protocol).
EVALUATION_TASK_SEED = 2020
#: Base task seed of the validation tasks: choosing settings, trainings or checkpoints on
#: these keeps the evaluation tasks unseen.
VALIDATION_TASK_SEED = 2021

PolicyLike = Any  # anything with SB3's ``predict(obs, state, episode_start, deterministic)``


def standard_error(values: Sequence[float] | np.ndarray) -> float | None:
    """Standard error of the mean (sample standard deviation / sqrt(n)).

    ``None`` for fewer than two values: the spread of one task or one seed is undefined, and
    printing it as 0.0 would claim a certainty the data do not have.
    """
    x = np.asarray(values, dtype=np.float64).ravel()
    return float(x.std(ddof=1) / np.sqrt(x.size)) if x.size > 1 else None


def format_mean_se(mean: float, se: float | None) -> str:
    """``"54.3 ± 2.1"``, or ``"54.3 ± n/a"`` where the standard error is undefined."""
    return f"{mean:.1f} ± " + ("n/a" if se is None else f"{se:.1f}")


@dataclass
class TaskResult:
    """Outcome of one control task (one episode)."""

    seed: int
    percent_in_goal: float
    steps: int
    episode_length: int
    terminated_early: bool
    states: list[list[float]] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        """JSON-friendly representation."""
        return {
            "seed": self.seed,
            "percent_in_goal": self.percent_in_goal,
            "steps": self.steps,
            "episode_length": self.episode_length,
            "terminated_early": self.terminated_early,
            "states": self.states,
        }


@dataclass
class ControlEvaluation:
    """Results of :func:`evaluate_control` over several tasks."""

    env_id: str
    tasks: list[TaskResult]

    @property
    def percentages(self) -> np.ndarray:
        """Per-task percentage of steps in goal (0-100)."""
        return np.array([t.percent_in_goal for t in self.tasks], dtype=np.float64)

    @property
    def mean(self) -> float:
        """Mean percentage over tasks."""
        return float(self.percentages.mean()) if self.tasks else float("nan")

    @property
    def standard_error(self) -> float | None:
        """Standard error of the mean over tasks (``None`` for fewer than two tasks)."""
        return standard_error(self.percentages)


class _EpisodeRecorder:
    """``evaluate_policy`` callback: records ``in_goal`` and the true state at every step."""

    def __init__(self, record_states: bool) -> None:
        self.record_states = record_states
        self.in_goal: list[bool] = []
        self.states: list[list[float]] = []
        self.terminated = False

    def __call__(self, locals_: dict[str, Any], _globals: dict[str, Any]) -> None:
        info = locals_["info"]
        self.in_goal.append(bool(info["in_goal"]))
        if self.record_states:
            self.states.append([float(x) for x in info["state"]])
        if locals_["done"]:
            self.terminated = not info.get("TimeLimit.truncated", False)


def task_seeds(base_seed: int, num_tasks: int) -> list[int]:
    """Fixed, well-separated seeds for ``num_tasks`` control tasks."""
    return [int(s) for s in np.random.SeedSequence(base_seed).generate_state(num_tasks)]


def evaluate_control(
    policy: PolicyLike | Callable[[gym.Env], PolicyLike],
    env_id: str,
    seeds: Sequence[int],
    env_kwargs: dict[str, Any] | None = None,
    record_states: bool = True,
    deterministic: bool = True,
    reset_options: dict[str, Any] | None = None,
) -> ControlEvaluation:
    """Run one episode per seed and measure the percentage of steps in goal.

    Args:
        policy: An object with SB3's ``predict`` (a ``PCCAgent``, an SB3 model), or a factory
            ``env -> policy`` for controllers that need the env itself (the oracle reads the
            true state from it).
        env_id: Registered Gymnasium id, e.g. ``"pcc/Planar-v0"``.
        seeds: One seed per task; the start state is drawn from the env's start distribution
            with that seed.
        env_kwargs: Extra keyword arguments for ``gym.make`` (e.g. ``noise_std``).
        record_states: Keep the true-state trajectory of every task.
        deterministic: Passed to ``predict``.
        reset_options: ``options`` of every episode's ``reset`` (e.g. ``{"start":
            "validation"}`` for a pcc env's validation starts).

    Returns:
        A :class:`ControlEvaluation` with one :class:`TaskResult` per seed.
    """
    if env_id.startswith("pcc/"):
        import pcc_envs  # noqa: F401  (registers the pcc/ ids)

    results: list[TaskResult] = []
    for seed in seeds:
        env = gym.make(env_id, **(env_kwargs or {}))
        episode_length = int(env.spec.max_episode_steps) if env.spec else 0
        vec_env = DummyVecEnv([lambda env=env: Monitor(env)])
        vec_env.seed(int(seed))
        if reset_options:
            vec_env.set_options(dict(reset_options))
        recorder = _EpisodeRecorder(record_states)
        try:  # a failing controller factory or policy must not leave the env (pybullet) open
            controller = (policy(env) if callable(policy) and not hasattr(policy, "predict")
                          else policy)
            evaluate_policy(
                controller,
                vec_env,
                n_eval_episodes=1,
                deterministic=deterministic,
                callback=recorder,
                warn=False,
            )
        finally:
            vec_env.close()
        in_goal, states = recorder.in_goal, recorder.states
        denominator = max(episode_length, len(in_goal))
        results.append(
            TaskResult(
                seed=int(seed),
                percent_in_goal=100.0 * sum(in_goal) / denominator,
                steps=len(in_goal),
                episode_length=denominator,
                terminated_early=recorder.terminated and len(in_goal) < denominator,
                states=states,
            )
        )
    return ControlEvaluation(env_id=env_id, tasks=results)


def evaluate_on_validation_tasks(
    policy: PolicyLike | Callable[[gym.Env], PolicyLike],
    env_id: str,
    num_tasks: int = 5,
    env_kwargs: dict[str, Any] | None = None,
) -> ControlEvaluation:
    """:func:`evaluate_control` on ``num_tasks`` validation tasks (:data:`VALIDATION_TASK_SEED`).

    The one definition of the validation tasks that trainings, checkpoints and settings are
    chosen on, so that the evaluation tasks stay unseen. On a pcc env they start from its
    validation start distribution (``reset(options={"start": "validation"})``): the task
    start distribution, except where the tasks have one or two fixed starts (swing-up, the
    arms, lane keeping), which validation tasks perturb; other envs start from their own
    start distribution.

    Raises:
        ValueError: ``num_tasks`` below 1.
    """
    if num_tasks < 1:
        raise ValueError(f"num_tasks must be >= 1, got {num_tasks}.")
    options = {"start": "validation"} if env_id.startswith("pcc/") else None
    return evaluate_control(policy, env_id, task_seeds(VALIDATION_TASK_SEED, num_tasks),
                            env_kwargs, reset_options=options)


@dataclass(frozen=True)
class GoalHold:
    """How long a controller keeps the true state in the goal region from starts near the goal.

    Swing-up and balancing tasks fail in two ways: the controller never reaches the goal, or
    it reaches it and cannot stay (an upright pole or arm is unstable). The paper's metric mixes
    the two; this separates them.

    Attributes:
        env_id: The env the starts are in.
        starts: The true start states, each inside the goal region.
        steps_held: Per start, the steps until the true state first leaves the goal region (or
            the episode ends early); ``horizon`` if it never does.
        horizon: Steps of each episode.
    """

    env_id: str
    starts: list[list[float]]
    steps_held: list[int]
    horizon: int

    @property
    def mean_steps(self) -> float:
        """Mean steps held over the starts."""
        return float(np.mean(self.steps_held))

    @property
    def held_fraction(self) -> float:
        """Share of the starts held for the whole horizon."""
        return float(np.mean([steps == self.horizon for steps in self.steps_held]))

    def to_dict(self) -> dict[str, Any]:
        """JSON-friendly representation (with the mean and the held share)."""
        return {"env_id": self.env_id, "starts": self.starts, "steps_held": self.steps_held,
                "horizon": self.horizon, "mean_steps": self.mean_steps,
                "held_fraction": self.held_fraction}


def goal_hold_starts(env: Any, num_starts: int, spread: float = 0.05,
                     seed: int = 0) -> np.ndarray:
    """``num_starts`` true states inside the goal region, close to the goal state.

    Each is the env's goal state moved by ``U(-spread, spread)`` times the half-width of its
    sampler box in every coordinate (rates included, so the starts are nearly at rest); draws
    outside the box or the goal region are drawn again.

    Args:
        env: A ``pcc_envs`` environment (wrapped or not): it needs ``goal_state``,
            ``state_low`` / ``state_high`` and ``in_goal``.
        num_starts: How many starts.
        spread: Size of the start region, as a share of the sampler box's half-width.
        seed: Seed of the draws.

    Returns:
        The starts, shape ``(num_starts, state_dim)``.

    Raises:
        ValueError: The env lacks a goal state, sampler box or goal test; ``num_starts`` below
            1 or ``spread`` not positive; or hardly any draw lands in the goal region.
    """
    core = getattr(env, "unwrapped", env)
    missing = [name for name in ("goal_state", "state_low", "state_high", "in_goal")
               if getattr(core, name, None) is None]
    if missing:
        raise ValueError(f"A goal hold needs an env with a goal state, a sampler box and a goal "
                         f"test; {type(core).__name__} lacks {', '.join(missing)}.")
    if num_starts < 1 or not spread > 0:
        raise ValueError(f"num_starts must be >= 1 and spread > 0, got {num_starts}, {spread}.")
    rng = np.random.default_rng(seed)
    goal = np.asarray(core.goal_state, dtype=np.float64)
    low, high = np.asarray(core.state_low), np.asarray(core.state_high)
    starts: list[np.ndarray] = []
    max_draws = 1000 * num_starts
    for _ in range(max_draws):
        state = goal + rng.uniform(-spread, spread, goal.shape) * (high - low) / 2.0
        if np.all(state >= low) and np.all(state <= high) and core.in_goal(state):
            starts.append(state)
            if len(starts) == num_starts:
                return np.stack(starts)
    raise ValueError(f"Only {len(starts)} of {max_draws} draws within spread {spread} of the "
                     f"goal state fell inside the goal region; use a smaller spread.")


def evaluate_goal_hold(
    policy: PolicyLike | Callable[[gym.Env], PolicyLike],
    env_id: str,
    num_starts: int = 5,
    horizon: int = 100,
    spread: float = 0.05,
    seed: int = 0,
    env_kwargs: dict[str, Any] | None = None,
) -> GoalHold:
    """Start in the goal region, near the goal state, and count the steps the controller stays.

    One episode of ``horizon`` steps per start of :func:`goal_hold_starts`
    (``reset(options={"state": s})``), run by :func:`evaluate_control`.

    Args:
        policy: As for :func:`evaluate_control` (an agent, an SB3 model, or a factory
            ``env -> policy`` such as the oracle).
        env_id: A registered ``pcc/`` id.
        num_starts: Episodes, one per start.
        horizon: Steps of each episode (the env's time limit is set to it).
        spread: Size of the start region (see :func:`goal_hold_starts`).
        seed: Seed of the starts.
        env_kwargs: Extra keyword arguments for ``gym.make`` (e.g. ``noise_std``).

    Returns:
        The :class:`GoalHold`.

    Raises:
        ValueError: ``horizon`` below 1, or see :func:`goal_hold_starts`.
    """
    if horizon < 1:
        raise ValueError(f"horizon must be >= 1, got {horizon}.")
    if env_id.startswith("pcc/"):
        import pcc_envs  # noqa: F401  (registers the pcc/ ids)
    kwargs = {**(env_kwargs or {}), "max_episode_steps": int(horizon)}
    env = gym.make(env_id, **kwargs)
    try:
        starts = goal_hold_starts(env, num_starts, spread, seed)
        core = env.unwrapped
        steps_held = []
        for index, start in enumerate(starts):
            task = evaluate_control(policy, env_id, [index], kwargs,
                                    reset_options={"state": start}).tasks[0]
            inside = [bool(core.in_goal(np.asarray(s))) for s in task.states]
            steps_held.append(inside.index(False) if False in inside else len(inside))
    finally:
        env.close()
    return GoalHold(env_id=env_id, starts=starts.tolist(), steps_held=steps_held,
                    horizon=int(horizon))
