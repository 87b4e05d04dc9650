"""Learning curves of one or more runs as a PNG (matplotlib, headless)."""

from __future__ import annotations

import csv
from pathlib import Path

PANELS = (('eval_return', 'validation return (greedy)'), ('eval_coverage', 'validation coverage (greedy)'),
          ('train_return', 'training return (last 100 episodes)'), ('loss', 'TD loss (smooth L1)'))


def read_progress(path: str | Path) -> list[dict]:
    with open(path, newline='') as f:
        return [{k: float(v) if v not in ('', 'nan') else float('nan') for k, v in row.items()}
                for row in csv.DictReader(f)]


def plot_progress(paths, out: str | Path, title: str = '', labels=None) -> None:
    """One panel per PANELS entry, one line per progress.csv (x: environment steps)."""
    import matplotlib  # matplotlib: only plotting pays for its import
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt  # matplotlib: only plotting pays for its import
    paths = [paths] if isinstance(paths, (str, Path)) else list(paths)
    labels = labels or [Path(p).parent.name for p in paths]
    fig, axes = plt.subplots(2, 2, figsize=(10, 6.5))
    for path, label in zip(paths, labels):
        rows = read_progress(path)
        x = [r['env_steps'] for r in rows]
        for ax, (key, name) in zip(axes.flat, PANELS):
            ax.plot(x, [r.get(key, float('nan')) for r in rows], label=label)
            ax.set_title(name, fontsize=10)
            ax.set_xlabel('environment steps')
            ax.grid(alpha=0.3)
    if len(paths) > 1:
        axes.flat[0].legend(fontsize=8)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=90)
    plt.close(fig)
