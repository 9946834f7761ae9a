"""Training callbacks for :meth:`PCCAgent.learn <pcc_agent.agent.PCCAgent.learn>`.

:class:`KeepBestControl` keeps the weights that control best on validation tasks instead of
the weights of the lowest validation loss. The loss is a poor guide to control on some
domains: two Pendulum-from-pixels trainings reached the same validation loss (105.2), one
kept the pendulum upright 49 % of the time and the other never (``RESULTS_LOG.md``, fourth
session of 2026-12-05). Scoring control every few epochs costs a few planned episodes.
"""

from __future__ import annotations

import copy
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import torch
from stable_baselines3.common.callbacks import BaseCallback

__all__ = ["KeepBestControl", "validation_task_score"]


class KeepBestControl(BaseCallback):
    """Score control every ``every`` epochs and end training with the best-scoring weights.

    Every ``every`` epochs from epoch ``start`` on, ``score(agent)`` is called (it should plan
    on validation tasks, never on the tasks you report) and the weights are copied when the
    score beats every earlier one. When training ends, the trainer has restored the weights
    of its lowest validation loss; they are scored too, and replaced by the copy only if the
    copy scored higher. One training step is one epoch (see ``PCCAgent.learn``).

    With ``state_path``, the history and the best weights so far are written to that file
    after every score, and a training resumed from a checkpoint (``learn(resume=True)``)
    goes on from them; without it, a resumed training starts a new history. Scores of epochs
    that the resumed training repeats are replaced by the new ones; weights kept from such an
    epoch stay candidates (they were trained and scored). The file is left in place at the
    end (a run killed after training but before its results are written resumes from it):
    delete it when the results are safe.

    Attributes:
        history: ``(epoch, score)`` of every scored epoch, and ``(-1, score)`` for the
            trainer's final weights.
        best_epoch: The epoch whose weights the agent ended with (-1: the trainer's own).
        best_score: Their score.

    Example:
        >>> from pcc_agent.callbacks import KeepBestControl, validation_task_score
        >>> keep = KeepBestControl(validation_task_score("pcc/Planar-v0"), every=25)
        >>> agent.learn(callback=keep)  # doctest: +SKIP
    """

    def __init__(self, score: Callable[[Any], float], every: int = 10, start: int = 0,
                 verbose: int = 0, state_path: str | os.PathLike[str] | None = None) -> None:
        super().__init__(verbose)
        if not callable(score):
            raise TypeError(f"score must be a function agent -> float, got {score!r}.")
        if every < 1:
            raise ValueError(f"every must be >= 1 epoch, got {every}.")
        if start < 0:
            raise ValueError(f"start must be >= 0, got {start}.")
        self.score, self.every, self.start = score, every, start
        self.state_path = None if state_path is None else Path(state_path)
        self.history: list[tuple[int, float]] = []
        self.best_epoch: int | None = None
        self.best_score: float | None = None
        self._best_state: dict[str, torch.Tensor] | None = None

    def _scored(self) -> float:
        """The agent's score, with the model's mode and the planner's random draws put back.

        So training and later planning go on as they would without the callback.
        """
        network = self.model.model
        was_training = network.training
        draws = self.model._plan_generator.get_state()
        try:
            value = float(self.score(self.model))
        finally:
            network.train(was_training)
            self.model._plan_generator.set_state(draws)
        if value != value:  # NaN
            raise ValueError("score(agent) returned NaN.")
        return value

    def _on_training_start(self) -> None:
        self.history, self.best_epoch, self.best_score, self._best_state = [], None, None, None
        if (self.state_path is not None and self.locals.get("resume")
                and self.state_path.is_file()):
            self._load_state()

    def _on_step(self) -> bool:
        epoch = int(self.locals["epoch"])
        if epoch < self.start or epoch % self.every:
            return True
        value = self._scored()
        # A resumed training repeats the epochs after its checkpoint: their new scores count.
        self.history = [(e, v) for e, v in self.history if e < epoch] + [(epoch, value)]
        if self.verbose:
            print(f"epoch {epoch}: control score {value:.1f}")
        if self.best_score is None or value > self.best_score:
            self.best_epoch, self.best_score = epoch, value
            self._best_state = copy.deepcopy(self.model.model.state_dict())
        self._save_state()
        return True

    @property
    def best_state(self) -> dict[str, torch.Tensor] | None:
        """The best-scoring weights so far (during training; ``None`` before the first score).

        For callers that stop at a moment of their own choosing, such as a wall-clock budget
        (``pcc_bench.time_to_control``). Treat it as read-only: it is the callback's copy.
        """
        return self._best_state

    def _save_state(self) -> None:
        if self.state_path is None:
            return
        from pcc_agent.io import atomic_torch_save

        atomic_torch_save({"history": [[e, v] for e, v in self.history],
                           "best_epoch": self.best_epoch, "best_score": self.best_score,
                           "best_state": self._best_state}, self.state_path)

    def _load_state(self) -> None:
        from pcc_agent.checkpoint import CheckpointError, torch_load_safely

        assert self.state_path is not None
        state = torch_load_safely(self.state_path)
        try:
            self.history = [(int(e), float(v)) for e, v in state["history"]]
            self.best_epoch, self.best_score = state["best_epoch"], state["best_score"]
            self._best_state = state["best_state"]
        except (KeyError, TypeError, ValueError) as error:
            raise CheckpointError(
                f"{self.state_path} is not a KeepBestControl state ({error!r}); delete it to "
                "start the control history afresh.") from error

    def _on_training_end(self) -> None:
        final = self._scored()
        self.history.append((-1, final))
        if self._best_state is not None and self.best_score is not None and (
                self.best_score > final):
            self.model.model.load_state_dict(self._best_state)
        else:
            self.best_epoch, self.best_score = -1, final
        self._best_state = None
        if self.verbose:
            print(f"kept the weights of epoch {self.best_epoch} (-1: lowest validation loss), "
                  f"control score {self.best_score:.1f}")


def validation_task_score(env_id: str, num_tasks: int = 5, env_kwargs: dict[str, Any] | None
                          = None) -> Callable[[Any], float]:
    """A ``score`` for :class:`KeepBestControl`: % in goal on validation tasks of a pcc env.

    The tasks are drawn with ``pcc_agent.evaluation.VALIDATION_TASK_SEED`` (2021), never the
    evaluation tasks' 2020.
    """
    from pcc_agent.evaluation import evaluate_on_validation_tasks

    if num_tasks < 1:
        raise ValueError(f"num_tasks must be >= 1, got {num_tasks}.")

    def score(agent: Any) -> float:
        return evaluate_on_validation_tasks(agent, env_id, num_tasks, env_kwargs).mean

    return score
