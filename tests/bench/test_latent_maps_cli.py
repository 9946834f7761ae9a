"""The latent-map command draws one PNG per saved agent and names missing files."""

from __future__ import annotations

import dataclasses

import pytest

from pcc_agent import PCCAgent
from pcc_agent.presets import get_preset
from pcc_bench import latent_maps


def test_latent_maps_of_saved_agents(tmp_path):
    preset = get_preset("pcc/Planar-v0")
    preset = dataclasses.replace(preset, train=dataclasses.replace(preset.train, epochs=1))
    agent = PCCAgent("pcc/Planar-v0", preset=preset, seed=0, data_cache_dir=tmp_path / "data")
    agent.learn(total_timesteps=200)
    agent.save(tmp_path / "seed0.pt")
    out = tmp_path / "maps"
    assert latent_maps.main([str(tmp_path / "seed0.pt"), "--out", str(out), "--prefix", "x_",
                             "--num-states", "50"]) == 0
    png = out / "x_seed0.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_latent_maps_names_a_missing_checkpoint(tmp_path):
    with pytest.raises(SystemExit, match="nope.pt"):
        latent_maps.main([str(tmp_path / "nope.pt"), "--out", str(tmp_path)])
