"""Statistics of the run records: the summary rows of the reproduction grid.

Per (env, method, noise, preset): mean and standard error over all tasks and for the top-1
model, IQM with a bootstrap interval across models, the references (oracle, no action); and
the models of the ``restarts`` presets and of the presets with spare trainings, chosen from
their trainings (:func:`choose_models`).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from pcc_bench.presets import (
    PAPER_RESULTS,
    REPRODUCE_PRESETS,
    RESTART_SEED_STRIDE,
    ReproducePreset,
)
from pcc_bench.records import NO_ACTION, ORACLE, REFERENCE_METHODS, planner_revision_of


def interquartile_mean(values: np.ndarray) -> float:
    """Mean of the middle 50% of the values (rliable's IQM)."""
    values = np.sort(np.asarray(values, dtype=np.float64).ravel())
    n = values.size
    lo, hi = int(math.floor(0.25 * n)), int(math.ceil(0.75 * n))
    return float(values[lo:hi].mean()) if hi > lo else float(values.mean())


def bootstrap_iqm_ci(
    per_model: list[np.ndarray], reps: int = 2000, seed: int = 0
) -> tuple[float, float]:
    """95% bootstrap interval of the IQM, resampling models (then tasks within each model)."""
    rng = np.random.default_rng(seed)
    stats = np.empty(reps)
    n = len(per_model)
    for r in range(reps):
        picks = rng.integers(0, n, n)
        sample = [
            per_model[i][rng.integers(0, len(per_model[i]), len(per_model[i]))] for i in picks
        ]
        stats[r] = interquartile_mean(np.concatenate(sample))
    return float(np.percentile(stats, 2.5)), float(np.percentile(stats, 97.5))


def is_restart_training(spec: dict[str, Any]) -> bool:
    """Whether a run is a second or later training of a ``restarts`` preset's model.

    Such runs count only through :func:`select_restarts`, so that a preset's own rows keep
    its models ``0 .. N-1``.
    """
    return int(spec.get("seed", 0)) >= RESTART_SEED_STRIDE


def aggregate(records: Iterable[dict[str, Any]]) -> list[dict[str, Any]]:
    """Summary rows per (env, method, noise, preset) from run records.

    Restart trainings (:func:`is_restart_training`) are left out: pass the records of
    :func:`choose_models` to get the rows of the presets that choose among trainings.
    """
    from pcc_agent.evaluation import standard_error

    groups: dict[tuple[str, str, float, str], list[dict[str, Any]]] = {}
    for rec in records:
        s = rec["spec"]
        if is_restart_training(s):
            continue
        groups.setdefault((s["env_id"], s["method"], s["noise_std"], s["preset"]), []).append(rec)
    def reference_means(method: str) -> tuple[dict[Any, float], dict[Any, float]]:
        """A reference controller's mean per (env, noise, preset), and per task set.

        The references do not depend on the model variant: a preset without its own run uses
        another preset's on the same tasks (same env, noise, task seed and task count).
        """
        own = {(k[0], k[2], k[3]): float(np.mean(v[0]["percentages"]))
               for k, v in groups.items() if k[1] == method}
        by_tasks = {(k[0], k[2], v[0]["spec"].get("task_seed"), len(v[0]["percentages"]),
                     planner_revision_of(v[0])): float(np.mean(v[0]["percentages"]))
                    for k, v in groups.items() if k[1] == method}
        return own, by_tasks

    references = {method: reference_means(method) for method in REFERENCE_METHODS}

    def reference_mean(method: str, env_id: str, noise: float, preset: str,
                       recs: list[dict[str, Any]]) -> float | None:
        own, by_tasks = references[method]
        # An oracle only serves rows of its own planner revision; the floor plans nothing.
        revision = None if method == NO_ACTION else planner_revision_of(recs[0])
        tasks = (env_id, noise, recs[0]["spec"].get("task_seed"), len(recs[0]["percentages"]),
                 revision)
        return own.get((env_id, noise, preset), by_tasks.get(tasks))

    rows = []
    for (env_id, method, noise, preset), recs in sorted(groups.items()):
        recs = sorted(recs, key=lambda r: r["spec"]["seed"])
        per_model = [np.asarray(r["percentages"], dtype=np.float64) for r in recs]
        all_tasks = np.concatenate(per_model)
        means = np.array([m.mean() for m in per_model])
        best = int(np.argmax(means))
        top = per_model[best]

        planned = registered_preset(preset)
        row: dict[str, Any] = {
            "env": env_id,
            "method": method,
            "noise_std": noise,
            "preset": preset,
            "model_variant": recs[0]["spec"]["model_variant"],
            "n_models": len(recs),
            # The preset's grid size: a row with fewer models is a reduced grid.
            "n_models_planned": (
                1 if method in REFERENCE_METHODS else planned.num_models if planned else None),
            "n_tasks": int(np.median([m.size for m in per_model])),
            "seeds": [r["spec"]["seed"] for r in recs],
            "task_seed": recs[0]["spec"].get("task_seed"),
            "mean_all": float(all_tasks.mean()),
            "se_all": standard_error(all_tasks),
            "mean_top1": float(top.mean()),
            "se_top1": standard_error(top),
            "top1_seed": recs[best]["spec"]["seed"],
            "iqm": interquartile_mean(all_tasks),
            "iqm_ci": list(bootstrap_iqm_ci(per_model)) if len(per_model) > 1 else None,
            "oracle_mean": reference_mean(ORACLE, env_id, noise, preset, recs),
            "floor_mean": reference_mean(NO_ACTION, env_id, noise, preset, recs),
            "train_seconds_mean": float(np.mean([r["train_seconds"] for r in recs])),
            "settings": recs[0].get("config", {}),
        }
        paper = PAPER_RESULTS.get((env_id, method, noise))
        row["paper_all"] = list(paper["all"]) if paper else None
        row["paper_top1"] = list(paper["top1"]) if paper and "top1" in paper else None
        rows.append(row)
    return rows


def registered_preset(label: str) -> ReproducePreset | None:
    """The registered preset behind a row label such as ``"paper+max_epochs=5"``."""
    return REPRODUCE_PRESETS.get(label.split(" [", 1)[0].split("+", 1)[0])


def select_restarts(
    records: Sequence[dict[str, Any]],
    presets: Iterable[ReproducePreset] = REPRODUCE_PRESETS.values(),
) -> list[dict[str, Any]]:
    """The models of every ``restarts`` preset, chosen from its trainings' records.

    Model ``m`` of (env, method, noise) exists once all of its trainings (seeds ``m + k *
    RESTART_SEED_STRIDE``) are finished; it is the training with the lowest best validation
    loss. Its record is that training's, filed under the restarts preset with seed ``m``,
    the summed training time, and every training's validation loss and control score
    (``restarts``) for the record. Trainings run with command-line overrides (filed under
    ``runs_preset + "+..."``) make the models of the overridden preset (``name + "+..."``).
    Only trainings of the preset's recipe (variant, epoch cap, patience, tasks) count.
    """
    selected = []
    for preset in presets:
        if preset.restarts <= 1:
            continue
        by_cell: dict[tuple[Any, ...], dict[int, dict[str, Any]]] = {}
        for rec in records:
            s = rec["spec"]
            overrides = _overrides_as_training_of(s, preset)
            if s["method"] in REFERENCE_METHODS or overrides is None:
                continue
            training = s["seed"] // RESTART_SEED_STRIDE
            if training >= preset.restarts:  # a training of a preset with more restarts
                continue
            cell = (preset.name + overrides, s["env_id"], s["method"], s["noise_std"],
                    s["seed"] % RESTART_SEED_STRIDE)
            by_cell.setdefault(cell, {})[training] = rec
        for (label, _, _, _, model_seed), trainings in sorted(by_cell.items()):
            if model_seed >= preset.num_models or sorted(trainings) != list(
                    range(preset.restarts)):
                continue
            losses = {k: rec.get("training", {}).get("best_validation_loss")
                      for k, rec in trainings.items()}
            if any(loss is None for loss in losses.values()):
                continue
            best = trainings[min(losses, key=lambda k: (losses[k], k))]
            selected.append({
                **best,
                "spec": {**best["spec"], "preset": label, "seed": model_seed},
                "selected_training_seed": best["spec"]["seed"],
                "train_seconds": sum(float(r["train_seconds"]) for r in trainings.values()),
                "restarts": [{"seed": r["spec"]["seed"], "best_validation_loss": losses[k],
                              "mean": r["mean"]} for k, r in sorted(trainings.items())],
            })
    return selected


def choose_models(
    records: Sequence[dict[str, Any]],
    presets: Iterable[ReproducePreset] = REPRODUCE_PRESETS.values(),
) -> list[dict[str, Any]]:
    """The records whose models make the rows: every preset's choice among its trainings.

    The trainings a preset with spares did not keep are left out (:func:`kept_trainings`);
    the models of the ``restarts`` presets are added (:func:`select_restarts`).
    """
    presets = list(presets)
    return kept_trainings(records, presets) + select_restarts(records, presets)


def kept_trainings(
    records: Sequence[dict[str, Any]],
    presets: Iterable[ReproducePreset] = REPRODUCE_PRESETS.values(),
) -> list[dict[str, Any]]:
    """``records`` without the spare trainings that presets with spares did not keep.

    Per (preset with its overrides, env, method, noise), the ``spare_trainings`` finished
    trainings with the lowest validation control are left out (ties: the higher best
    validation loss, then the higher seed), so the full grid keeps ``num_models`` (and a
    grid run with ``--num-models 1`` keeps 1 of its 2 trainings). The kept records are
    copied with ``selection``: the rule and every training's seed, validation and evaluation
    mean. A cell with a training that has no validation score, or with no more trainings
    than spares, keeps every training. Records of other presets pass unchanged.

    A preset with spares and a ``candidates_preset`` chooses among that preset's runs
    (filed under ``runs_preset``, or ``runs_preset + "+..."`` with overrides): those records
    pass unchanged, for their own rows (but for the spares, seeds ``num_models`` onwards,
    which that preset's rows never had), and the kept ones are added again as copies filed
    under the choosing preset (``name``, or ``name + "+..."``), for the cells where at least
    one spare has run (in any env: a grid may be run with ``--envs`` beyond the preset's).
    """
    spare_presets = [preset for preset in presets if preset.spare_trainings]
    replaced: dict[int, dict[str, Any] | None] = {}
    own_pools = {p.name: p for p in spare_presets if p.candidates_preset is None}
    by_cell: dict[tuple[Any, ...], tuple[ReproducePreset, list[dict[str, Any]]]] = {}

    def pool(label: str, preset: ReproducePreset, rec: dict[str, Any]) -> None:
        s = rec["spec"]
        by_cell.setdefault((label, s["env_id"], s["method"], s["noise_std"]),
                           (preset, []))[1].append(rec)

    for rec in records:
        s = rec["spec"]
        if s["method"] in REFERENCE_METHODS:
            continue
        filed = str(s.get("preset", ""))
        preset = own_pools.get(filed.split("+", 1)[0])
        if preset is not None:
            pool(filed, preset, rec)
        for chooser in spare_presets:
            overrides = (None if chooser.candidates_preset is None
                         else _overrides_as_training_of(s, chooser))
            if overrides is None:
                continue
            pool(chooser.name + overrides, chooser,
                 {**rec, "spec": {**s, "preset": chooser.name + overrides}})
            if int(s["seed"]) >= chooser.num_models:  # a spare, not a model of its own row
                replaced[id(rec)] = None

    added: list[dict[str, Any]] = []
    for preset, trainings in by_cell.values():
        by_seed = {int(r["spec"]["seed"]): r for r in trainings}
        expected = sorted(by_seed)
        if preset.candidates_preset is not None and expected[-1] < preset.num_models:
            continue  # none of its spares has run: the other preset's row says it all
        keep = len(expected) - preset.spare_trainings
        if keep < 1 or any("validation" not in r for r in trainings):
            if preset.candidates_preset is not None:
                added.extend(by_seed[seed] for seed in expected)
            continue

        kept_seeds = sorted(expected, key=lambda seed: _validation_rank(by_seed[seed]))[:keep]
        selection = {
            "rule": f"the {keep} of {len(expected)} trainings with the highest validation "
                    "control (task seed 2021)",
            "trainings": [{"seed": seed, "validation_mean": by_seed[seed]["validation"]["mean"],
                           "mean": by_seed[seed]["mean"], "kept": seed in kept_seeds}
                          for seed in expected],
        }
        for seed in expected:
            record = by_seed[seed]
            chosen = {**record, "selection": selection} if seed in kept_seeds else None
            if preset.candidates_preset is None:
                replaced[id(record)] = chosen
            elif chosen is not None:
                added.append(chosen)
    kept = []
    for rec in records:
        new = replaced.get(id(rec), rec)
        if new is not None:
            kept.append(new)
    return kept + added


def _validation_rank(record: dict[str, Any]) -> tuple[float, float, int]:
    """Sort key of a training: the highest validation control, the lowest loss, the lowest seed."""
    loss = record.get("training", {}).get("best_validation_loss")
    return (-float(record["validation"]["mean"]), math.inf if loss is None else float(loss),
            int(record["spec"]["seed"]))


def _overrides_as_training_of(spec: dict[str, Any], preset: ReproducePreset) -> str | None:
    """The overrides (``""`` or ``"+..."``) under which a run is a training of ``preset``.

    None when the run is filed under another preset than ``preset.runs_preset``, or under
    it without overrides but with another recipe.
    """
    filed = str(spec.get("preset", ""))
    runs = preset.runs_preset
    if filed != runs and not filed.startswith(runs + "+"):
        return None
    overrides = filed[len(runs):]
    return overrides if overrides or _is_training_of(spec, preset) else None


def _is_training_of(spec: dict[str, Any], preset: ReproducePreset) -> bool:
    """Whether a run record's spec follows ``preset``'s recipe (no override)."""
    return (
        spec.get("model_variant") == preset.model_variant
        and spec.get("num_tasks", preset.num_tasks) == preset.num_tasks
        and spec.get("task_seed", preset.task_seed) == preset.task_seed
        and spec.get("max_epochs") == preset.max_epochs
        and spec.get("patience") == preset.patience
        and spec.get("flush_denormals") == preset.flush_denormals
        and spec.get("learning_rate") == preset.learning_rate
        and spec.get("prediction_horizon") == preset.prediction_horizon
        and spec.get("plan_length") == preset.plan_length
        and spec.get("num_samples") == preset.num_samples.get(spec.get("env_id", ""))
    )
