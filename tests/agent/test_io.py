"""pcc_agent.io: the shared atomic writers, version dict and logger set-up."""

import json

import pytest

from pcc_agent import io


def test_atomic_writers_write_whole_files_and_leave_no_temporary(tmp_path):
    io.atomic_write_text("hello", tmp_path / "a" / "b.txt")
    io.atomic_write_json(tmp_path / "c.json", {"x": [1, 2]})
    io.atomic_torch_save({"w": 1}, tmp_path / "d.pt")
    assert (tmp_path / "a" / "b.txt").read_text() == "hello"
    assert json.loads((tmp_path / "c.json").read_text()) == {"x": [1, 2]}
    assert (tmp_path / "d.pt").stat().st_size > 0
    assert not list(tmp_path.rglob("*.tmp"))


def test_atomic_write_keeps_the_old_file_when_the_writer_fails(tmp_path):
    path = tmp_path / "kept.txt"
    io.atomic_write_text("old", path)

    def fail(handle):
        handle.write("half")
        raise RuntimeError("disk full")

    with pytest.raises(RuntimeError):
        io.atomic_write(path, fail)
    assert path.read_text() == "old"
    assert not list(tmp_path.glob("*.tmp"))


def test_atomic_save_figure_writes_a_png(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots()
    ax.plot([0, 1])
    io.atomic_save_figure(fig, tmp_path / "f.png")
    plt.close(fig)
    assert (tmp_path / "f.png").read_bytes()[:4] == b"\x89PNG"


def test_versions_name_the_packages():
    assert {"pcc_control", "torch", "gymnasium", "stable_baselines3", "numpy",
            "python"} <= set(io.versions())


def test_sb3_logger_needs_a_folder_for_files(tmp_path):
    with pytest.raises(ValueError, match="need a folder"):
        io.sb3_logger(None, ["csv"])
    logger = io.sb3_logger(tmp_path, ["csv", "tensorboard?"])
    logger.record("x", 1.0)
    logger.dump(0)
    logger.close()
    assert (tmp_path / "progress.csv").exists()
