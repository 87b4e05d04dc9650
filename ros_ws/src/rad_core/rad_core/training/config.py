"""The knobs both learners share: `LearnerConfig`, the base of `dqn.TrainConfig` (`rad train`) and
`expert.ExpertConfig` (`rad expert`).

Each field is declared once, with its help (`knob`), which the command line shows as the flag's
help: `rad <command> --<field-name-with-dashes> VALUE` sets any field. A config that needs another
default for a shared field redeclares it with `LearnerConfig.with_default`, which keeps the help.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import Any, Self

from rad_core.domain.errors import RadError


def knob(default, help: str):
    """A config field with its default and its help (the command line's flag help)."""
    return field(default=default, metadata={'help': help})


@dataclass
class LearnerConfig:
    """What every training run here has: its seed, the network it starts from, and the optimiser
    and target network of its TD updates."""

    seed: int = knob(0, 'seeds every random choice of the run (scenes, exploration, the held-out split, '
                        "batch sampling) and torch's generator (new weights)")
    init: str = knob('', "the network to start from: a shipped name ('milp-dqn-mixed') or a model.pt; "
                         "rad train starts from new weights where it is empty")
    lr: float = knob(3e-4, 'Adam learning rate')
    batch_size: int = knob(32, 'transitions per gradient step')
    target_update: int = knob(1_000, 'steps between hard target-network updates (rad train: environment '
                                     'steps; rad expert: gradient steps)')
    gamma: float = knob(0.999, "discount (the paper's)")
    grad_clip: float = knob(10.0, 'gradient norm clip')
    threads: int = knob(1, 'torch CPU threads (1 is fastest on the 2-core machine when anything else runs)')

    @classmethod
    def with_default(cls, name: str, default: Any):
        """The shared field `name` with another default, its help kept: for a config built on this
        one, `lr: float = LearnerConfig.with_default('lr', 3e-5)`."""
        return knob(default, cls.__dataclass_fields__[name].metadata['help'])

    def validate(self) -> None:
        """The shared fields' bounds; a config built on this one checks its own fields too."""
        self.require_positive('batch_size', 'target_update', 'threads')
        if not (0 < self.gamma <= 1) or self.lr <= 0:
            raise RadError('need 0 < gamma <= 1 and lr > 0')
        if not self.grad_clip > 0:
            raise RadError(f'grad_clip must be a positive gradient norm, got {self.grad_clip}')

    def require_positive(self, *names: str) -> None:
        """Each named field is at least 1."""
        for name in names:
            if getattr(self, name) < 1:
                raise RadError(f'{name} must be at least 1, got {getattr(self, name)}')

    @classmethod
    def from_dict(cls, d: dict) -> Self:
        """The config a stored document holds (a checkpoint's, a run folder's config.json); keys
        this version does not know are dropped, fields the document lacks take their defaults."""
        known = {f.name for f in fields(cls)}
        return cls(**{k: v for k, v in d.items() if k in known})
