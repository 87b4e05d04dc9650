"""Tiny DQN runs for the training tests: a small network on a 24-scene g = 3 dataset."""

from __future__ import annotations

from pathlib import Path

from rad_core.training.dataset import build
from rad_core.training.dqn import TrainConfig

SMALL_NET = dict(dim=32, heads=4, rounds=2, ff=64, readout=32)
SMALL_NET_FLAGS = [a for k, v in SMALL_NET.items() for a in (f'--{k}', str(v))]   # the same as rad train flags


def tiny_dataset(folder: Path) -> Path:
    path = folder / 'tiny.jsonl.gz'
    build(path, [3], 24)
    return path


def tiny(dataset, **kw) -> TrainConfig:
    base = dict(dataset=str(dataset), total_steps=120, learning_starts=40, train_every=2, target_update=40,
                batch_size=8, buffer_size=500, eval_every=60, eval_scenes=3, checkpoint_every_s=1e9, **SMALL_NET)
    base.update(kw)
    return TrainConfig(**base)
