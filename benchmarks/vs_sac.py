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
evaluation (``seed<seed>.state.pt``, see :mod:`benchmarks.sac_state`). Until the run ends, its
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
    python -m benchmarks.vs_sac --env pcc/Planar-v0 --steps 20000 --checkpoints 2000 5000 \
        10000 20000 --seeds 0 1 2 --results-dir benchmarks/results/vs_sac \
        --reproduce-dir benchmarks/results/reproduce
    python -m benchmarks.vs_sac --env pcc/Planar-v0 --aggregate-only
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from benchmarks import sac_state
from benchmarks.no_action_floor import contains_zero_action, zero_action_percentages
from benchmarks.presets import REPRODUCE_PRESETS
from benchmarks.reproduce import (
    NO_ACTION,
    ORACLE,
    _positive_int,
    _save_figure_atomic,
    _versions,
    _write_json_atomic,
    _write_text_atomic,
    is_restart_training,
    load_records,
    machine_info,
    select_restarts,
)

DEFAULT_RESULTS_DIR = Path("pcc_results") / "vs_sac"
DEFAULT_REPRODUCE_DIR = Path("pcc_results") / "reproduce"
FORMAT = 1
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
    record = _read_record(path)
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


def _read_record(path: Path) -> dict[str, Any] | None:
    """A JSON record, or None if the file is missing, partial or not a record."""
    try:
        record = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError):
        return None
    return record if isinstance(record, dict) else None


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
    evaluation (:mod:`benchmarks.sac_state`); a run that was cut short continues from its last
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
    earlier = _comparable_partial_points(_read_record(path), settings)
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
            "format": FORMAT, "status": status, "env_id": env_id, "observation": observation,
            "reward": reward, "seed": seed, "steps": steps,
            "train_seconds": earlier_seconds + time.perf_counter() - start,
            "resumed_at_steps": resumed_at, "curve": curve, "task_seeds": list(task_seed_list),
            "machine": machine_info(), "versions": _versions(), "command": " ".join(sys.argv),
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
                    _write_json_atomic(path, {**record_fields("partial"),
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
    _write_json_atomic(path, record)
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


def oracle_point(env_id: str, task_seed_list: Sequence[int], results_dir: Path) -> dict | None:
    """The oracle's record on these tasks, run here and cached if needed (None: no oracle)."""
    from pcc_agent.evaluation import evaluate_control
    from pcc_agent.oracle import ORACLE_CONFIGS, OracleController

    config = ORACLE_CONFIGS.get(env_id)
    if config is None:
        return None
    settings = json.loads(json.dumps(dataclasses.asdict(config)))
    path = results_dir / "runs" / env_id.replace("/", "_") / "oracle.json"
    record = _read_record(path)
    if (record is not None and record.get("task_seeds") == list(task_seed_list)
            and record.get("oracle") == settings):
        return record
    print(f"Running the oracle on {len(task_seed_list)} {env_id} tasks (the ceiling).")
    ev = evaluate_control(lambda env: OracleController(env, config), env_id, task_seed_list,
                          record_states=False)
    record = {"format": FORMAT, "status": "done", "env_id": env_id, "oracle": settings,
              "task_seeds": list(task_seed_list), "percentages": ev.percentages.tolist()}
    _write_json_atomic(path, record)
    return record


def _allows_zero_action(env_id: str) -> bool:
    """Whether ``env_id``'s action space contains the zero action (else it has no floor)."""
    if env_id.startswith("pcc/"):
        import pcc_envs  # noqa: F401  (registers the pcc/ ids)
    env = gym.make(env_id)
    try:
        return contains_zero_action(env.action_space)
    finally:
        env.close()


def summarize(
    env_id: str,
    results_dir: Path,
    reproduce_dir: Path,
    task_seed_list: Sequence[int] | None = None,
) -> dict[str, Any]:
    """Learning curves (mean and SE over seeds) and the model-based points, as one dict.

    One curve per policy, reward and step budget, keyed
    ``"sac_<observation>[_sparse] (<steps> steps)"``. With ``task_seed_list``, only runs
    evaluated on exactly these tasks count, and the oracle and the no-action floor are run on
    them if the reproduction results have none.
    """
    from pcc_agent.evaluation import standard_error

    def same_tasks(record: dict[str, Any]) -> bool:
        return task_seed_list is None or record.get("task_seeds") == list(task_seed_list)

    curves: dict[str, Any] = {}
    run_dir = results_dir / "runs" / env_id.replace("/", "_")
    budget_dirs = sorted(
        run_dir.glob("sac_*/budget[0-9]*") if run_dir.exists() else [],
        key=lambda d: (d.parent.name, int(d.name.removeprefix("budget"))),
    )
    partial: list[dict[str, Any]] = []
    for sub in budget_dirs:
        records = [_read_record(p) for p in sorted(sub.glob("seed*.json"))]
        records = [rec for rec in records if rec is not None and same_tasks(rec)]
        key = f"{sub.parent.name} ({sub.name.removeprefix('budget')} steps)"
        partial.extend(
            {"curve": key, "seed": rec["seed"], "steps_done": rec["steps_done"],
             "points": [{"env_steps": p["env_steps"], "mean": p["mean"]} for p in rec["curve"]]}
            for rec in records if rec.get("status") == "partial"
        )
        records = [rec for rec in records if rec.get("status") == "done"]
        if not records:
            continue
        points: dict[int, list[float]] = {}
        for rec in records:
            for point in rec["curve"]:
                points.setdefault(point["env_steps"], []).append(point["mean"])
        curves[key] = [
            {
                "env_steps": steps,
                "mean": float(np.mean(v)),
                "se": standard_error(v),
                "n_seeds": len(v),
            }
            for steps, v in sorted(points.items())
        ]
    model_based: dict[str, Any] = {}
    records = load_records(reproduce_dir) if reproduce_dir.exists() else []
    for rec in records + select_restarts(records):
        spec = rec["spec"]
        if (spec["env_id"] != env_id or spec["noise_std"] != 0.0 or not same_tasks(rec)
                or is_restart_training(spec)):
            continue
        # One point per (method, preset): "paper" and "paper-fast" runs are different models.
        entry = model_based.setdefault(
            f"{spec['method']} ({spec['preset']})",
            {
                "method": spec["method"],
                "percentages": [],
                "num_samples": None,
                "preset": spec["preset"],
            },
        )
        entry["percentages"].extend(rec["percentages"])
        data_size = rec.get("config", {}).get("data", {}).get("num_samples")
        # A model of a restarts preset consumed one data set per training it was chosen from.
        trainings = len(rec.get("restarts", ())) or 1
        entry["num_samples"] = None if data_size is None else int(data_size) * trainings
    if task_seed_list is not None and not any(
        entry["method"] == ORACLE for entry in model_based.values()
    ):
        oracle = oracle_point(env_id, task_seed_list, results_dir)
        if oracle is not None:
            model_based["oracle (vs_sac)"] = {"method": ORACLE, "percentages":
                                              list(oracle["percentages"]), "num_samples": None,
                                              "preset": "vs_sac"}
    if (task_seed_list is not None
            and not any(entry["method"] == NO_ACTION for entry in model_based.values())
            and _allows_zero_action(env_id)):
        model_based[f"{NO_ACTION} (vs_sac)"] = {
            "method": NO_ACTION, "percentages": zero_action_percentages(env_id, task_seed_list),
            "num_samples": None, "preset": "vs_sac"}
    for entry in model_based.values():
        values = np.asarray(entry.pop("percentages"))
        entry.update(mean=float(values.mean()), se=standard_error(values), n_tasks=int(values.size))
    return {"env": env_id, "sac": curves, "model_based": model_based, "partial": partial}


def _curve_label(key: str) -> str:
    """``"sac_image_sparse (20000 steps)"`` -> ``"SAC image, sparse reward, budget 20000"``."""
    name, steps = key.split(" (")
    parts = name.split("_")
    reward = parts[2] if len(parts) > 2 else "dense"
    return f"SAC {parts[1]}, {reward} reward, budget {steps.removesuffix(' steps)')}"


def write_outputs(summary: dict[str, Any], results_dir: Path) -> None:
    """JSON, Markdown table and learning-curve PNG for one env."""
    import matplotlib

    from pcc_agent.evaluation import format_mean_se

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    name = summary["env"].split("/")[1]
    _write_json_atomic(results_dir / f"{name}.json", summary)
    lines = [
        f"## {summary['env']}\n",
        "| method | env samples | % steps in goal (mean ± SE) | n |",
        "|---|---|---|---|",
    ]
    for label, entry in sorted(summary["model_based"].items()):
        samples = {ORACLE: "- (true dynamics)", NO_ACTION: "- (zero actions)"}.get(
            entry["method"], entry["num_samples"])
        lines.append(
            f"| {label} | {samples} | {format_mean_se(entry['mean'], entry['se'])} "
            f"| {entry['n_tasks']} tasks |"
        )
    for policy, curve in summary["sac"].items():
        for p in curve:
            lines.append(
                f"| {policy} | {p['env_steps']} | {format_mean_se(p['mean'], p['se'])} "
                f"| {p['n_seeds']} seeds |"
            )
    if summary.get("partial"):
        lines += ["", "Runs in progress (not in the rows above; the same command continues "
                  "them from their training state, or from scratch where it is lost):", ""]
        lines += [
            f"- {_curve_label(run['curve'])}, seed {run['seed']}, at {run['steps_done']:,} steps: "
            + ", ".join(f"{p['mean']:.1f}% at {p['env_steps']:,}" for p in run["points"])
            for run in summary["partial"]
        ]
    _write_text_atomic(results_dir / f"{name}.md", "\n".join(lines) + "\n")
    fig, ax = plt.subplots(figsize=(9, 4.5))
    for policy, curve in summary["sac"].items():
        x = [p["env_steps"] for p in curve]
        y = np.array([p["mean"] for p in curve])
        e = np.array([np.nan if p["se"] is None else p["se"] for p in curve])
        ax.plot(x, y, marker="o", label=_curve_label(policy))
        ax.fill_between(x, y - e, y + e, alpha=0.2)
    for run in summary.get("partial", []):  # drawn apart from the means they are not in
        ax.plot([p["env_steps"] for p in run["points"]], [p["mean"] for p in run["points"]],
                linestyle="--", marker=".",
                label=f"{_curve_label(run['curve'])}, seed {run['seed']} (in progress)")
    model_based = sorted(summary["model_based"].items())
    oracles = [entry for _, entry in model_based if entry["method"] == ORACLE]
    if oracles:  # one ceiling, whatever preset evaluated it
        ax.axhline(oracles[0]["mean"], color="k", linestyle="--", label="oracle (true dynamics)")
    floors = [entry for _, entry in model_based if entry["method"] == NO_ACTION]
    if floors:
        ax.axhline(floors[0]["mean"], color="0.5", linestyle=":", label="no action (floor)")
    points = [(k, e) for k, e in model_based
              if e["method"] not in (ORACLE, NO_ACTION) and e["num_samples"]]
    # Points share the data-set size: spread them a little along the log axis to keep them apart.
    for i, (label, entry) in enumerate(points):
        dodge = 1.0 + 0.04 * (i - (len(points) - 1) / 2)
        ax.errorbar(
            entry["num_samples"] * dodge,
            entry["mean"],
            yerr=np.nan if entry["se"] is None else entry["se"],
            fmt="s",
            capsize=3,
            label=f"{label}, {entry['n_tasks']} tasks",
        )
    ax.set_xscale("log")
    ax.set_xlabel("environment samples")
    ax.set_ylabel("% of steps in goal")
    ax.set_title(f"{summary['env']}: SAC vs embed-to-control")
    ax.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5))
    fig.tight_layout()
    _save_figure_atomic(fig, results_dir / f"{name}.png")
    plt.close(fig)
    print("\n".join(lines))


def build_parser() -> argparse.ArgumentParser:
    """The command-line interface."""
    parser = argparse.ArgumentParser(
        prog="python -m benchmarks.vs_sac", description=__doc__.split("\n\n")[0]
    )
    parser.add_argument("--env", default="pcc/Planar-v0", help="Registered env id.")
    parser.add_argument("--steps", type=_positive_int, default=100_000,
                        help="SAC environment steps.")
    parser.add_argument(
        "--checkpoints",
        type=_positive_int,
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
        "--num-tasks", type=_positive_int, default=REPRODUCE_PRESETS["paper"].num_tasks,
        help="Control tasks per evaluation (the reproduction pipeline's task seeds).",
    )
    parser.add_argument(
        "--buffer-size", type=_positive_int, default=100_000,
        help="Replay buffer in transitions (100,000 80x80x2 transitions take about 2.6 GB).",
    )
    parser.add_argument(
        "--save-every", type=_positive_int, default=DEFAULT_SAVE_EVERY,
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
    """Entry point of ``python -m benchmarks.vs_sac``."""
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
