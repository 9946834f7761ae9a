"""pcc_agent.callbacks: keeping the weights that control best on validation tasks."""

from __future__ import annotations

import dataclasses

import gymnasium as gym
import numpy as np
import pytest
import torch

import pcc_envs  # noqa: F401
from pcc_agent import PCCAgent
from pcc_agent.callbacks import KeepBestControl, validation_task_score
from pcc_agent.planning.config import PlannerConfig
from pcc_agent.presets import get_preset

ENV_ID = "pcc/Planar-v0"


def tiny_agent(cache, epochs: int = 4) -> PCCAgent:
    preset = get_preset(ENV_ID)
    preset = dataclasses.replace(
        preset, train=dataclasses.replace(preset.train, epochs=epochs, batch_size=64),
        planner=PlannerConfig(plan_length=5, iterations=2, mpc_iterations=1, num_candidates=2))
    return PCCAgent(ENV_ID, method="pcc", preset=preset, seed=1, data_cache_dir=cache)


def weights(agent: PCCAgent) -> dict[str, torch.Tensor]:
    return {k: v.clone() for k, v in agent.model.state_dict().items()}


def scripted(values: list[float], seen: list[dict[str, torch.Tensor]]):
    """A score that plans one step (as a real score would) and returns the next value."""
    obs, _ = gym.make(ENV_ID).reset(seed=5)

    def score(agent: PCCAgent) -> float:
        agent.predict(obs)
        seen.append(weights(agent))
        return values[len(seen) - 1]

    return score


def same(a: dict[str, torch.Tensor], b: dict[str, torch.Tensor]) -> bool:
    return a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)


def test_training_ends_with_the_weights_of_the_best_score(tmp_path):
    seen: list[dict[str, torch.Tensor]] = []
    keep = KeepBestControl(scripted([5.0, 1.0, 3.0], seen), every=2)  # epochs 2, 4, the end
    agent = tiny_agent(tmp_path).learn(total_timesteps=300, callback=keep)
    assert keep.history == [(2, 5.0), (4, 1.0), (-1, 3.0)]
    assert keep.best_epoch == 2 and keep.best_score == 5.0
    assert same(weights(agent), seen[0]) and not same(seen[0], seen[2])


def test_the_trainers_weights_stay_when_they_score_best_and_nothing_else_changes(tmp_path):
    obs, _ = gym.make(ENV_ID).reset(seed=9)
    plain = tiny_agent(tmp_path).learn(total_timesteps=300)
    seen: list[dict[str, torch.Tensor]] = []
    keep = KeepBestControl(scripted([1.0, 2.0, 3.0, 4.0], seen), every=1, start=2)
    agent = tiny_agent(tmp_path).learn(total_timesteps=300, callback=keep)
    assert [epoch for epoch, _ in keep.history] == [2, 3, 4, -1] and keep.best_epoch == -1
    # Scoring (planning mid-training) changed neither the training nor later planning.
    assert same(weights(agent), weights(plain))
    assert agent.predict(obs)[0].tolist() == plain.predict(obs)[0].tolist()


def test_scores_during_training_plan_with_that_epochs_model(tmp_path):
    """Each mid-training score plans with the current weights: goal code and dynamics.

    (The fused Adam step does not bump the weights' version counters; the planner of the
    first scored epoch was once kept for the whole training.)
    """
    goal_codes: list[tuple[torch.Tensor, torch.Tensor]] = []

    def score(agent: PCCAgent) -> float:
        planned = agent.mpc.cost.goal.clone()
        with torch.no_grad():
            fresh = agent.model.encode(torch.as_tensor(agent.goal_observation[None]))[0][0]
        goal_codes.append((planned, fresh))
        return 0.0

    tiny_agent(tmp_path, epochs=3).learn(total_timesteps=300,
                                         callback=KeepBestControl(score, every=1))
    assert len(goal_codes) == 4  # epochs 1-3 and the end
    for planned, fresh in goal_codes:
        assert torch.allclose(planned, fresh)
    assert not torch.allclose(goal_codes[0][0], goal_codes[2][0])


def test_a_resumed_training_keeps_the_control_history_and_best_weights(tmp_path):
    """Killed at epoch 3 (checkpoint at 2), resumed: epoch 1's weights still win."""
    values = {1: 9.0, 2: 1.0, 3: 3.0, 4: 2.0}
    seen: dict[int, dict[str, torch.Tensor]] = {}

    def score(agent: PCCAgent, interrupt_at: int | None = None) -> float:
        epoch = agent.num_timesteps // 300
        if epoch == interrupt_at:
            raise KeyboardInterrupt
        seen.setdefault(epoch, weights(agent))
        return values[epoch]

    state, checkpoint = tmp_path / "control.pt", tmp_path / "training.pt"
    first = KeepBestControl(lambda agent: score(agent, interrupt_at=3), every=1,
                            state_path=state)
    with pytest.raises(KeyboardInterrupt):
        tiny_agent(tmp_path).learn(total_timesteps=300, callback=first,
                                   checkpoint_path=checkpoint, checkpoint_every=2)
    assert first.history == [(1, 9.0), (2, 1.0)] and state.is_file()
    resumed = KeepBestControl(score, every=1, state_path=state)
    agent = tiny_agent(tmp_path).learn(total_timesteps=300, callback=resumed,
                                       checkpoint_path=checkpoint, resume=True)
    assert resumed.history == [(1, 9.0), (2, 1.0), (3, 3.0), (4, 2.0), (-1, 2.0)]
    assert resumed.best_epoch == 1 and same(weights(agent), seen[1])
    # Without resume=True the file is ignored: a new training starts a new history.
    fresh = KeepBestControl(score, every=2, state_path=state)
    tiny_agent(tmp_path, epochs=2).learn(total_timesteps=300, callback=fresh)
    assert fresh.history == [(2, 1.0), (-1, 1.0)]


def test_validation_task_score_plans_on_the_validation_tasks(tmp_path):
    agent = tiny_agent(tmp_path, epochs=1).learn(total_timesteps=200)
    value = validation_task_score(ENV_ID, num_tasks=1)(agent)
    assert 0.0 <= value <= 100.0


def test_validation_tasks_start_from_the_validation_starts():
    from pcc_agent.evaluation import evaluate_control, evaluate_on_validation_tasks

    class ZeroTorque:
        def predict(self, obs, state=None, episode_start=None, deterministic=True):
            return np.zeros((len(obs), 1), dtype=np.float32), state

    zero = ZeroTorque()
    env_id = "pcc/PendulumSwingUp-v0"  # every evaluation task starts hanging at rest
    validation = evaluate_on_validation_tasks(zero, env_id, num_tasks=2)
    starts = [t.states[0] for t in validation.tasks]
    assert not np.allclose(starts[0], starts[1])
    assert all(abs(abs(s[0]) - np.pi) <= np.pi / 8 + 0.05 for s in starts)  # one step on
    seeds = [t.seed for t in validation.tasks]
    plain = evaluate_control(zero, env_id, seeds)
    assert all(np.allclose(t.states[0], [-np.pi, 0.0]) for t in plain.tasks)


@pytest.mark.parametrize("kwargs, error", [
    ({"score": 3}, TypeError), ({"score": len, "every": 0}, ValueError),
    ({"score": len, "start": -1}, ValueError)])
def test_bad_settings_are_refused(kwargs, error):
    with pytest.raises(error):
        KeepBestControl(**kwargs)
    with pytest.raises(ValueError, match="num_tasks"):
        validation_task_score(ENV_ID, num_tasks=0)
