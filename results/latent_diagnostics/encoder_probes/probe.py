"""Probe (2026-12-06, second session; committed as the record of the experiment): does a keypoint encoder put CartPole's rates into the PCC code?"""
import argparse, dataclasses, json, time, sys
import numpy as np, torch
from pcc_agent.agent import PCCAgent
from pcc_agent.callbacks import KeepBestControl
from pcc_agent.config import ConvSpec
from pcc_agent.diagnostics import state_decodability
from pcc_agent.evaluation import evaluate_on_validation_tasks
from pcc_agent.presets import get_preset
from pcc_bench.latent_diagnostics import _held_out_transitions
import gymnasium as gym, pcc_envs  # noqa

p = argparse.ArgumentParser()
p.add_argument("--variant", default="kp")
p.add_argument("--env", default="pcc/CartPole-v0")
p.add_argument("--epochs", type=int, default=30)
p.add_argument("--every", type=int, default=10)
p.add_argument("--seed", type=int, default=0)
p.add_argument("--tasks", type=int, default=5)
p.add_argument("--out", required=True)
a = p.parse_args()
torch.set_num_threads(1)
base = get_preset(a.env, "fast")
m = base.model
if a.variant == "kp":
    m = dataclasses.replace(m, encoder_kind="keypoints", encoder_downsample=2,
        encoder_convs=(ConvSpec(16, 5, 2), ConvSpec(16, 3, 1), ConvSpec(16, 1, 1)),
        decoder_pixel_shuffle=True, decoder_convs=(ConvSpec(16, 3, 1), ConvSpec(32, 3, 1)))
elif a.variant == "kp-std":
    m = dataclasses.replace(m, encoder_kind="keypoints", encoder_downsample=2, input_standardization=True,
        encoder_convs=(ConvSpec(16, 5, 2), ConvSpec(16, 3, 1), ConvSpec(16, 1, 1)),
        decoder_pixel_shuffle=True, decoder_convs=(ConvSpec(16, 3, 1), ConvSpec(32, 3, 1)))
elif a.variant.startswith("diff"):
    m = dataclasses.replace(m, encoder_motion_gain=float(a.variant[4:]),
        decoder_pixel_shuffle=True, decoder_convs=(ConvSpec(16, 3, 1), ConvSpec(32, 3, 1)))
elif a.variant == "frame":
    m = dataclasses.replace(m, encoder_kind="frame_cnn",
        decoder_pixel_shuffle=True, decoder_convs=(ConvSpec(16, 3, 1), ConvSpec(32, 3, 1)))
elif a.variant == "kp-noshuffle":
    m = dataclasses.replace(m, encoder_kind="keypoints", encoder_downsample=2,
        encoder_convs=(ConvSpec(16, 5, 2), ConvSpec(16, 3, 1), ConvSpec(16, 1, 1)))
preset = dataclasses.replace(base.with_training(flush_denormals=True, epochs=a.epochs), model=m)
data = _held_out_transitions(a.env, 3000, 0.0)
env = gym.make(a.env)
log = []
t0 = time.time()
def score(agent):
    r2 = state_decodability(agent.model, data.obs, data.state, env.unwrapped.state_error)
    ev = evaluate_on_validation_tasks(agent, a.env, a.tasks)
    row = {"minutes": round((time.time() - t0) / 60, 1), "r2": np.round(r2, 3).tolist(),
           "validation": ev.mean, "per_task": [round(t.percent_in_goal, 1) for t in ev.tasks] if hasattr(ev.tasks[0], "percent_in_goal") else None}
    log.append(row); print(row, flush=True)
    json.dump({"args": vars(a), "model": dataclasses.asdict(m), "log": log}, open(a.out, "w"), indent=1)
    return ev.mean
agent = PCCAgent(a.env, "pcc", preset=preset, seed=a.seed, device="cpu")
keep = KeepBestControl(score, every=a.every, start=a.every, verbose=1)
agent.learn(callback=keep, progress_bar=False)
print("train result", agent.train_result.epochs if agent.train_result else None, time.time() - t0)
