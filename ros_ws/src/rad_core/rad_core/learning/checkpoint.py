"""Checkpoint files: the trained policy, and everything to resume a training.

Two files, both written atomically (a temporary file in the same folder, then
os.replace, so a kill at any moment leaves the previous file or the new one,
never half of one):

- model file (`rad-qnet/1`): format, network sizes, weights, the action space
  and training summary. Small (about 0.5 MB); the shipped agents are these.
  Loaded with torch's weights-only unpickler: it holds tensors and plain data.
- training checkpoint (`rad-train/1`): the model file's content plus the
  target network, optimizer, replay buffer, random generator states and the
  training position. Resuming from it continues the run exactly.

Every way a file can be wrong (missing, not a torch file, truncated, another
format or version, weights that do not fit the network) is a `CheckpointError`
naming the file and the problem; nothing falls back to another policy.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Any

import torch

from rad_core.domain.errors import RadError

MODEL_FORMAT = 'rad-qnet/1'
TRAIN_FORMAT = 'rad-train/1'
WEIGHTS_DIR = Path(__file__).resolve().parent / 'weights'


class CheckpointError(RadError):
    pass


def atomic_save(obj: Any, path: str | Path, save=None) -> None:
    """Write obj to path atomically; save(obj, file): how (default torch.save)."""
    save = save or torch.save
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=path.name + '.', suffix='.tmp', dir=path.parent)
    try:
        with os.fdopen(fd, 'wb') as f:
            save(obj, f)
            f.flush()
            os.fsync(f.fileno())
        os.chmod(tmp, 0o644)   # mkstemp's 0600 would hide shipped weights from other users
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def resolve(name_or_path: str | Path) -> Path:
    """A shipped agent's model file by name ('milp-dqn'), or any path."""
    text = str(name_or_path)
    shipped = WEIGHTS_DIR / f'{text}.pt'
    if os.sep not in text and not text.endswith('.pt') and shipped.is_file():
        return shipped
    return Path(text)


def read(path: str | Path, expect: str, weights_only: bool = True) -> dict:
    path = Path(path)
    if not path.exists():
        raise CheckpointError(f'checkpoint {str(path)!r} does not exist')
    if not path.is_file():
        raise CheckpointError(f'checkpoint {str(path)!r} is not a file')
    try:
        doc = torch.load(path, map_location='cpu', weights_only=weights_only)
    except Exception as e:  # noqa: BLE001 - torch raises many kinds for a bad file
        detail = str(e).splitlines()[0][:120] if str(e) else type(e).__name__
        if 'Weights only load failed' in detail:
            detail = ('it is not a torch file of tensors and plain data; a training checkpoint? '
                      'pass the model.pt beside it')
        raise CheckpointError(f'checkpoint {str(path)!r} is corrupt or not a rad model file ({detail})') from None
    if not isinstance(doc, dict) or 'format' not in doc:
        raise CheckpointError(f'checkpoint {str(path)!r} has no format field: not a rad checkpoint')
    if doc['format'] != expect:
        raise CheckpointError(f'checkpoint {str(path)!r} has format {doc["format"]!r}; this rad reads {expect!r}')
    return doc


def load_weights(module: torch.nn.Module, state: dict, path: str | Path, what: str = 'weights') -> None:
    try:
        module.load_state_dict(state)
    except (RuntimeError, KeyError, TypeError) as e:
        first = str(e).splitlines()[0] if str(e) else type(e).__name__
        raise CheckpointError(f'checkpoint {str(path)!r}: {what} do not fit the network ({first[:160]})') from None
