"""The reproduction summary as text.

Markdown tables (results per paper table, evaluation settings) for ``summary.md``, and
:func:`terminal_table`, a compact plain-text table that fits a terminal of 100 columns.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from pcc_bench.aggregation import registered_preset
from pcc_bench.presets import ABLATIONS
from pcc_bench.records import REFERENCE_METHODS


def format_pair(pair: Sequence[float | None] | None) -> str:
    from pcc_agent.evaluation import format_mean_se

    return "-" if pair is None else format_mean_se(pair[0], pair[1])


def paper_table(row: dict[str, Any]) -> str:
    """Which of the paper's tables a summary row belongs to."""
    if row["noise_std"]:
        return "Table 3: noisy dynamics"
    if row["method"] in ABLATIONS:
        return "Table 2: ablations"
    return "Table 1: E2C, RCE and PCC"


def models_cell(row: dict[str, Any]) -> str:
    """The models-x-tasks cell: ``"10 x 10"``, or the difference from the preset's grid.

    ``"3 of 10 x 10 (reduced grid)"`` when models are missing; ``"12 x 10 (2 beyond the
    preset's 10)"`` when extra seeds were run (top-1 is then the best of more models than the
    protocol's).
    """
    planned = row.get("n_models_planned")
    if planned is not None and row["n_models"] < planned:
        return f"{row['n_models']} of {planned} x {row['n_tasks']} (reduced grid)"
    if planned is not None and row["n_models"] > planned:
        return (f"{row['n_models']} x {row['n_tasks']} ({row['n_models'] - planned} beyond "
                f"the preset's {planned})")
    return f"{row['n_models']} x {row['n_tasks']}"


def noise_variance(row: dict[str, Any]) -> str:
    """A row's process-noise variance as Table 3 writes it (rows keep the std, ``noise_std``)."""
    return f"{row['noise_std'] ** 2:g}"


def markdown_table(rows: list[dict[str, Any]]) -> str:
    """The summary as a Markdown table, our numbers beside the paper's.

    The noise column gives the process-noise variance, as the paper's Table 3 subscripts do
    (``summary.json`` keeps the standard deviation, ``noise_std``).
    """
    lines = [
        "| env | method | noise variance | preset (variant) | models x tasks | ours: all "
        "| paper: all "
        "| ours: top-1 | paper: top-1 | IQM [95% CI] | oracle | no action |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        ci = r["iqm_ci"]
        iqm = f"{r['iqm']:.1f}" + (f" [{ci[0]:.1f}, {ci[1]:.1f}]" if ci else "")
        oracle, floor = ("-" if r.get(key) is None else f"{r[key]:.1f}"
                         for key in ("oracle_mean", "floor_mean"))
        lines.append(
            f"| {r['env']} | {r['method']} | {noise_variance(r)} | {r['preset']} "
            f"({r['model_variant']}) | {models_cell(r)} "
            f"| {format_pair((r['mean_all'], r['se_all']))} | {format_pair(r['paper_all'])} "
            f"| {format_pair((r['mean_top1'], r['se_top1']))} | {format_pair(r['paper_top1'])} "
            f"| {iqm} "
            f"| {oracle} | {floor} |"
        )
    return "\n".join(lines) + "\n"


def training_recipe(settings: dict[str, Any]) -> str:
    """A short description of how the models of a row were trained (from the run config)."""
    model, train = settings.get("model", {}), settings.get("train", {})
    changes = []
    if model.get("input_standardization"):
        changes.append("input standardization")
    if train.get("warmup_epochs"):
        changes.append(f"{train['warmup_epochs']}-epoch KL warm-up")
    if train.get("flush_denormals"):
        changes.append("subnormals flushed to zero")
    if "lr" in train and train["lr"] != 5e-4:  # the paper's Adam learning rate
        changes.append(f"learning rate {train['lr']:g}")
    if train.get("prediction_horizon", 1) > 1:
        changes.append(f"{train['prediction_horizon']}-step prediction term (weight "
                       f"{train.get('multistep_coef', 1.0):g} per extra step)")
    recipe = "paper recipe" if not changes else "paper recipe + " + " + ".join(changes)
    if not train:
        return recipe
    return (f"{recipe}; early stop after {train.get('patience')} epochs without improvement, "
            f"not before epoch {train.get('min_epochs', 0)}, at most {train.get('epochs')}")


def _override(preset: str, field: str) -> str | None:
    """The value of a command-line override in a row's preset label.

    Labels are ``base+field=value,...``, possibly followed by `` [planner rN]``.
    """
    for tag in preset.split(" [", 1)[0].partition("+")[2].split(","):
        key, _, value = tag.partition("=")
        if key == field:
            return value
    return None


def settings_table(rows: list[dict[str, Any]]) -> str:
    """The evaluation and training settings of every (env, preset, method) row."""
    from pcc_bench.presets import CONTROL_SELECTION_TASKS, TASK_STARTS

    seen: dict[tuple[str, str, str], dict[str, Any]] = {}
    for r in rows:
        if (r["method"] not in REFERENCE_METHODS
                and (r["env"], r["preset"], r["method"]) not in seen):
            seen[(r["env"], r["preset"], r["method"])] = r
    lines = [
        "| env | preset | method | episode length | plan length (replan every) "
        "| iLQR iters (first / MPC) | candidates (extreme) | kappa (Q = kappa I) | R "
        "| action bounds | data size "
        "| tasks per model (task seed) | model seeds | task starts | training |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for (env, preset, method), row in seen.items():
        s = row["settings"]
        p = s.get("planner", {})
        registered = registered_preset(preset)
        recipe = training_recipe(s)
        if registered is not None and registered.restarts > 1:
            recipe += (f"; each model the best of {registered.restarts} trainings by "
                       "validation loss")
        if registered is not None and registered.spare_trainings:
            # The row's own count: a grid run with --num-models keeps that many.
            kept = row["n_models"]
            recipe += (f"; the {kept} of {kept + registered.spare_trainings} trainings that "
                       "control best on validation tasks (task seed 2021)")
        every = _override(preset, "keep_best_control_every")
        if every is not None:
            recipe += (f"; each training ends with its weights that control best on "
                       f"{CONTROL_SELECTION_TASKS} validation tasks (task seed 2021), scored "
                       f"every {every} epochs")
        lines.append(
            f"| {env} | {preset} | {method} | {s.get('episode_length', '-')} "
            f"| {p.get('plan_length')} ({p.get('replan_every', 1)}) "
            f"| {p.get('iterations')} / {p.get('mpc_iterations')} "
            f"| {p.get('num_candidates')} ({p.get('num_extreme', 2)}) "
            f"| {p.get('kappa')} | {p.get('r_weight')} I "
            f"| [{p.get('action_low')}, {p.get('action_high')}] "
            f"| {s.get('data', {}).get('num_samples')} "
            f"| {row['n_tasks']} ({row.get('task_seed', '-')}) | {row['seeds']} "
            f"| {TASK_STARTS.get(env, '-')} | {recipe} |"
        )
    return "\n".join(lines) + "\n"


#: The width terminal tables are fitted to.
TERMINAL_WIDTH = 100


def terminal_table(headers: Sequence[str], rows: Sequence[Sequence[Any]],
                   width: int = TERMINAL_WIDTH) -> str:
    """A plain-text table whose lines fit ``width`` columns.

    Columns are separated by two spaces; where the table would be wider, the widest columns
    are narrowed and their cells wrapped onto several lines (at spaces where possible).
    """
    import textwrap

    cells = [[str(h) for h in headers]] + [["" if c is None else str(c) for c in r] for r in rows]
    widths = [max(len(row[i]) for row in cells) for i in range(len(headers))]
    budget = width - 2 * (len(headers) - 1)
    floor = 6
    while sum(widths) > budget and max(widths) > floor:
        widest = max(range(len(widths)), key=lambda i: widths[i])
        widths[widest] -= 1
    lines = []
    for k, row in enumerate(cells):
        wrapped = [textwrap.wrap(cell, w, break_on_hyphens=False) or [""]
                   for cell, w in zip(row, widths)]
        for part in range(max(len(w) for w in wrapped)):
            lines.append("  ".join(
                (w[part] if part < len(w) else "").ljust(widths[i])
                for i, w in enumerate(wrapped)).rstrip())
        if k == 0:
            lines.append("  ".join("-" * w for w in widths))
    return "\n".join(lines) + "\n"


def summary_terminal_table(rows: list[dict[str, Any]], width: int = TERMINAL_WIDTH) -> str:
    """The summary rows for a terminal: one block per (env, noise), each fitting ``width``.

    Cells: mean ± standard error over all tasks of all models (``all``) and over the best
    model's tasks (``top-1``), the paper's ``all`` beside ours, the oracle (ceiling) and the
    no-action floor. The reference controllers are columns, not rows; the IQM and the
    evaluation settings are in ``summary.md``.
    """
    def pair(values: Sequence[float | None] | None) -> str:
        return format_pair(values).replace(" ± ", "±")

    def models(r: dict[str, Any]) -> str:
        planned = r.get("n_models_planned")
        shown = f"{r['n_models']}/{planned}" if planned and planned != r["n_models"] else str(
            r["n_models"])
        return f"{shown}x{r['n_tasks']}"

    blocks = []
    for env, noise in sorted({(r["env"], r["noise_std"]) for r in rows}):
        body = [[r["method"], r["preset"], models(r), pair((r["mean_all"], r["se_all"])),
                 pair(r["paper_all"]), pair((r["mean_top1"], r["se_top1"])),
                 "-" if r.get("oracle_mean") is None else f"{r['oracle_mean']:.1f}",
                 "-" if r.get("floor_mean") is None else f"{r['floor_mean']:.1f}"]
                for r in rows
                if (r["env"], r["noise_std"]) == (env, noise)
                and r["method"] not in REFERENCE_METHODS]
        if not body:
            continue
        title = env + (f", noise variance {noise ** 2:g}" if noise else "")
        blocks.append(title + "\n" + terminal_table(
            ["method", "preset", "models", "all", "paper", "top-1", "oracle", "floor"], body,
            width))
    return "\n".join(blocks)
