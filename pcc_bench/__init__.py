"""pcc_bench: the benchmarks of pcc-control (reproducing the paper, SAC, speeds, diagnostics).

Shared parts, one responsibility each:

* :mod:`pcc_bench.records`: what a run is, where its record lives, when a record counts;
* :mod:`pcc_bench.runs`: execute one run (train, control tasks, record);
* :mod:`pcc_bench.executors`: where runs execute (serial, loky worker processes, Ray);
* :mod:`pcc_bench.grid`: the runs of a preset, and running the unfinished ones;
* :mod:`pcc_bench.aggregation`: summary statistics over run records;
* :mod:`pcc_bench.tables`, :mod:`pcc_bench.plots`: the summary as tables and figures;
* :mod:`pcc_bench.costs`: what a grid will cost;
* :mod:`pcc_bench.presets`: the grids (reproduction presets) and the paper's numbers;
* :mod:`pcc_bench.cli`: the ``pcc`` command.

One module per command, each runnable as ``python -m pcc_bench.<command>``: ``reproduce``,
``vs_sac``, ``no_action_floor``, ``planner_sweep``, ``planner_speed``, ``train_speed``,
``env_speed``, ``latent_maps``, ``latent_diagnostics``, ``latent_formation``,
``long_training``. The library (:mod:`pcc_envs`, :mod:`pcc_agent`) never imports this package.
"""
