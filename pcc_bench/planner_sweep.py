"""Choose planner settings with numbers: control quality over a grid of planner settings.

Two modes:

* ``--oracle ENV_ID``: the true-dynamics oracle (:class:`pcc_agent.oracle.OracleController`)
  plans with each setting. This is how the per-domain planner settings of
  ``pcc_agent.presets`` are chosen: it measures what the planner itself allows, before any
  learning, so the settings are not fitted to one learned model.
* ``CHECKPOINT ...``: saved agents (``PCCAgent.save``, or the float16 weights the reproduction
  pipeline keeps under ``<results>/weights/``) re-run their control tasks with each setting;
  training is not repeated. With several agents of one env (e.g. a grid row's models), each
  setting is also summarized by its mean over the agents (``summary``), so a setting is
  chosen for the row, not for one model.

Settings are never chosen on the evaluation tasks: the tasks are drawn from
``--task-seed`` (default 2021, a validation split) and start from the env's validation starts
(``reset(options={"start": "validation"})``, which perturb the one start of swing-up and the
arms); the evaluation tasks' seed (2020, ``pcc_bench.presets``) is refused unless
``--allow-evaluation-tasks`` is given (to report, never to choose), and only it starts from
the task starts.

Examples:
    python -m pcc_bench.planner_sweep --oracle pcc/CartPole-v0 --plan-lengths 10 50
        --replan-every 1 5 --kappas 10 1000 --out results/planner_sweep/cp.json
    python -m pcc_bench.planner_sweep CHECKPOINT --plan-lengths 10 20 40 --kappas 1 10
    python -m pcc_bench.planner_sweep results/reproduce/weights/runs/LABEL/ENV/noise0.0/pcc/*
        --task-seed 2022 --plan-lengths 30 50 --out sweep.json
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from pcc_agent.evaluation import VALIDATION_TASK_SEED
from pcc_agent.io import atomic_write_json
from pcc_bench.arguments import command_parser
from pcc_bench.presets import REPRODUCE_PRESETS

#: Planner fields a sweep can vary, with their command-line option and type.
SWEPT_FIELDS: dict[str, tuple[str, type]] = {
    "plan_length": ("--plan-lengths", int),
    "replan_every": ("--replan-every", int),
    "kappa": ("--kappas", float),
    "r_weight": ("--r-weights", float),
    "terminal_weight": ("--terminal-weights", float),
    "iterations": ("--iterations", int),
    "mpc_iterations": ("--mpc-iterations", int),
    "num_candidates": ("--num-candidates", int),
    "num_extreme": ("--num-extreme", int),
}


def _weights(text: str) -> tuple[float, ...]:
    try:
        return tuple(float(w) for w in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"state weights are comma-separated numbers such as 1,0.1; got {text!r}") from None


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``python -m pcc_bench.planner_sweep``."""
    parser = command_parser(__doc__, "pcc_bench.planner_sweep")
    parser.add_argument("checkpoints", type=Path, nargs="*", metavar="CHECKPOINT",
                        help="PCCAgent files (.pt or float16 .safetensors) of one env.")
    parser.add_argument("--oracle", metavar="ENV_ID", help="Sweep the true-dynamics oracle.")
    for name, (option, kind) in SWEPT_FIELDS.items():
        parser.add_argument(option, dest=name, type=kind, nargs="+", default=None,
                            help=f"Values of PlannerConfig.{name} (default: the preset's).")
    parser.add_argument("--state-weights", type=_weights, nargs="+", default=None,
                        help="Oracle only: true-state weights, one comma-separated tuple each "
                             "(default: ORACLE_CONFIGS).")
    parser.add_argument("--num-tasks", type=int, default=REPRODUCE_PRESETS["paper"].num_tasks)
    parser.add_argument("--task-seed", type=int, default=VALIDATION_TASK_SEED)
    parser.add_argument("--allow-evaluation-tasks", action="store_true",
                        help="Permit the evaluation tasks' seed (to report, not to choose).")
    parser.add_argument("--out", type=Path, default=None, help="JSON file for the rows.")
    return parser


def settings_grid(base: Any, args: argparse.Namespace) -> list[Any]:
    """Every valid combination of the swept values, as planner configs derived from ``base``.

    A combination that ``PlannerConfig`` refuses (e.g. ``replan_every`` above
    ``plan_length``) is left out with a printed note; a grid left empty is an error.
    """
    swept = {name: getattr(args, name) for name in SWEPT_FIELDS if getattr(args, name)}
    configs, refused = [], []
    for values in itertools.product(*swept.values()):
        try:
            configs.append(dataclasses.replace(base, **dict(zip(swept, values))))
        except ValueError as error:
            refused.append(str(error))
            print(f"Left out {dict(zip(swept, values))}: {error}")
    if not configs:
        raise ValueError(f"no valid planner setting in the grid: {refused[0]}")
    return configs


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python -m pcc_bench.planner_sweep``."""
    parser = build_parser()
    argv = list(sys.argv[1:] if argv is None else argv)
    args = parser.parse_args(argv)
    evaluation_seed = REPRODUCE_PRESETS["paper"].task_seed
    if args.task_seed == evaluation_seed and not args.allow_evaluation_tasks:
        parser.error(f"--task-seed {evaluation_seed} draws the evaluation tasks; planner "
                     "settings are chosen on other tasks (default "
                     f"{VALIDATION_TASK_SEED}). Add --allow-evaluation-tasks to report on them.")
    if bool(args.checkpoints) == bool(args.oracle):
        parser.error("give either saved agents (CHECKPOINT ...) or --oracle ENV_ID")
    if args.state_weights and not args.oracle:
        parser.error("--state-weights applies to --oracle sweeps only")

    import torch

    from pcc_agent.evaluation import evaluate_control, format_mean_se, task_seeds

    torch.set_num_threads(1)
    seeds = task_seeds(args.task_seed, args.num_tasks)
    # Tasks of other seeds than the evaluation tasks' start from the validation starts: where
    # every task starts from one state (swing-up, the arms), another seed alone would replay
    # the evaluation task.
    starts = "task" if args.task_seed == evaluation_seed else "validation"
    if args.oracle:
        from pcc_agent.oracle import OracleController, oracle_config_for, oracle_planner_for

        env_id, method, env_kwargs = args.oracle, "oracle", None
        oracle_base = oracle_config_for(env_id)
        base_planner = oracle_planner_for(env_id, oracle_base)
        weight_grid = args.state_weights or [oracle_base.state_weights]
    else:
        from pcc_agent import PCCAgent

        agents = {str(path): PCCAgent.load(path) for path in args.checkpoints}
        first = next(iter(agents.values()))
        env_id, method, env_kwargs = first.env_id, first.method, first.env_kwargs
        others = sorted({a.env_id for a in agents.values()} - {env_id})
        if others:
            parser.error(f"the saved agents control different envs ({env_id}, "
                         f"{', '.join(others)}); sweep one env at a time")
        base_planner = first.planner
        weight_grid = [None]
    options = {"start": starts} if env_id.startswith("pcc/") else None
    try:
        configs = settings_grid(base_planner, args)
    except ValueError as error:  # PlannerConfig refuses an inconsistent combination
        parser.error(str(error))
    rows: list[dict[str, Any]] = []
    summary: list[dict[str, Any]] = []
    targets = [None] if args.oracle else list(agents)
    total = len(configs) * len(weight_grid) * len(targets)
    for planner, weights in itertools.product(configs, weight_grid):
        varied = ", ".join(f"{name} {getattr(planner, name):g}" for name in SWEPT_FIELDS
                           if getattr(args, name))
        if weights is not None and args.state_weights:
            varied += f", state weights {weights}"
        setting_rows = []
        for checkpoint in targets:
            start = time.perf_counter()
            if args.oracle:
                oracle = dataclasses.replace(oracle_base, state_weights=weights)
                result = evaluate_control(
                    lambda env, o=oracle, p=planner: OracleController(env, o, p),
                    env_id, seeds, env_kwargs, record_states=False, reset_options=options)
            else:
                agent = agents[checkpoint]
                agent.set_planner(planner)  # also restarts the planner's draws from the seed
                result = evaluate_control(agent, env_id, seeds, env_kwargs,
                                          record_states=False, reset_options=options)
            row = {
                "env": env_id, "method": method, "checkpoint": checkpoint,
                **{name: getattr(planner, name) for name in SWEPT_FIELDS},
                "state_weights": list(weights) if weights is not None else None,
                "num_tasks": len(seeds), "task_seed": args.task_seed,
                "starts": starts if options else None,
                "mean": result.mean, "se": result.standard_error,
                "percentages": result.percentages.tolist(),
                "seconds": time.perf_counter() - start,
            }
            rows.append(row)
            setting_rows.append(row)
            where = "" if checkpoint is None else f" [{Path(checkpoint).stem}]"
            print(f"{varied or 'preset settings'}{where}: "
                  f"{format_mean_se(row['mean'], row['se'])} % in goal "
                  f"({row['seconds']:.0f} s)", flush=True)
            if args.out is not None:  # after every row: a cut-short sweep keeps what it measured
                _write(args.out, argv, rows, summary,
                       done=len(rows) == total and len(targets) == 1)
        if len(targets) > 1:
            means = [r["mean"] for r in setting_rows]
            summary.append({
                **{name: getattr(planner, name) for name in SWEPT_FIELDS},
                "num_agents": len(means), "mean_over_agents": float(sum(means) / len(means)),
                "agent_means": means})
            print(f"{varied or 'preset settings'}: {summary[-1]['mean_over_agents']:.1f} % in "
                  f"goal over {len(means)} agents", flush=True)
            if args.out is not None:
                _write(args.out, argv, rows, summary, done=len(rows) == total)
    if args.out is not None:
        print(f"Wrote {args.out}")
    return 0


def _write(out: Path, argv: list[str], rows: list[dict[str, Any]],
           summary: list[dict[str, Any]], done: bool) -> None:
    """Write the sweep so far (``status`` partial until every row is measured)."""
    payload: dict[str, Any] = {
        "command": " ".join(["python -m pcc_bench.planner_sweep", *argv]),
        "status": "done" if done else "partial", "rows": rows}
    if summary:
        payload["summary"] = summary
    atomic_write_json(out, payload)


if __name__ == "__main__":
    sys.exit(main())
