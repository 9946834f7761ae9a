"""The ``pcc`` command (pcc_bench.cli) and the shape of the benchmark package."""

from __future__ import annotations

import ast
import json
from pathlib import Path

import pytest

from pcc_bench import cli
from pcc_bench.tables import terminal_table

ROOT = Path(__file__).resolve().parents[2]


def test_version(capsys):
    import pcc_agent

    assert cli.main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"pcc-control {pcc_agent.__version__}"


def test_help_lists_every_command_within_100_columns(capsys):
    assert cli.main([]) == 0
    out = capsys.readouterr().out
    for name in ("train", "evaluate", "reproduce", "vs-sac", "diagnostics", "speed"):
        assert f"  {name} " in out
    assert max(len(line) for line in out.splitlines()) <= 100


def test_unknown_command_is_refused(capsys):
    assert cli.main(["bogus"]) == 2
    assert "unknown command 'bogus'" in capsys.readouterr().err


@pytest.mark.parametrize("argv", [[name] for name in cli.COMMANDS if name != "speed"]
                         + [["speed", name] for name in cli.SPEED_COMMANDS])
def test_every_command_has_help_with_an_example(argv, capsys):
    with pytest.raises(SystemExit) as stop:
        cli.main([*argv, "--help"])
    assert stop.value.code == 0
    out = capsys.readouterr().out
    prog = "pcc " + " ".join(argv)
    assert out.startswith(f"usage: {prog}")
    assert "examples" in out and f"\n  {prog} " in out


def test_train_then_evaluate(tmp_path, capsys):
    model = tmp_path / "planar.pt"
    assert cli.main(["train", "--env", "pcc/Planar-v0", "--samples", "200", "--epochs", "1",
                     "--output", str(model), "--data-dir", str(tmp_path / "data"),
                     "--no-progress"]) == 0
    assert model.exists()
    capsys.readouterr()
    assert cli.main(["evaluate", str(model), "--num-tasks", "2", "--hold", "--json",
                     str(tmp_path / "eval.json")]) == 0
    out = capsys.readouterr().out
    assert "pcc on pcc/Planar-v0" in out and "oracle" in out and "mean" in out
    assert "Goal hold: steps of 100 in the goal region" in out
    assert max(len(line) for line in out.splitlines() if str(tmp_path) not in line) <= 100
    hold = json.loads((tmp_path / "eval.json").read_text())["goal_hold"]
    assert set(hold) == {"pcc", "oracle"} and hold["pcc"]["starts"] == hold["oracle"]["starts"]
    assert all(0 <= steps <= 100 for steps in hold["pcc"]["steps_held"])


def test_train_keeps_the_weights_that_control_best(tmp_path, capsys):
    assert cli.main(["train", "--env", "pcc/Planar-v0", "--samples", "200", "--epochs", "2",
                     "--keep-best-control", "1", "--output", str(tmp_path / "planar.pt"),
                     "--data-dir", str(tmp_path / "data"), "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "Validation control (% in goal, 5 tasks) by epoch: 1 " in out and "final" in out
    assert "kept " in out and (tmp_path / "planar.pt").exists()


def test_train_with_a_prediction_horizon(tmp_path, capsys):
    args = ["train", "--env", "pcc/Planar-v0", "--samples", "100", "--epochs", "1",
            "--output", str(tmp_path / "planar.pt"), "--data-dir", str(tmp_path / "data"),
            "--no-progress"]
    assert cli.main([*args, "--prediction-horizon", "2"]) == 0
    from pcc_agent.agent import PCCAgent

    agent = PCCAgent.load(tmp_path / "planar.pt")
    assert agent.preset.train.prediction_horizon == 2
    with pytest.raises(SystemExit, match="--prediction-horizon must be at least 2"):
        cli.main([*args, "--prediction-horizon", "1"])


def test_evaluate_refuses_a_missing_model(tmp_path):
    with pytest.raises(SystemExit, match="No saved agent"):
        cli.main(["evaluate", str(tmp_path / "none.pt")])


def test_terminal_table_wraps_to_the_width():
    text = terminal_table(["name", "long"], [["a", "word " * 60], ["b", "x"]], width=40)
    assert max(len(line) for line in text.splitlines()) <= 40
    assert text.splitlines()[2].startswith("a ")


def _imports(path: Path) -> set[str]:
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module:
            names.add(node.module)
            if node.module == "pcc_bench":
                names |= {f"pcc_bench.{alias.name}" for alias in node.names}
    return names


def test_the_library_never_imports_the_benchmarks():
    for package in ("pcc_agent", "pcc_envs"):
        for path in (ROOT / package).rglob("*.py"):
            bad = {n for n in _imports(path) if n.split(".")[0] in ("pcc_bench", "benchmarks")}
            assert not bad, f"{path} imports {bad}"


def test_benchmark_modules_are_small_and_free_of_import_cycles():
    graph = {}
    for path in (ROOT / "pcc_bench").glob("*.py"):
        assert len(path.read_text().splitlines()) <= 600, path
        tree = ast.parse(path.read_text())
        top = [n for n in tree.body if isinstance(n, ast.Import | ast.ImportFrom)]
        graph[f"pcc_bench.{path.stem}"] = {
            n.module if n.module != "pcc_bench" else f"pcc_bench.{a.name}"
            for n in top if isinstance(n, ast.ImportFrom) and (n.module or "").startswith(
                "pcc_bench") for a in n.names}

    def visit(node, stack):
        for nxt in graph.get(node, ()):
            assert nxt not in stack, f"import cycle: {[*stack, nxt]}"
            visit(nxt, [*stack, nxt])

    for module in graph:
        visit(module, [module])
