"""The SAC comparison's summary: SAC's learning curves beside the model-based points.

Reads the finished SAC runs of one env (written by :mod:`pcc_bench.vs_sac`) and the
reproduction pipeline's run records on the same tasks, and writes ``<env>.json``, ``<env>.md``
and ``<env>.png``. An oracle or no-action floor missing from the reproduction records is
measured here.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from pcc_agent.io import atomic_save_figure, atomic_write_json, atomic_write_text
from pcc_bench.aggregation import choose_models, is_restart_training
from pcc_bench.records import NO_ACTION, ORACLE, load_records
from pcc_bench.zero_action import contains_zero_action, zero_action_percentages

#: The format number of the SAC comparison's records.
RECORD_FORMAT = 1


def read_record(path: Path) -> dict[str, Any] | None:
    """A JSON record, or None if the file is missing, partial or not a record."""
    try:
        record = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError):
        return None
    return record if isinstance(record, dict) else None


def oracle_point(env_id: str, task_seed_list: Sequence[int], results_dir: Path) -> dict | None:
    """The oracle's record on these tasks, run here and cached if needed (None: no oracle)."""
    from pcc_agent.evaluation import evaluate_control
    from pcc_agent.oracle import ORACLE_CONFIGS, OracleController

    config = ORACLE_CONFIGS.get(env_id)
    if config is None:
        return None
    settings = json.loads(json.dumps(dataclasses.asdict(config)))
    path = results_dir / "runs" / env_id.replace("/", "_") / "oracle.json"
    record = read_record(path)
    if (record is not None and record.get("task_seeds") == list(task_seed_list)
            and record.get("oracle") == settings):
        return record
    print(f"Running the oracle on {len(task_seed_list)} {env_id} tasks (the ceiling).")
    ev = evaluate_control(lambda env: OracleController(env, config), env_id, task_seed_list,
                          record_states=False)
    record = {"format": RECORD_FORMAT, "status": "done", "env_id": env_id, "oracle": settings,
              "task_seeds": list(task_seed_list), "percentages": ev.percentages.tolist()}
    atomic_write_json(path, record)
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
        records = [read_record(p) for p in sorted(sub.glob("seed*.json"))]
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
    for rec in choose_models(records):
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
    atomic_write_json(results_dir / f"{name}.json", summary)
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
    atomic_write_text("\n".join(lines) + "\n", results_dir / f"{name}.md")
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
    atomic_save_figure(fig, results_dir / f"{name}.png")
    plt.close(fig)
    print("\n".join(lines))
