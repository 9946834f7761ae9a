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
    "TaskResult",
    "evaluate_control",
    "evaluate_on_validation_tasks",
    "format_mean_se",
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
