"""Which trained models control well, and why: latent diagnostics of every finished run.

For every finished model run of a reproduction results directory whose saved agent is still there
(the float16 weights the record was evaluated with, else the float32 ``checkpoints/``, both
written by ``pcc_bench.reproduce``), this measures
:func:`pcc_agent.diagnostics.latent_diagnostics` on held-out transitions. The transitions
are the same for every model: the env's uniform sampler with a seed no model was trained
on. It writes the results beside the run's control score and best validation loss, with
Spearman rank correlations between each diagnostic and the control score, per method and
over all methods. It also reports how well each model's code determines every true-state
coordinate (:func:`pcc_agent.diagnostics.state_decodability`, k-NN R^2), which shows e.g. a
cart-pole code without velocities, and how each model's dynamics behave at the goal
(:func:`pcc_agent.diagnostics.goal_linearization`: the goal code's one-step drift and the
spectral radius there, beside the true dynamics' at the goal state), and how far the
planner's cost, the latent distance to the goal, climbs on the straight way from each task's
start to the goal (:func:`pcc_agent.diagnostics.goal_path_barrier`, the mean over the run's
tasks), and whether the held-out states coded nearest the goal are near it in state space
(:func:`pcc_agent.diagnostics.goal_aliasing`: near 0 if so, near 1 or above for a fold that
puts a distant state there), and, on envs with cheap true dynamics, how the latent dynamics
predict and feel the action near the goal (:func:`pcc_agent.diagnostics.goal_prediction`:
the 10-step open-loop error over that of standing still, and the action's one-step effect
over the one-step error), and how many steps the agent keeps the true state in the goal region
when started inside it (:func:`pcc_agent.evaluation.evaluate_goal_hold`, 5 starts near the
goal state, 100 steps: low for a controller that reaches the goal but cannot stay). Nothing
is retrained and no control task is rerun.

Usage:
    python -m pcc_bench.latent_diagnostics --results-dir results/reproduce \
        --preset paper-fast-long --env pcc/Planar-v0 \
        --output results/latent_diagnostics/Planar-v0_paper-fast-long
"""

from __future__ import annotations

import argparse
import functools
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from pcc_agent.io import atomic_write_json, atomic_write_text
from pcc_bench.aggregation import is_restart_training
from pcc_bench.arguments import command_parser
from pcc_bench.records import REFERENCE_METHODS, RunSpec, checkpoint_path, load_records
from pcc_bench.weights import saved_agent_path

#: Seed of the held-out transitions (the grids train on seeds 0, 1, ...).
HELD_OUT_SEED = 1_000_000
#: Fewest held-out transitions: the k-NN state R^2 uses 2/3 as references (k = 10) and 1/3.
MIN_SAMPLES = 30
DIAGNOSTICS = ("consistency_error", "curvature", "latent_scale", "best_validation_loss",
               "min_state_r2", "goal_drift", "goal_spectral_radius", "goal_path_barrier",
               "goal_aliasing", "goal_prediction_error", "goal_action_effect", "goal_hold_steps")


def spearman(x: Sequence[float], y: Sequence[float]) -> float | None:
    """Spearman's rank correlation (ties get their mean rank); None when undefined."""
    a, b = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
    if a.size < 3 or a.size != b.size:
        return None
    ranks = [_ranks(a), _ranks(b)]
    if min(r.std() for r in ranks) == 0:
        return None
    return float(np.corrcoef(*ranks)[0, 1])


def _ranks(values: np.ndarray) -> np.ndarray:
    order = np.argsort(values, kind="stable")
    ranks = np.empty(values.size)
    ranks[order] = np.arange(values.size, dtype=np.float64)
    for value in np.unique(values):  # ties share their mean rank
        tied = values == value
        ranks[tied] = ranks[tied].mean()
    return ranks


def diagnose_runs(
    results_dir: Path, env_id: str, preset: str, num_samples: int = 1000
) -> list[dict[str, Any]]:
    """One row per finished model run of (env, preset) with a saved agent."""
    import gymnasium as gym
    import torch

    import pcc_envs  # noqa: F401  (registers the pcc/ envs)

    torch.set_num_threads(1)
    env = gym.make(env_id)
    try:
        rows = [row for record in load_records(results_dir)
                if (row := _diagnose_run(results_dir, env_id, preset, num_samples, record, env))]
    finally:
        env.close()
    return sorted(rows, key=lambda r: (r["method"], r["noise_std"], r["seed"]))


def _diagnose_run(
    results_dir: Path, env_id: str, preset: str, num_samples: int, record: dict[str, Any],
    env: Any,
) -> dict[str, Any] | None:
    """The diagnostics row of one run record, or None if it is not a model of the grid."""
    from pcc_agent.agent import PCCAgent
    from pcc_agent.diagnostics import (
        goal_aliasing,
        goal_linearization,
        goal_path_barrier,
        goal_prediction,
        latent_diagnostics,
        state_decodability,
    )
    from pcc_agent.evaluation import evaluate_goal_hold

    spec = RunSpec(**record["spec"])
    if (spec.method in REFERENCE_METHODS or spec.env_id != env_id or spec.preset != preset
            or is_restart_training(record["spec"])):  # the grid's models 0 .. N-1 only
        return None
    agent_file = saved_agent_path(record, results_dir, spec)
    if agent_file is None:
        print(f"No saved agent for {spec.method} seed {spec.seed} (neither weights nor "
              f"{checkpoint_path(results_dir, spec)}); skipped.")
        return None
    data = _held_out_transitions(env_id, num_samples, spec.noise_std)
    agent = PCCAgent.load(agent_file, device="cpu")
    found = latent_diagnostics(agent.model, data.obs, data.action, data.next_obs)
    state_r2 = state_decodability(agent.model, data.obs, data.state, env.unwrapped.state_error)
    at_goal = goal_linearization(agent.model, agent.goal_observation, found.latent_scale)
    aliasing = goal_aliasing(agent.model, data.obs, data.state, agent.goal_observation,
                             env.unwrapped.goal_state, env.unwrapped.state_error)
    starts = [_task_start(env, seed) for seed in record.get("task_seeds", [])]
    barrier = None
    if starts:  # tasks often share their start (Pendulum: all 10): one path per distinct one
        distinct, counts = np.unique(np.array(starts), axis=0, return_counts=True)
        barrier = float(np.average([
            goal_path_barrier(agent.model, env, start, agent.goal_observation,
                              found.latent_scale)
            for start in distinct], weights=counts))
    near_goal = (goal_prediction(agent.model, env)
                 if getattr(env.unwrapped, "supports_oracle", False) else None)
    hold = evaluate_goal_hold(agent, env_id, env_kwargs=spec.env_kwargs).mean_steps
    print(f"{spec.method} seed {spec.seed}: {record['mean']:.1f}% in goal, consistency "
          f"error {found.consistency_error:.4f}, curvature {found.curvature:.2e}, state "
          f"R^2 {np.round(state_r2, 2).tolist()}, at the goal: drift {at_goal.drift:.3f}, "
          f"spectral radius {at_goal.spectral_radius:.3f}, goal path barrier "
          f"{'-' if barrier is None else f'{barrier:.2f}'}, goal aliasing {aliasing:.2f}"
          + ("" if near_goal is None else
             f", near the goal: prediction error / hold {near_goal.error_over_hold:.2f}, "
             f"action effect {near_goal.action_effect:.3f}")
          + f", goal hold {hold:.1f} steps of 100", flush=True)
    return {
        "env": env_id, "preset": preset, "method": spec.method, "seed": spec.seed,
        "noise_std": spec.noise_std, "percent_in_goal": float(record["mean"]),
        "best_validation_loss": record.get("training", {}).get("best_validation_loss"),
        **found.to_dict(),
        "state_r2": [round(float(v), 4) for v in state_r2],
        "min_state_r2": float(state_r2.min()),
        "goal_drift": at_goal.drift,
        "goal_spectral_radius": at_goal.spectral_radius,
        "goal_path_barrier": barrier,
        "goal_aliasing": aliasing,
        "goal_prediction_error": None if near_goal is None else near_goal.error_over_hold,
        "goal_action_effect": None if near_goal is None else near_goal.action_effect,
        "goal_hold_steps": hold,
    }


def _task_start(env: Any, task_seed: int) -> np.ndarray:
    """The true start state of the control task with this seed (the env's reset)."""
    env.reset(seed=int(task_seed))
    return np.array(env.unwrapped.state, dtype=np.float64)


@functools.lru_cache(maxsize=4)
def _held_out_transitions(env_id: str, num_samples: int, noise_std: float) -> Any:
    """The held-out transitions of one noise level, shared by every model."""
    from pcc_envs.data import collect_transitions

    return collect_transitions(env_id, num_samples, HELD_OUT_SEED, noise_std=noise_std)


def true_goal_linearization_of(env_id: str) -> dict[str, Any] | None:
    """The env's true dynamics linearized at its goal, or None without cheap true dynamics."""
    import gymnasium as gym

    from pcc_agent.diagnostics import true_goal_linearization

    env = gym.make(env_id)
    try:
        if not getattr(env.unwrapped, "supports_oracle", False):
            return None
        return true_goal_linearization(env).to_dict()
    finally:
        env.close()


def correlations(rows: list[dict[str, Any]]) -> dict[str, dict[str, float | None]]:
    """Spearman correlation of each diagnostic with the control score, per method and all."""
    groups: dict[str, list[dict[str, Any]]] = {"all methods": rows}
    for row in rows:
        groups.setdefault(row["method"], []).append(row)
    out = {}
    for name, members in groups.items():
        score = [r["percent_in_goal"] for r in members]
        out[name] = {"n_models": len(members)}
        for key in DIAGNOSTICS:
            pairs = [(r[key], s) for r, s in zip(members, score) if r.get(key) is not None]
            out[name][key] = spearman(*zip(*pairs)) if pairs else None
    return out


def markdown(
    rows: list[dict[str, Any]],
    corr: dict[str, dict[str, float | None]],
    true_goal: dict[str, Any] | None = None,
) -> str:
    """The rows and the correlations as Markdown tables.

    ``true_goal`` (the true dynamics' :class:`~pcc_agent.diagnostics.GoalLinearization` as a
    dict) is stated under the table.
    """
    lines = [
        "| method | seed | % in goal | consistency error | curvature | latent scale "
        "| best val. loss | state R^2 (k-NN, per coordinate) | goal drift "
        "| goal spectral radius | goal path barrier | goal aliasing "
        "| goal prediction error | goal action effect | goal hold |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        val = "-" if r["best_validation_loss"] is None else f"{r['best_validation_loss']:.1f}"
        barrier, aliasing, prediction, effect, hold = (
            "-" if r.get(key) is None else f"{r[key]:.{digits}f}"
            for key, digits in (("goal_path_barrier", 2), ("goal_aliasing", 2),
                                ("goal_prediction_error", 2), ("goal_action_effect", 3),
                                ("goal_hold_steps", 1)))
        lines.append(
            f"| {r['method']} | {r['seed']} | {r['percent_in_goal']:.1f} "
            f"| {r['consistency_error']:.4f} | {r['curvature']:.2e} | {r['latent_scale']:.2f} "
            f"| {val} | {', '.join(f'{v:.2f}' for v in r['state_r2'])} "
            f"| {r['goal_drift']:.3f} | {r['goal_spectral_radius']:.3f} "
            f"| {barrier} | {aliasing} | {prediction} | {effect} | {hold} |"
        )
    lines += ["", "Goal drift: one step with no action from the goal's code, in units of the "
              "latent scale. Goal spectral radius: the largest eigenvalue modulus of the "
              "latent dynamics linearized there (above 1: unstable). Goal path barrier: how "
              "far the latent distance to the goal climbs on the straight state path from a "
              "task's start to the goal, in units of the latent scale (mean over tasks; 0: "
              "it falls all the way). Goal aliasing: the largest state distance from the goal "
              "of the 10 held-out states coded nearest the goal, over the median of all "
              "held-out states (near 0: the goal's latent neighbours are its state "
              "neighbours; near 1 or above: a fold puts a distant state there). Goal "
              "prediction error: from 200 states near the goal with random actions, the "
              "10-step open-loop latent prediction's error over the error of predicting that "
              "nothing moves (below 1: better than standing still). Goal action effect: the "
              "action's one-step effect on the predicted code over the one-step prediction "
              "error (well below 1: the planner steers a response lost in the model's "
              "error). Goal hold: from 5 starts inside the goal region near the goal state, "
              "the mean steps of 100 until the agent lets the true state leave it (low: it "
              "may reach the goal but cannot stay)."]
    if true_goal is not None:
        lines[-1] += (f" The true dynamics at the goal state: spectral radius "
                      f"{true_goal['spectral_radius']:.3f}, eigenvalue moduli "
                      f"{', '.join(f'{v:.3f}' for v in true_goal['eigenvalue_moduli'])}.")
    lines += ["", "Spearman rank correlation with the % in goal:", "",
              "| models | n | " + " | ".join(DIAGNOSTICS) + " |",
              "|---|---|" + "---|" * len(DIAGNOSTICS)]
    for name, values in corr.items():
        cells = ["-" if values[k] is None else f"{values[k]:+.2f}" for k in DIAGNOSTICS]
        lines.append(f"| {name} | {values['n_models']} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def build_parser() -> argparse.ArgumentParser:
    """The command-line interface."""
    parser = command_parser(__doc__, "pcc_bench.latent_diagnostics")
    parser.add_argument("--results-dir", type=Path, required=True,
                        help="A reproduction results directory (runs/ and checkpoints/).")
    parser.add_argument("--env", default="pcc/Planar-v0", help="Env id of the runs.")
    parser.add_argument("--preset", required=True, help="Preset name of the runs.")
    parser.add_argument("--samples", type=int, default=1000, help="Held-out transitions.")
    parser.add_argument("--output", type=Path, required=True,
                        help="Output path without suffix: writes .json and .md.")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python -m pcc_bench.latent_diagnostics``."""
    arguments = list(sys.argv[1:] if argv is None else argv)
    args = build_parser().parse_args(arguments)
    if args.samples < MIN_SAMPLES:
        raise SystemExit(f"--samples must be at least {MIN_SAMPLES} (the state R^2 needs "
                         f"reference and held-out codes), got {args.samples}.")
    rows = diagnose_runs(args.results_dir, args.env, args.preset, args.samples)
    if not rows:
        raise SystemExit(f"No finished {args.env} runs of preset {args.preset!r} with a saved "
                         f"agent under {args.results_dir}.")
    corr = correlations(rows)
    true_goal = true_goal_linearization_of(args.env)
    atomic_write_json(Path(f"{args.output}.json"), {
        "command": " ".join(["python -m pcc_bench.latent_diagnostics", *arguments]),
        "held_out_seed": HELD_OUT_SEED, "rows": rows, "spearman": corr,
        "true_goal_linearization": true_goal,
    })
    text = markdown(rows, corr, true_goal)
    atomic_write_text(text, Path(f"{args.output}.md"))
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
