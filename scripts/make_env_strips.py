"""Write a PNG strip of observation frames from a short random rollout for every env.

Each strip shows the newest frame of every ``--every``-th observation of a uniformly random
rollout from the env's start distribution, scaled by ``--scale`` with nearest-neighbour
interpolation, into ``docs/images/<name>.png`` (``name`` = the id without ``pcc/`` and
``-v0``).

Usage:
    python scripts/make_env_strips.py
    python scripts/make_env_strips.py --envs pcc/Planar-v0 --frames 10
"""

from __future__ import annotations

import argparse
from pathlib import Path

import cv2
import gymnasium as gym
import numpy as np

import pcc_envs

ROOT = Path(__file__).resolve().parents[1]


def strip(env_id: str, frames: int, every: int, scale: int, seed: int) -> np.ndarray:
    """The strip image of one env: ``frames`` frames side by side, 2-pixel grey gaps."""
    env = gym.make(env_id)
    obs, _ = env.reset(seed=seed)
    env.action_space.seed(seed)
    shots = [obs[-1]]
    while len(shots) < frames:
        for _ in range(every):
            obs, _, terminated, truncated, _ = env.step(env.action_space.sample())
            if terminated or truncated:
                obs, _ = env.reset()
        shots.append(obs[-1])
    env.close()
    h, w = shots[0].shape
    gap = np.full((h * scale, 2), 128, dtype=np.uint8)
    tiles = []
    for shot in shots:
        tiles += [cv2.resize(shot, (w * scale, h * scale), interpolation=cv2.INTER_NEAREST), gap]
    return np.concatenate(tiles[:-1], axis=1)


def main(argv: list[str] | None = None) -> None:
    """Command-line entry point."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--envs", nargs="*", default=None, help="ids (default: all registered)")
    parser.add_argument("--frames", type=int, default=8)
    parser.add_argument("--every", type=int, default=3, help="env steps between frames")
    parser.add_argument("--scale", type=int, default=3)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "images")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    for env_id in args.envs or pcc_envs.ENV_IDS:
        try:
            image = strip(env_id, args.frames, args.every, args.scale, args.seed)
        except ImportError as exc:  # e.g. LaneKeeping without pybullet
            print(f"skipped {env_id}: {exc}")
            continue
        name = env_id.split("/")[-1].removesuffix("-v0")
        path = args.out / f"{name}.png"
        cv2.imwrite(str(path), image)
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
