"""Latent diagnostics: exact values on a model with known dynamics, the CLI on a tiny grid."""

from __future__ import annotations

import json

import gymnasium as gym
import numpy as np
import pytest
import torch

from pcc_agent import diagnostics
from pcc_agent.diagnostics import (
    goal_aliasing,
    goal_linearization,
    goal_path_barrier,
    goal_prediction,
    knn_decodability,
    largest_climb,
    latent_diagnostics,
    state_decodability,
    true_goal_linearization,
)
from pcc_agent.model import EmbeddingModel
from pcc_agent.presets import get_preset
from pcc_bench import latent_diagnostics as cli
from pcc_envs.data import collect_transitions


def planar_model() -> EmbeddingModel:
    return EmbeddingModel((1, 40, 40), 2, get_preset("pcc/Planar-v0").model, seed=0)


def test_identity_dynamics_are_consistent_and_flat():
    """f(z, u) = z exactly: no curvature, and zero error when the observation does not move."""
    model = planar_model()
    with torch.no_grad():
        model.dynamics.head.weight.zero_()
        model.dynamics.head.bias.zero_()
    data = collect_transitions("pcc/Planar-v0", 64, seed=0)
    still = latent_diagnostics(model, data.obs, data.action, data.obs)
    assert still.consistency_error == 0.0 and still.curvature == pytest.approx(0.0, abs=1e-12)
    moved = latent_diagnostics(model, data.obs, data.action, data.next_obs)
    assert moved.consistency_error > 0 and moved.latent_scale > 0 and moved.num_samples == 64


def test_diagnostics_are_reproducible_and_check_their_input():
    model = planar_model()
    data = collect_transitions("pcc/Planar-v0", 40, seed=1)
    first = latent_diagnostics(model, data.obs, data.action, data.next_obs, batch_size=16)
    again = latent_diagnostics(model, data.obs, data.action, data.next_obs, batch_size=16)
    assert first == again and first.curvature > 0
    with pytest.raises(ValueError, match="same non-zero number"):
        latent_diagnostics(model, data.obs, data.action[:3], data.next_obs)
    with pytest.raises(ValueError, match="model expects"):
        latent_diagnostics(model, data.obs[:, :, :20], data.action, data.next_obs[:, :, :20])
    with pytest.raises(ValueError, match="Actions must be"):
        latent_diagnostics(model, data.obs, data.action[:, :1], data.next_obs)


def test_knn_decodability_finds_what_the_code_carries():
    """A code of (s0, 1e-3 s1) carries both coordinates (whitening), a code of s0 only one."""
    rng = np.random.default_rng(0)
    states = rng.uniform(-1.0, 1.0, size=(1500, 2))
    only_first = knn_decodability(states[:, :1], states)
    assert only_first[0] > 0.98 and abs(only_first[1]) < 0.2
    both = knn_decodability(np.c_[states[:, 0], 1e-3 * states[:, 1]], states)
    assert both.min() > 0.95


def test_knn_decodability_wraps_angles_with_the_env_state_error():
    env = gym.make("pcc/PendulumSwingUp-v0").unwrapped
    rng = np.random.default_rng(1)
    states = np.c_[rng.uniform(-np.pi, np.pi, 1500), rng.uniform(-1.0, 1.0, 1500)]
    code = np.c_[np.cos(states[:, 0]), np.sin(states[:, 0])]
    wrapped = knn_decodability(code, states, env.state_error)
    unwrapped = knn_decodability(code, states)
    assert wrapped[0] > 0.99 and unwrapped[0] < wrapped[0] - 0.01
    with pytest.raises(ValueError, match="same N"):
        knn_decodability(code[:10], states)
    with pytest.raises(ValueError, match="reference"):
        knn_decodability(code[:12], states[:12])


def test_state_decodability_of_a_model_checks_its_input():
    model = planar_model()
    data = collect_transitions("pcc/Planar-v0", 60, seed=2)
    first = state_decodability(model, data.obs, data.state, batch_size=16)
    assert first.shape == (2,) and np.isfinite(first).all()
    assert np.array_equal(first, state_decodability(model, data.obs, data.state))
    with pytest.raises(ValueError, match="model expects"):
        state_decodability(model, data.obs[:, :, :20], data.state)


def test_goal_linearization_of_a_constant_shift():
    """f(z, u) = z + b exactly: drift ||b|| / scale, A = I (all moduli 1), B = 0."""
    model = planar_model()
    with torch.no_grad():
        model.dynamics.head.weight.zero_()
        model.dynamics.head.bias.zero_()
        model.dynamics.head.bias[:2] = torch.tensor([0.3, -0.4])
    goal = gym.make("pcc/Planar-v0").unwrapped.goal_observation()
    found = goal_linearization(model, goal, scale=2.0)
    assert found.drift == pytest.approx(0.25, rel=1e-5)
    assert found.eigenvalue_moduli == pytest.approx((1.0, 1.0), abs=1e-6)
    assert found.spectral_radius == pytest.approx(1.0, abs=1e-6)
    assert found.controllability == (0.0, 0.0)
    with pytest.raises(ValueError, match="model expects"):
        goal_linearization(model, goal[:, :20])
    with pytest.raises(ValueError, match="scale must be > 0"):
        goal_linearization(model, goal, scale=0.0)


def test_goal_linearization_matches_autograd_jacobian():
    """The eigenvalues come from the same A that reverse-mode autograd gives at (z_g, 0)."""
    model = planar_model().eval()
    goal = gym.make("pcc/Planar-v0").unwrapped.goal_observation()
    with torch.no_grad():
        z_goal = model.encode(torch.as_tensor(goal[None]))[0][0]
    A = torch.autograd.functional.jacobian(  # noqa: N806
        lambda z: model.transition_mean(z[None], torch.zeros(1, 2))[0], z_goal)
    expected = np.sort(np.abs(np.linalg.eigvals(A.double().numpy())))[::-1]
    found = goal_linearization(model, goal)
    assert found.eigenvalue_moduli == pytest.approx(tuple(expected), rel=1e-4)
    assert found.controllability[0] == 1.0 and len(found.controllability) == 2


def test_true_goal_linearization_of_the_upright_cart_pole():
    """The upright pole's unstable rate is sqrt(g (M + m) / (l (4/3 (M + m) - m))) per second;
    one 20 ms RK4 step multiplies it by exp(rate * dt)."""
    env = gym.make("pcc/CartPole-v0")
    params = env.unwrapped.params
    total = params.cart_mass + params.pole_mass
    rate = np.sqrt(params.gravity * total
                   / (params.pole_half_length * (4.0 / 3.0 * total - params.pole_mass)))
    found = true_goal_linearization(env)
    assert found.drift == 0.0
    assert found.spectral_radius == pytest.approx(np.exp(rate * env.unwrapped.dt), rel=1e-5)
    assert found.eigenvalue_moduli[-1] == pytest.approx(np.exp(-rate * env.unwrapped.dt),
                                                        rel=1e-5)


def test_goal_prediction_of_dynamics_that_never_move_is_standing_still():
    """f(z, u) = z: the open-loop prediction is the start's code (error = hold's error) and
    the action moves nothing; the planar agent moves near the goal, so hold's error is > 0."""
    model = planar_model()
    with torch.no_grad():
        model.dynamics.head.weight.zero_()
        model.dynamics.head.bias.zero_()
    env = gym.make("pcc/Planar-v0")
    found = goal_prediction(model, env, horizon=5, num_starts=20, spread=0.2)
    assert found.error_over_hold == pytest.approx(1.0, rel=1e-6)
    assert found.action_effect == 0.0
    assert (found.horizon, found.num_starts) == (5, 20)
    assert goal_prediction(model, env, horizon=5, num_starts=20, spread=0.2) == found
    with pytest.raises(ValueError, match="cheap true dynamics"):
        goal_prediction(model, object())
    with pytest.raises(ValueError, match="horizon and num_starts"):
        goal_prediction(model, env, horizon=0)
    env.close()


def test_largest_climb_is_the_rise_above_the_running_minimum():
    assert largest_climb([5.0, 4.0, 6.0, 3.0, 0.0]) == 2.0
    assert largest_climb([3.0, 2.0, 2.0, 0.0]) == 0.0  # falls all the way: no barrier
    assert largest_climb([1.0, 4.0, 2.0, 5.0]) == 4.0
    assert largest_climb([]) == 0.0


@pytest.mark.parametrize("start_angle", [3.0, 3.5, -np.pi])
def test_goal_path_barrier_tries_both_ways_round_to_the_goal(start_angle, monkeypatch):
    """Two straight paths from the start to the goal state, one each way round the angle;
    the barrier is the lower climb of the latent distance to the goal's code along them."""
    env = gym.make("pcc/PendulumSwingUp-v0")
    core = env.unwrapped
    model = EmbeddingModel((2, 48, 48), 1, get_preset("pcc/PendulumSwingUp-v0").model, seed=0)
    goal_obs = core.goal_observation()
    rendered = []
    real = core.observations_of

    def record_paths(states):
        rendered.append(np.array(states))
        return real(states)

    monkeypatch.setattr(core, "observations_of", record_paths)
    start = np.array([start_angle, 0.5])
    barrier = goal_path_barrier(model, env, start, goal_obs, scale=2.0, num_points=11)
    (states,) = rendered
    paths = states.reshape(2, 11, 2)
    steps = np.diff(paths[:, :, 0], axis=1)
    assert {np.sign(steps[0, 0]), np.sign(steps[1, 0])} == {-1.0, 1.0}  # both ways round
    for path, step in zip(paths, steps):
        np.testing.assert_allclose(path[0], start)
        np.testing.assert_allclose(core.state_error(path[-1:])[0], 0.0, atol=1e-12)
        np.testing.assert_allclose(path[:, 1], np.linspace(0.5, 0.0, 11))  # rate to rest
        assert np.allclose(step, step[0])  # straight
    # the short way first: at most half a turn
    assert abs(paths[0, -1, 0] - start_angle) <= np.pi + 1e-12
    with torch.no_grad():
        codes = model.encode(torch.as_tensor(real(states)))[0]
        goal = model.encode(torch.as_tensor(goal_obs[None]))[0]
    distances = (codes - goal).norm(dim=-1).numpy().reshape(2, 11)
    assert barrier == pytest.approx(min(map(largest_climb, distances)) / 2.0, rel=1e-5)
    with pytest.raises(ValueError, match="start state has shape"):
        goal_path_barrier(model, env, np.zeros(3), goal_obs)
    env.close()


def test_goal_path_barrier_of_an_env_without_angles_has_one_path(monkeypatch):
    env = gym.make("pcc/Planar-v0")
    core = env.unwrapped
    goal_obs = core.goal_observation()
    rendered = []
    real = core.observations_of
    monkeypatch.setattr(core, "observations_of", lambda s: rendered.append(s) or real(s))
    barrier = goal_path_barrier(planar_model(), env, np.array([3.0, 3.0]), goal_obs,
                                num_points=5)
    np.testing.assert_allclose(rendered[0], np.linspace([3.0, 3.0], core.goal_state, 5))
    assert barrier >= 0.0
    env.close()


def test_goal_aliasing_is_small_for_a_faithful_code_and_near_one_for_a_fold(monkeypatch):
    """The states coded nearest the goal: its state neighbours under a code that is the state,
    the far side of the room under a code that folds the room onto itself."""
    rng = np.random.default_rng(0)
    states = rng.uniform(0.0, 40.0, size=(2000, 2))
    goal = np.array([37.0, 37.0])
    obs = np.zeros((len(states), 1, 40, 40), dtype=np.uint8)  # stand-ins: the codes are patched
    goal_obs = np.ones((1, 40, 40), dtype=np.uint8)
    model = planar_model()

    def codes_of(code_of_state):
        def encoder_means(model, observations, batch_size=500):
            return np.array([goal]) if observations[0].any() else code_of_state(states)
        return encoder_means

    monkeypatch.setattr(diagnostics, "_encoder_means", codes_of(lambda s: s))
    faithful = goal_aliasing(model, obs, states, goal_obs, goal)
    # a four-fold map: (x, y), (40 - x, y), (x, 40 - y) and (40 - x, 40 - y) share a code
    monkeypatch.setattr(diagnostics, "_encoder_means",
                        codes_of(lambda s: np.abs(s - 20.0) + 20.0))
    folded = goal_aliasing(model, obs, states, goal_obs, goal)
    from_goal = np.linalg.norm(states - goal, axis=1)
    assert faithful < 0.1
    assert faithful == pytest.approx(np.sort(from_goal)[:10].max() / np.median(from_goal))
    assert folded > 1.5  # some of the nearest codes are states across the room
    with pytest.raises(ValueError, match="neighbours must be between 1"):
        goal_aliasing(model, obs, states, goal_obs, goal, neighbours=0)
    with pytest.raises(ValueError, match="goal state"):
        goal_aliasing(model, obs, states[:, :1], goal_obs, goal)


def test_spearman_matches_known_values():
    assert cli.spearman([1, 2, 3, 4], [10, 20, 30, 40]) == pytest.approx(1.0)
    assert cli.spearman([1, 2, 3, 4], [4, 3, 2, 1]) == pytest.approx(-1.0)
    assert cli.spearman([1, 1, 2, 3], [0, 0, 5, 5]) == pytest.approx(np.corrcoef(
        [0.5, 0.5, 2, 3], [0.5, 0.5, 2.5, 2.5])[0, 1])
    assert cli.spearman([1, 2], [1, 2]) is None and cli.spearman([1, 1, 1], [1, 2, 3]) is None


def test_cli_on_a_tiny_grid(tmp_path):
    from pcc_bench.records import RunSpec, checkpoint_path
    from pcc_bench.runs import execute_run

    for seed in (0, 1, 2):
        spec = RunSpec(env_id="pcc/Planar-v0", method="pcc", seed=seed, noise_std=0.0,
                       num_tasks=1, task_seed=7, model_variant="paper", preset="tiny",
                       num_samples=128, max_epochs=1)
        execute_run(spec, tmp_path, str(tmp_path / "data"))
    checkpoint_path(tmp_path, spec).unlink()  # seed 2: its float16 weights are enough
    out = tmp_path / "diag" / "Planar-v0_tiny"
    assert cli.main(["--results-dir", str(tmp_path), "--preset", "tiny", "--samples", "50",
                     "--output", str(out)]) == 0
    result = json.loads(out.with_name(out.name + ".json").read_text())
    assert [row["seed"] for row in result["rows"]] == [0, 1, 2]
    assert result["spearman"]["pcc"]["n_models"] == 3
    assert "--preset tiny" in result["command"]
    text = out.with_name(out.name + ".md").read_text()
    assert "| pcc | 2 |" in text and "goal path barrier | goal aliasing |" in text
    assert "goal action effect | goal hold |" in text and "Goal hold: from 5 starts" in text
    # Planar's true dynamics are x + u: every eigenvalue is 1.
    assert "The true dynamics at the goal state: spectral radius 1.000" in text
    assert result["true_goal_linearization"]["eigenvalue_moduli"] == pytest.approx([1.0, 1.0])
    for row in result["rows"]:
        assert len(row["state_r2"]) == 2
        assert row["min_state_r2"] == pytest.approx(min(row["state_r2"]), abs=1e-4)
        assert row["goal_drift"] >= 0 and row["goal_spectral_radius"] > 0
        assert row["goal_path_barrier"] is not None and row["goal_path_barrier"] >= 0
        assert row["goal_aliasing"] >= 0
        assert 0 <= row["goal_hold_steps"] <= 100
    with pytest.raises(SystemExit, match="at least 30"):
        cli.main(["--results-dir", str(tmp_path), "--preset", "tiny", "--samples", "20",
                  "--output", str(out)])
    with pytest.raises(SystemExit, match="No finished"):
        cli.main(["--results-dir", str(tmp_path), "--preset", "other", "--output", str(out)])

