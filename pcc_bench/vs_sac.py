"""Side by side with Stable-Baselines3: SAC on the same images, the same tasks, the same metric.

For one env, this trains SB3's SAC with ``CnnPolicy`` on our uint8 image observations (and,
as a reference, SAC with ``MlpPolicy`` on the TRUE state), evaluating it at several numbers of
environment samples (the learning curve) with :func:`pcc_agent.evaluation.evaluate_control`:
the same function, task seeds and metric (percentage of steps in goal) as the reproduction
pipeline. The PCC / E2C / RCE points (at their data-set sizes) and the oracle ceiling are
read from the reproduction pipeline's run files for the same env and task seeds; runs on other
tasks are left out, and an oracle missing there is run here (``runs/<env>/oracle.json``).
So is the no-action floor (zero actions on the same tasks): where a start lies near the goal
(CartPole), doing nothing already scores; a floor missing there is measured here.

Every (env, policy, reward, budget, seed) run writes one JSON file,
``runs/<env>/sac_<observation>[_sparse]/budget<steps>/seed<seed>.json``. Finished runs are
skipped, and a run cut short (Ctrl-C, a crash, the end of a session) continues from its
training state, saved beside the record every ``--save-every`` steps and after every
evaluation (``seed<seed>.state.pt``, see :mod:`pcc_bench.sac_state`). Until the run ends, its
record file holds the curve so far with ``"status": "partial"``, never counted in the means:
those points can be committed, whereas the state file (gigabytes for images) stays on the
machine, and a run started afresh over them checks that it reaches the same weights at the
same steps (``earlier_sitting_sha256_match``). A finished record holds the
learning curve, the true-state trajectory of every task at the last evaluation (``tasks``, as
in the reproduction records) and ``policy_sha256``, the digest of the trained weights (each
curve point has the digest of the weights it evaluated): a rerun of the same command on a
host with the same SIMD features (``machine.simd_flags``) is checked bit for bit with it.
Runs with different budgets are different agents (SAC's ``learning_starts`` and buffer depend
on the budget), so each budget has its own learning curve in the outputs.

Reward: SAC learns from the env's reward, the model-based methods from none (their planner
has the paper's quadratic latent cost). ``--reward sparse`` (default) pays 1 per step in the
goal region, i.e. the metric itself; ``--reward dense`` is the env's negative weighted squared
distance to the goal. Both are scored by the same metric. The default is the stronger
baseline: on Planar's true state, SAC reached 71% of steps in goal after 20,000 steps with
the sparse reward and 3% with the dense one, whose gradient near the 2-pixel goal is too flat
to tell hovering beside the goal from sitting in it.

Replay buffer: one transition of an 80x80x2 observation costs 2 x 12.8 kB (obs and next obs,
uint8), so the default buffer of 100,000 transitions takes about 2.6 GB; 40x40 and 48x48
observations need 3-4x less. ``--buffer-size`` changes it.

Examples:
    python -m pcc_bench.vs_sac --env pcc/Planar-v0 --steps 20000 --checkpoints 2000 5000 \
        10000 20000 --seeds 0 1 2 --results-dir results/vs_sac \
        --reproduce-dir results/reproduce
    python -m pcc_bench.vs_sac --env pcc/Planar-v0 --aggregate-only
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from pcc_agent.io import atomic_write_json, versions
from pcc_bench import sac_state
from pcc_bench.arguments import command_parser, positive_int
from pcc_bench.presets import REPRODUCE_PRESETS
from pcc_bench.records import machine_info
from pcc_bench.vs_sac_summary import RECORD_FORMAT, read_record, summarize, write_outputs

DEFAULT_RESULTS_DIR = Path("pcc_results") / "vs_sac"
DEFAULT_REPRODUCE_DIR = Path("pcc_results") / "reproduce"
#: Environment steps between two saves of a SAC run's training state (besides evaluations).
DEFAULT_SAVE_EVERY = 2500


class TrueStateObservation(gym.ObservationWrapper):
    """Replace the image observation by the env's true state (float32), for the reference SAC."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        dim = env.unwrapped.state_dim
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (dim,), dtype=np.float32)

    def observation(self, observation: np.ndarray) -> np.ndarray:
        """The true state as float32."""
        return self.env.unwrapped.state.astype(np.float32)


REWARDS = ("dense", "sparse")


def make_env(env_id: str, observation: str, reward: str) -> gym.Env:
    """The env as SAC sees it: images (``"image"``) or the true state (``"state"``).

    ``reward`` is the env's ``reward_type`` SAC trains on (``"dense"`` or ``"sparse"``).
    """
    import pcc_envs  # noqa: F401

    env = gym.make(env_id, reward_type=reward)
    return TrueStateObservation(env) if observation == "state" else env


def load_finished_sac_run(
    path: Path,
    steps: int,
    checkpoints: Sequence[int],
    task_seed_list: Sequence[int],
    reward: str,
    buffer_size: int,
) -> dict[str, Any] | None:
    """A finished run's record, or None if it is missing or stale.

    Stale: made with other steps, checkpoints, task seeds, reward or replay-buffer size (not
    the agent or curve asked for). Records without a ``reward`` key were trained on the dense
    reward.
    """
    record = read_record(path)
    if (
        record is None
        or record.get("status") != "done"
        or record.get("steps") != steps
        or [p["env_steps"] for p in record.get("curve", [])] != list(checkpoints)
        or record.get("task_seeds") != list(task_seed_list)
        or record.get("reward", "dense") != reward
        or record.get("buffer_size") != buffer_size
    ):
        return None
    return record


def sac_run_path(
    results_dir: Path, env_id: str, observation: str, steps: int, seed: int, reward: str
) -> Path:
    """Where the record of one SAC run (env, observation, reward, step budget, seed) lives."""
    suffix = "" if reward == "dense" else f"_{reward}"
    return (
        results_dir
        / "runs"
        / env_id.replace("/", "_")
        / f"sac_{observation}{suffix}"
        / f"budget{steps}"
        / f"seed{seed}.json"
    )


def policy_digest(model: Any) -> str:
    """SHA-256 of a trained SB3 model's weights (policy state dict and entropy coefficient).

    Written into each run record, so that a rerun of the same command can be checked to
    reproduce the training bit for bit, not only its evaluation percentages (on hosts with
    the same SIMD features: other kernels round differently).
    """
    import hashlib

    digest = hashlib.sha256()
    tensors = dict(model.policy.state_dict())
    if getattr(model, "log_ent_coef", None) is not None:
        tensors["log_ent_coef"] = model.log_ent_coef
    for name in sorted(tensors):
        digest.update(name.encode())
        digest.update(tensors[name].detach().cpu().contiguous().numpy().tobytes())
    return digest.hexdigest()


def run_sac(
    env_id: str,
    observation: str,
    seed: int,
    steps: int,
    checkpoints: Sequence[int],
    task_seed_list: Sequence[int],
    buffer_size: int,
    results_dir: Path,
    reward: str,
    save_every: int = DEFAULT_SAVE_EVERY,
) -> dict[str, Any]:
    """Train one SAC agent, evaluating it at every checkpoint; write and return its record.

    The training state is saved every ``save_every`` environment steps and after every
    evaluation (:mod:`pcc_bench.sac_state`); a run that was cut short continues from its last
    state, and the state file is removed once the record is written.
    """
    import stable_baselines3
    import torch
    from stable_baselines3 import SAC
    from stable_baselines3.common.callbacks import BaseCallback
    from tqdm.auto import tqdm

    from pcc_agent.agent import sb3_logger
    from pcc_agent.evaluation import evaluate_control

    if reward not in REWARDS:
        raise ValueError(f"reward must be one of {REWARDS}, got {reward!r}")
    if save_every < 1:
        raise ValueError(f"save_every must be at least 1 step, got {save_every}")
    path = sac_run_path(results_dir, env_id, observation, steps, seed, reward)
    wanted = sorted({c for c in checkpoints if c <= steps} | {steps})
    record = load_finished_sac_run(path, steps, wanted, task_seed_list, reward,
                                   min(buffer_size, steps))
    if record is not None:
        sac_state.state_path(path).unlink(missing_ok=True)  # left by a crash after the record
        return record
    policy = "CnnPolicy" if observation == "image" else "MlpPolicy"
    settings = {
        "env_id": env_id, "policy": policy, "observation": observation, "reward": reward,
        "seed": seed, "steps": steps, "checkpoints": list(wanted),
        "task_seeds": list(task_seed_list), "buffer_size": min(buffer_size, steps),
        "learning_starts": min(1000, steps // 10),
        "stable_baselines3": stable_baselines3.__version__,
    }
    env = make_env(env_id, observation, reward)
    model = SAC(
        policy,
        env,
        buffer_size=settings["buffer_size"],
        learning_starts=settings["learning_starts"],
        seed=seed,
        device="auto",
        verbose=0,
    )
    model.set_logger(sb3_logger(None, []))  # SB3's default makes an empty temp dir per run
    state_file = sac_state.state_path(path)
    state = sac_state.load_state(state_file, settings)
    earlier = _comparable_partial_points(read_record(path), settings)
    if state is None and earlier:
        print(f"{path} holds a partial run of an earlier sitting ({len(earlier)} evaluations) "
              "but no training state is left: the run starts afresh, and its weights are "
              "checked against the earlier sitting's at those steps.")
    curve: list[dict[str, Any]] = []
    earlier_seconds, resumed_at, steps_done = 0.0, [], 0
    if state is not None:
        sac_state.restore_state(model, state)
        curve, earlier_seconds = state["curve"], state["train_seconds"]
        steps_done = state["steps_done"]
        resumed_at = [*state["resumed_at"], steps_done]
        # Fresh random streams for the rest of the run, deterministic given the resume point.
        model.set_random_seed(int(np.random.SeedSequence([seed, steps_done]).generate_state(1)[0]))
        print(f"Resuming SAC({observation}) seed {seed} on {env_id} at {steps_done} steps.")
    wanted = [c for c in wanted if c not in {point["env_steps"] for point in curve}]

    bar = tqdm(total=steps, initial=steps_done, unit="step",
               desc=f"SAC {observation} seed {seed}")
    start = time.perf_counter()

    def record_fields(status: str) -> dict[str, Any]:
        """What a partial and a finished record of this run both hold, as of now."""
        return {
            "format": RECORD_FORMAT, "status": status, "env_id": env_id, "observation": observation,
            "reward": reward, "seed": seed, "steps": steps,
            "train_seconds": earlier_seconds + time.perf_counter() - start,
            "resumed_at_steps": resumed_at, "curve": curve, "task_seeds": list(task_seed_list),
            "machine": machine_info(), "versions": versions(), "command": " ".join(sys.argv),
        }
    last_saved = steps_done
    final_tasks: list[dict[str, Any]] = []  # the last evaluation's tasks, with trajectories

    class EvalAndSave(BaseCallback):
        # Called after each env step, before its transition is stored and trained on: the
        # model and buffer then hold num_timesteps - 1 fully processed steps.
        def _on_step(self) -> bool:
            bar.update(self.num_timesteps - bar.n)
            evaluated = False
            if wanted and self.num_timesteps >= wanted[0]:
                wanted.pop(0)
                evaluated = True
                eval_start = time.perf_counter()
                final = self.num_timesteps >= steps
                ev = evaluate_control(
                    lambda e: make_policy_view(self.model, e, observation),
                    env_id,
                    task_seed_list,
                    record_states=final,
                )
                if final:  # where the trained agent takes each task, as reproduce keeps
                    final_tasks[:] = [task.to_dict() for task in ev.tasks]
                curve.append(
                    {
                        "env_steps": self.num_timesteps,
                        "percentages": ev.percentages.tolist(),
                        "mean": ev.mean,
                        "se": ev.standard_error,
                        "eval_seconds": time.perf_counter() - eval_start,
                        # The weights evaluated here: two runs of one seed that differ in
                        # budget or checkpoints can be compared step for step.
                        "policy_sha256": policy_digest(self.model),
                    }
                )
                bar.write(
                    f"  {env_id} SAC({observation}) seed {seed} @ {self.num_timesteps} steps: "
                    f"{ev.mean:.1f}% in goal"
                )
                before = earlier.get(self.num_timesteps) if not resumed_at else None
                if before is not None:  # this sitting retrained the same steps from scratch
                    same = before == curve[-1]["policy_sha256"]
                    curve[-1]["earlier_sitting_sha256_match"] = same
                    bar.write("    the same weights as the earlier sitting" if same else
                              "    OTHER weights than the earlier sitting at this step (other "
                              "kernels? see machine.simd_flags of both)")
                if not final:  # kept in git even when the session's state file is lost
                    atomic_write_json(path, {**record_fields("partial"),
                                              "steps_done": self.num_timesteps,
                                              "settings": settings})
            nonlocal last_saved
            processed = self.num_timesteps - 1
            if wanted and (evaluated or processed - last_saved >= save_every):
                sac_state.save_state(state_file, self.model, processed, settings, curve,
                                     earlier_seconds + time.perf_counter() - start, resumed_at)
                last_saved = processed
            return True

    with bar:
        model.learn(total_timesteps=steps - steps_done, callback=EvalAndSave(),
                    reset_num_timesteps=state is None)
    record = {
        **record_fields("done"),
        "policy": f"SAC {policy} ({observation})",
        "buffer_size": settings["buffer_size"],
        "tasks": final_tasks,
        "policy_sha256": policy_digest(model),
        "torch_threads": torch.get_num_threads(),
    }
    atomic_write_json(path, record)
    state_file.unlink(missing_ok=True)
    return record


def _comparable_partial_points(record: dict[str, Any] | None,
                               settings: dict[str, Any]) -> dict[int, str]:
    """Weights' digests, by env step, of an earlier sitting's partial record of this run.

    Only the points the earlier sitting trained without a resume before them: a run started
    afresh must reach exactly these weights there (on a host with the same SIMD features).
    """
    if record is None or record.get("status") != "partial" or record.get("settings") != settings:
        return {}
    first_resume = min(record.get("resumed_at_steps") or [float("inf")])
    return {int(p["env_steps"]): p["policy_sha256"] for p in record.get("curve", [])
            if p["env_steps"] <= first_resume and "policy_sha256" in p}


class _StatePolicy:
    """SB3 model trained on true states, evaluated on the image env (reads the true state)."""

    def __init__(self, model: Any, env: gym.Env) -> None:
        self.model, self.env = model, env

    def predict(
        self,
        observation: np.ndarray,
        state: Any = None,
        episode_start: Any = None,
        deterministic: bool = True,
    ) -> tuple[np.ndarray, Any]:
        """Act on the env's true state instead of the image observation."""
        s = self.env.unwrapped.state.astype(np.float32)[None]
        action, _ = self.model.predict(s, deterministic=deterministic)
        return action, state


def make_policy_view(model: Any, env: gym.Env, observation: str) -> Any:
    """The object evaluate_control drives: the model itself, or its true-state view."""
    return model if observation == "image" else _StatePolicy(model, env)


def build_parser() -> argparse.ArgumentParser:
    """The command-line interface."""
    parser = command_parser(__doc__, "pcc_bench.vs_sac")
    parser.add_argument("--env", default="pcc/Planar-v0", help="Registered env id.")
    parser.add_argument("--steps", type=positive_int, default=100_000,
                        help="SAC environment steps.")
    parser.add_argument(
        "--checkpoints",
        type=positive_int,
        nargs="+",
        default=None,
        help="Env-step counts at which SAC is evaluated (default: the PCC "
        "data-set size and 4 log-spaced points up to --steps).",
    )
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2], help="SAC seeds.")
    parser.add_argument(
        "--observations", nargs="+", default=["image", "state"], choices=["image", "state"]
    )
    parser.add_argument(
        "--reward",
        default="sparse",
        choices=REWARDS,
        help="The env reward SAC trains on: 'dense' (negative weighted squared distance to "
        "the goal) or 'sparse' (1 per step in the goal region, the metric itself).",
    )
    parser.add_argument(
        "--num-tasks", type=positive_int, default=REPRODUCE_PRESETS["paper"].num_tasks,
        help="Control tasks per evaluation (the reproduction pipeline's task seeds).",
    )
    parser.add_argument(
        "--buffer-size", type=positive_int, default=100_000,
        help="Replay buffer in transitions (100,000 80x80x2 transitions take about 2.6 GB).",
    )
    parser.add_argument(
        "--save-every", type=positive_int, default=DEFAULT_SAVE_EVERY,
        help="Environment steps between saves of a run's training state (also saved after "
        "every evaluation); a run cut short continues from its last state.",
    )
    parser.add_argument("--results-dir", type=Path, default=DEFAULT_RESULTS_DIR)
    parser.add_argument(
        "--reproduce-dir",
        type=Path,
        default=DEFAULT_REPRODUCE_DIR,
        help="Where the reproduction pipeline's run files are (PCC points).",
    )
    parser.add_argument("--threads", type=int, default=max(1, (os.cpu_count() or 1)),
                        help="Torch CPU threads.")
    parser.add_argument("--aggregate-only", action="store_true",
                        help="Only rebuild the table and plot from finished runs.")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python -m pcc_bench.vs_sac``."""
    parser = build_parser()
    args = parser.parse_args(argv)
    beyond = [c for c in args.checkpoints or [] if c > args.steps]
    if beyond:
        parser.error(f"--checkpoints {beyond} lie beyond --steps {args.steps}; SAC would never "
                     "reach them.")
    import torch

    from pcc_agent.evaluation import task_seeds
    from pcc_agent.presets import get_preset

    torch.set_num_threads(args.threads)
    seeds = task_seeds(REPRODUCE_PRESETS["paper"].task_seed, args.num_tasks)
    if not args.aggregate_only:
        dataset_size = get_preset(args.env).data.num_samples
        if args.checkpoints is None and dataset_size > args.steps:
            print(f"Note: the PCC data-set size ({dataset_size:,} transitions) is beyond --steps "
                  f"{args.steps:,}; the curve has no equal-sample point.")
        checkpoints = args.checkpoints or sorted(
            {dataset_size, *np.geomspace(1000, args.steps, 4).astype(int).tolist()}
        )
        try:
            for observation in args.observations:
                for seed in args.seeds:
                    run_sac(args.env, observation, seed, args.steps, checkpoints, seeds,
                            args.buffer_size, args.results_dir, args.reward, args.save_every)
        except KeyboardInterrupt:
            print("Interrupted: finished runs and the last training state are kept; run the "
                  "same command again to continue.", file=sys.stderr)
            return 130
    summary = summarize(args.env, args.results_dir, args.reproduce_dir, seeds)
    write_outputs(summary, args.results_dir)
    return 0


if __name__ == "__main__":
    sys.exit(main())
