"""Show the controller working after a small grid: per-task results and a controlled episode.

For every (env, noise) cell of the runs just made, :func:`show_control` prints each task's
percentage of steps in goal for every model beside the oracle (the planner on the true state)
and doing nothing, and draws one controlled episode of the best model
(:mod:`pcc_bench.episode_figure`) next to the summary. It only reads finished run records and
the agents saved beside them; runs whose agent file is missing get no picture.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from pcc_bench.records import REFERENCE_METHODS, load_finished_run
from pcc_bench.weights import saved_agent_path

#: Above this many models a per-task table would not fit a terminal; the summary suffices.
MAX_MODELS_SHOWN = 5


def selection_lines(cell: dict[str, dict[int, dict[str, Any]]], preset: str) -> list[str]:
    """One line per method whose trainings ``preset`` chose among (spare trainings): which, why.

    ``preset`` is the label of the rows the grid makes (with its overrides): another
    preset's choice among the same runs is not shown.
    """
    from pcc_bench.aggregation import kept_trainings

    lines = []
    for method, by_seed in sorted(cell.items()):
        chosen = [r for r in kept_trainings(list(by_seed.values()))
                  if "selection" in r and r["spec"]["preset"] == preset]
        if not chosen:
            continue
        trainings = chosen[0]["selection"]["trainings"]
        scores = ", ".join(f"#{t['seed']} {t['validation_mean']:.1f}"
                           + ("" if t["kept"] else " (left out)") for t in trainings)
        lines.append(f"{method}: {chosen[0]['selection']['rule']}; validation % in goal: "
                     f"{scores}")
    return lines


def per_task_table(cell: dict[str, dict[int, dict[str, Any]]]) -> str:
    """Plain-text table: one line per task, one column per model, oracle and no action last.

    Args:
        cell: ``method -> model seed -> record`` of one (env, noise) cell.
    """
    learned = [(m, s) for m in sorted(cell) if m not in REFERENCE_METHODS
               for s in sorted(cell[m])]
    references = [(m, s) for m in ("oracle", "no-action") if m in cell for s in sorted(cell[m])]
    columns = learned + references
    if not columns:
        return ""
    seeds = cell[columns[0][0]][columns[0][1]]["task_seeds"]
    names = [f"{m} #{s}" if m not in REFERENCE_METHODS else m for m, s in columns]
    width = max(9, *(len(n) for n in names))
    lines = ["task".ljust(6) + "".join(n.rjust(width + 1) for n in names)]
    for i, _seed in enumerate(seeds):
        values = []
        for m, s in columns:
            percentages = cell[m][s]["percentages"]
            values.append(f"{percentages[i]:.1f}" if i < len(percentages) else "-")
        lines.append(f"{i:<6}" + "".join(v.rjust(width + 1) for v in values))
    means = [f"{np.mean(cell[m][s]['percentages']):.1f}" for m, s in columns]
    lines.append("mean".ljust(6) + "".join(v.rjust(width + 1) for v in means))
    return "\n".join(lines)


def show_control(runs: Sequence[Any], results_dir: Path, preset: str) -> list[Path]:
    """Print per-task tables and draw the best model's episode of each cell; return the PNGs.

    ``preset``: the label of the grid's rows, whose choice among spare trainings is shown.
    """
    cells: dict[tuple[str, float], dict[str, dict[int, dict[str, Any]]]] = {}
    specs: dict[tuple[str, float, str, int], Any] = {}
    for spec in runs:
        record = load_finished_run(results_dir / spec.relative_path, spec)
        if record is None:
            continue
        key = (spec.env_id, spec.noise_std)
        cells.setdefault(key, {}).setdefault(spec.method, {})[spec.seed] = record
        specs[(spec.env_id, spec.noise_std, spec.method, spec.seed)] = spec
    pictures = []
    for (env_id, noise), cell in sorted(cells.items()):
        models = sum(len(v) for m, v in cell.items() if m not in REFERENCE_METHODS)
        if models == 0 or models > MAX_MODELS_SHOWN:
            continue
        print(f"\n{env_id} (noise {noise:g}): % of steps in goal per task")
        print(per_task_table(cell))
        for line in selection_lines(cell, preset):
            print(line)
        for method, by_seed in sorted(cell.items()):
            if method in REFERENCE_METHODS:
                continue
            seed, record = max(by_seed.items(), key=lambda item: np.mean(item[1]["percentages"]))
            agent_file = saved_agent_path(record, results_dir,
                                          specs[(env_id, noise, method, seed)])
            if agent_file is None:
                continue
            pictures.append(_draw_best(agent_file, env_id, record, results_dir, method, noise))
    for picture in pictures:
        print(f"A controlled episode of the best model: {picture}")
    return pictures


def _draw_best(agent_file: Path, env_id: str, record: dict[str, Any], results_dir: Path,
               method: str, noise: float) -> Path:
    """The best model's median task, drawn next to the summary."""
    from pcc_agent.agent import PCCAgent
    from pcc_bench.episode_figure import plot_controlled_episode

    agent = PCCAgent.load(agent_file, device="cpu")
    order = np.argsort(record["percentages"])
    task_seed = record["task_seeds"][int(order[len(order) // 2])]
    env_kwargs = {"noise_std": noise} if noise else None
    path = results_dir / f"episode_{env_id.split('/')[-1]}_{method}.png"
    plot_controlled_episode(agent, env_id, task_seed, path, env_kwargs=env_kwargs)
    return path
