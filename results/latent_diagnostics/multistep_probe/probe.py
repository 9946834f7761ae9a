"""Probe (2026-12-07, third session; committed as the record of the experiment): does a
multi-step prediction term put the arms' outer joint rates into the code?

Every arm model so far codes the angles and the base joint's rate, and the outer joints'
rates not at all (k-NN state R^2 near 0), whatever the encoder sees (frame gaps 3 and 5,
magnified differences, keypoints): the one-step objective gains too little from them. The
paper's deterministic cross-entropy ``-log D(x_{t+1} | f(mu(x_t), u_t))`` is extended here to
``k = 2..K`` steps, ``-log D(x_{t+k} | f^k(mu(x_t), u_t..u_{t+k-1}))``, on chains of random
actions from the paper's uniform state sampler: a rate left out of the code shows as a drift
that grows with ``k``. Weight ``--coef`` per extra step (the one-step term's 0.3 by default).
The rest is the paper's PCC objective on the chains' first transitions, trained with the
library's model, loss and Adam settings in a plain loop (not ``pcc_agent.training.Trainer``;
no early stopping). ``--horizon 1`` is the same loop without the new term. ``--goal-fraction``
starts that share of the chains near the goal instead (the arms' balance needs the dynamics
there, which the uniform sampler visits rarely).

Every ``--every`` epochs it scores k-NN state R^2 on 3,000 held-out transitions and % in
goal on validation tasks (seed 2021, perturbed starts).
"""
import argparse, dataclasses, json, time

import numpy as np, torch
import gymnasium as gym

import pcc_envs  # noqa: F401
from pcc_agent.agent import PCCAgent
from pcc_agent.diagnostics import state_decodability
from pcc_agent.evaluation import evaluate_on_validation_tasks
from pcc_agent.losses import TransitionBatch, pcc_loss
from pcc_agent.presets import get_preset
from pcc_agent.training import _make_adam, flushed_denormals
from pcc_envs.data import collect_transitions

p = argparse.ArgumentParser()
p.add_argument("--env", default="pcc/TwoLink-v0")
p.add_argument("--variant", default="motion")
p.add_argument("--horizon", type=int, default=3, help="K: steps of the longest prediction")
p.add_argument("--coef", type=float, default=0.3)
p.add_argument("--epochs", type=int, default=10)
p.add_argument("--every", type=int, default=5)
p.add_argument("--seed", type=int, default=0)
p.add_argument("--tasks", type=int, default=10)
p.add_argument("--goal-fraction", type=float, default=0.0,
               help="share of chains started near the goal state: every angle within "
               "--goal-angle of it, every rate within --goal-rate (the rest: uniform)")
p.add_argument("--goal-angle", type=float, default=np.pi / 4)
p.add_argument("--goal-rate", type=float, default=np.pi)
p.add_argument("--samples", type=int, default=None, help="chains (default: the preset's data size)")
p.add_argument("--plan-lengths", type=int, nargs="*", default=[],
               help="also score the validation tasks with these plan lengths")
p.add_argument("--save", default=None, help="save the agent here at every scoring (_ep<E>.pt)")
p.add_argument("--out", required=True)
a = p.parse_args()
torch.set_num_threads(1)
preset = get_preset(a.env, a.variant)
config = preset.train
env = gym.make(a.env).unwrapped
rng = np.random.default_rng(a.seed)


def chains(n: int, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Frames ``(n, k + 2, H, W)`` of ``s_0 .. s_{k+1}`` and actions ``(n, k, A)`` (u_1..u_k).

    ``s_0`` is uniform on the sampler's box (or, a ``--goal-fraction`` of them, near the goal), ``s_1`` one random action later (the older frame
    of the first observation, as in ``pcc_envs.data.collect_transitions``).
    """
    frames = np.empty((n, k + 2, *env.frame_shape), dtype=np.uint8)
    actions = np.empty((n, k, env.action_dim), dtype=np.float32)
    for start in range(0, n, 2000):
        m = min(2000, n - start)
        state = env.sample_states(rng, m)
        near = rng.random(m) < a.goal_fraction
        half = env.state_dim // 2  # the arms' states: angles, then rates
        spread = np.r_[np.full(half, a.goal_angle), np.full(half, a.goal_rate)]
        state[near] = env.goal_state + rng.uniform(-spread, spread, (int(near.sum()), len(spread)))
        frames[start:start + m, 0] = env.render_states(state)
        for step in range(k + 1):
            action = env.sample_action(rng, m).astype(np.float32)
            state = env.transition(state, action.astype(np.float64))
            frames[start:start + m, step + 1] = env.render_states(state)
            if step:
                actions[start:start + m, step - 1] = action
    return frames, actions


t0 = time.time()
frames, actions = chains(a.samples or preset.data.num_samples, a.horizon)
held_out = collect_transitions(a.env, 3000, seed=999_983)
print(f"data: {frames.shape} in {time.time() - t0:.0f} s", flush=True)
n_val = len(frames) // 10
order = rng.permutation(len(frames))
train_idx, val_idx = order[n_val:], order[:n_val]
frames_t, actions_t = torch.from_numpy(frames), torch.from_numpy(actions)

agent = PCCAgent(a.env, "pcc", preset=preset, seed=a.seed, device="cpu")
model = agent.model
optimizer = _make_adam(model, config)
generator = torch.Generator().manual_seed(a.seed + 1)
shuffle = torch.Generator().manual_seed(a.seed)


def observation(idx: torch.Tensor, step: int) -> torch.Tensor:
    """The stacked observation ``(s_step, s_{step+1})`` of the chains ``idx``."""
    return frames_t[idx, step:step + 2]


def loss_of(idx: torch.Tensor) -> tuple[torch.Tensor, float]:
    batch = TransitionBatch(observation(idx, 0), actions_t[idx, 0], observation(idx, 1))
    loss, _ = pcc_loss(model, batch, config, generator)
    extra = torch.zeros(())
    if a.horizon > 1:
        mu, _ = model.encode(batch.obs)
        z = model.transition_mean(mu, batch.action)
        for k in range(2, a.horizon + 1):
            z = model.transition_mean(z, actions_t[idx, k - 1])
            extra = extra - model.log_likelihood(z, observation(idx, k)).mean()
    return loss + a.coef * extra, float(extra.detach())


log = []


def score(epoch: int, train_loss: float, extra: float) -> None:
    model.eval()
    with torch.no_grad():
        r2 = state_decodability(model, held_out.obs, held_out.state, env.state_error)
        val = float(np.mean([float(loss_of(val_idx[i:i + 500])[0])
                             for i in range(0, len(val_idx), 500)]))
    agent.set_goal(env.goal_observation())
    agent.set_planner()
    validation = evaluate_on_validation_tasks(agent, a.env, a.tasks).mean
    by_length = {}
    for length in a.plan_lengths:
        agent.set_planner(plan_length=length)
        by_length[f"validation_T{length}"] = evaluate_on_validation_tasks(agent, a.env,
                                                                          a.tasks).mean
    agent.set_planner(get_preset(a.env, a.variant).planner)
    if a.save:
        agent.save(f"{a.save}_ep{epoch}.pt")
    model.train()
    log.append({"epoch": epoch, "minutes": round((time.time() - t0) / 60, 1),
                "train_loss": round(train_loss, 2), "val_loss": round(val, 2),
                "multistep_nll": round(extra, 2), "r2": np.round(r2, 3).tolist(),
                "validation": validation, **by_length})
    print(log[-1], flush=True)
    with open(a.out, "w") as f:
        json.dump({"args": vars(a), "model": dataclasses.asdict(preset.model),
                   "train": config.to_dict(), "log": log}, f, indent=1)


with flushed_denormals(True):
    model.train()
    for epoch in range(1, a.epochs + 1):
        perm = train_idx[torch.randperm(len(train_idx), generator=shuffle).numpy()]
        losses, extras = [], []
        for i in range(0, len(perm), config.batch_size):
            idx = torch.from_numpy(perm[i:i + config.batch_size])
            loss, extra = loss_of(idx)
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            optimizer.step()
            losses.append(float(loss.detach()))
            extras.append(extra)
        print(f"epoch {epoch}: loss {np.mean(losses):.1f}, multi-step {np.mean(extras):.1f}, "
              f"{(time.time() - t0) / 60:.1f} min", flush=True)
        if epoch % a.every == 0:
            score(epoch, float(np.mean(losses)), float(np.mean(extras)))
print("done", round(time.time() - t0), "s", flush=True)
