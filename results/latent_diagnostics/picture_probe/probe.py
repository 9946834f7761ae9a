"""Probe (2026-12-06, third session; committed as the record of the experiment): does the PCC
authors' cart-pole picture (pcc/CartPole-v1: a 52 x 6 pixel pole) let a CPU-sized model learn
the pole's dynamics that the picture drawn to scale (pcc/CartPole-v0: 15 x 2.5 pixels) hides?

Every ``--every`` epochs it scores the model on held-out data and validation tasks (seed 2021):
k-NN state R^2 per coordinate, the pole angle error of 1- and 10-step open-loop latent
predictions from near-upright starts (against holding the start), the action's one-step effect
on the predicted code over the one-step prediction error (near upright), and % in goal.
"""
import argparse, dataclasses, json, time
import numpy as np, torch
import gymnasium as gym
import pcc_envs  # noqa: F401
from pcc_agent.agent import PCCAgent
from pcc_agent.callbacks import KeepBestControl
from pcc_agent.diagnostics import state_decodability
from pcc_agent.evaluation import evaluate_on_validation_tasks
from pcc_agent.presets import get_preset
from pcc_bench.latent_diagnostics import _held_out_transitions

p = argparse.ArgumentParser()
p.add_argument("--env", default="pcc/CartPole-v1")
p.add_argument("--variant", default="fast")
p.add_argument("--epochs", type=int, default=30)
p.add_argument("--every", type=int, default=5)
p.add_argument("--seed", type=int, default=0)
p.add_argument("--tasks", type=int, default=5)
p.add_argument("--transition-hidden", type=int, nargs="+", default=None,
               help="Hidden widths of the transition MLP (default: the preset's).")
p.add_argument("--sampler-angle", type=float, default=None,
               help="The env's data sampler angle range (default: the env's, pi/2).")
p.add_argument("--out", required=True)
a = p.parse_args()
torch.set_num_threads(1)
base = get_preset(a.env, a.variant)
preset = base.with_training(flush_denormals=True, epochs=a.epochs)
if a.transition_hidden:
    preset = dataclasses.replace(preset, model=dataclasses.replace(
        preset.model, transition_hidden=tuple(a.transition_hidden)))
env_kwargs = {} if a.sampler_angle is None else {"sampler_angle": a.sampler_angle}
data = _held_out_transitions(a.env, 3000, 0.0)  # the default sampler box: the same data for all
env = gym.make(a.env).unwrapped

# Near-upright starts and random actions for the open-loop prediction test.
rng = np.random.default_rng(1_000_001)
n, horizon = 200, 10
starts = np.zeros((n, 4))
starts[:, 0] = rng.uniform(-np.pi / 10, np.pi / 10, n)
starts[:, 1] = rng.uniform(-0.5, 0.5, n)
starts[:, 2] = rng.uniform(-0.5, 0.5, n)
actions = rng.uniform(-1, 1, (horizon, n, 1))
trajectory = [starts]
for k in range(horizon):
    trajectory.append(np.stack([env.transition(s, u) for s, u in zip(trajectory[-1], actions[k])]))


def angle_error(a_, b_):
    return float(np.abs(np.angle(np.exp(1j * (a_ - b_)))).mean())


def prediction_errors(model):
    with torch.no_grad():
        codes = model.encode(torch.as_tensor(data.obs))[0].numpy()
        z = z_start = model.encode(torch.as_tensor(env.observations_of(starts)))[0]
        out = {}
        for k in range(1, horizon + 1):
            z = model.transition_mean(z, torch.as_tensor(actions[k - 1], dtype=z.dtype))
            if k == 1:  # the action's one-step effect on the code, against the one-step error
                codes_next = model.encode(torch.as_tensor(env.observations_of(trajectory[1])))[0]
                idle = model.transition_mean(z_start, torch.zeros(n, 1, dtype=z.dtype))
                error = (z - codes_next).norm(dim=1).mean()
                out["action_effect_1"] = round(float((z - idle).norm(dim=1).mean() / error), 4)
            if k in (1, horizon):
                d = ((z.numpy()[:, None] - codes[None]) ** 2).sum(-1)
                theta = data.state[np.argsort(d, axis=1)[:, :10], 0]
                predicted = np.angle(np.exp(1j * theta).mean(1))  # circular k-NN mean
                out[f"theta_err_{k}"] = round(angle_error(predicted, trajectory[k][:, 0]), 4)
                out[f"theta_hold_{k}"] = round(angle_error(starts[:, 0], trajectory[k][:, 0]), 4)
    return out


log = []
t0 = time.time()


def score(agent):
    r2 = state_decodability(agent.model, data.obs, data.state, env.state_error)
    row = {"minutes": round((time.time() - t0) / 60, 1), "r2": np.round(r2, 3).tolist(),
           **prediction_errors(agent.model)}
    ev = evaluate_on_validation_tasks(agent, a.env, a.tasks, env_kwargs)
    row["validation"] = ev.mean
    log.append(row)
    print(row, flush=True)
    with open(a.out, "w") as f:
        json.dump({"args": vars(a), "model": dataclasses.asdict(preset.model), "log": log}, f,
                  indent=1)
    return ev.mean


agent = PCCAgent(a.env, "pcc", preset=preset, seed=a.seed, device="cpu",
                 env_kwargs=env_kwargs)
agent.learn(callback=KeepBestControl(score, every=a.every, start=a.every, verbose=1),
            progress_bar=False)
print("done", round(time.time() - t0), "s")
