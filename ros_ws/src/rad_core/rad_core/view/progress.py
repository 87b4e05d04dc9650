"""A progress bar for long runs."""

from __future__ import annotations

import sys
import time
from typing import TextIO


class ProgressBar:
    """A one-line bar on a terminal (nothing when the stream is not one), so a
    long run shows it is alive without filling logs; no tqdm dependency."""

    def __init__(self, total: int, label: str = '', stream: TextIO | None = None, width: int = 30):
        self.total, self.label, self.width, self.done = max(total, 1), label, width, 0
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = hasattr(self.stream, 'isatty') and self.stream.isatty()
        self.t0 = time.perf_counter()

    def __call__(self, row: dict | None = None) -> None:
        self.done += 1
        if not self.enabled:
            return
        filled = self.width * self.done // self.total
        elapsed = time.perf_counter() - self.t0
        eta = elapsed / self.done * (self.total - self.done)
        self.stream.write(f'\r{self.label} [{"#" * filled}{"." * (self.width - filled)}] '
                          f'{self.done}/{self.total} {elapsed:.0f}s, ~{eta:.0f}s left ')
        if self.done >= self.total:
            self.stream.write('\n')
        self.stream.flush()
