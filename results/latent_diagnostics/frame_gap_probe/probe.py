"""Probe (2026-12-06, seventh session; committed as the record of the experiment): do the
arms' outer joint rates enter the code when the two frames lie ``frame_gap`` control periods
apart instead of one?

At 50 Hz a 3-link joint turning at pi rad/s moves its 12-pixel link by under a pixel between
consecutive frames, and every 3-link model so far codes the outer joints' rates with k-NN
state R^2 near 0. ``frame_gap`` (an env argument) changes only what the camera shows: the
dynamics, tasks and goal stay, so the oracle and every other row stay comparable.

Every ``--every`` epochs it scores the model on 3,000 held-out transitions of the same env
arguments (k-NN state R^2 per coordinate) and on validation tasks (seed 2021, perturbed
starts), and keeps the best-controlling weights.
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
from pcc_envs.data import collect_transitions

p = argparse.ArgumentParser()
p.add_argument("--env", default="pcc/ThreeLink-v0")
p.add_argument("--variant", default="motion")
p.add_argument("--frame-gap", type=int, default=1)
p.add_argument("--epochs", type=int, default=20)
p.add_argument("--every", type=int, default=5)
p.add_argument("--seed", type=int, default=0)
p.add_argument("--tasks", type=int, default=10)
p.add_argument("--out", required=True)
a = p.parse_args()
torch.set_num_threads(1)
preset = get_preset(a.env, a.variant).with_training(flush_denormals=True, epochs=a.epochs)
env_kwargs = {"frame_gap": a.frame_gap}
data = collect_transitions(a.env, 3000, seed=999_983, env_kwargs=env_kwargs)  # held out
env = gym.make(a.env, **env_kwargs).unwrapped
log, t0 = [], time.time()


def score(agent):
    r2 = state_decodability(agent.model, data.obs, data.state, env.state_error)
    validation = evaluate_on_validation_tasks(agent, a.env, a.tasks, env_kwargs).mean
    log.append({"minutes": round((time.time() - t0) / 60, 1), "r2": np.round(r2, 3).tolist(),
                "validation": validation})
    print(log[-1], flush=True)
    with open(a.out, "w") as f:
        json.dump({"args": vars(a), "model": dataclasses.asdict(preset.model), "log": log}, f,
                  indent=1)
    return validation


agent = PCCAgent(a.env, "pcc", preset=preset, seed=a.seed, device="cpu", env_kwargs=env_kwargs)
agent.learn(callback=KeepBestControl(score, every=a.every, start=a.every, verbose=1),
            progress_bar=False)
print("done", round(time.time() - t0), "s", flush=True)
