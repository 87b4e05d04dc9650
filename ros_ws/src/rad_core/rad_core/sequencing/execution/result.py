"""What an executed assembly produced: rad-result/1, measured coverage, deviations."""

from __future__ import annotations

import numpy as np

from rad_core.allocation.result import AllocationResult
from rad_core.domain.coverage import measured_coverage
from rad_core.domain.scene import Scene

FORMAT = 'rad-result/1'


def deviation(expected: Scene, measured: Scene, tol: float, set_aside: dict[str, str] | None = None) -> str | None:
    """Why the measured world is not the expected one (a block off by more than tol
    metres, or turned, or one registration set aside, or one the plan did not have
    that is seen again), or None when it matches.

    set_aside: blocks registration could not express (block id -> why), for the message.
    """
    set_aside = set_aside or {}
    seen = {b.id: b for b in measured.blocks}
    for block in expected.blocks:
        other = seen.get(block.id)
        if other is None and block.id in set_aside:
            return f'block {block.id} cannot be registered: {set_aside[block.id]}'
        if other is None:
            return f'block {block.id} is not seen by motion capture'
        off = float(np.linalg.norm(np.subtract(other.position, block.position)))
        if off > tol:
            return f'block {block.id} is {off * 1e3:.1f} mm from where the plan put it'
        if other.yaw != block.yaw:
            return f'block {block.id} is turned {other.yaw} deg, the plan has {block.yaw} deg'
    known = {b.id for b in expected.blocks}
    for block in measured.blocks:
        if block.id not in known:
            return f'block {block.id} is seen again (it was not in the plan)'
    return None


def result_document(scene: Scene, allocation: AllocationResult | None, steps: list[dict], final: Scene | None,
                    timings: dict, reallocations: list[dict] = (), execution: dict | None = None) -> dict:
    """The rad-result/1 document of a run (steps: PlanStep.to_dict() of executed steps;
    reallocations: `Reallocation.to_dict()` of every re-allocation its plans made; execution:
    the execute loop's recovery figures, `ExecutionResult.execution()`: replans, faults met and
    whether a new plan recovered from each, recovered_faults, lost_blocks)."""
    doc = {
        'format': FORMAT,
        'scene': scene.to_dict(),
        'allocation': allocation.to_dict() if allocation is not None else None,
        'steps': steps,
        'final_blocks': [b.to_dict() for b in final.blocks] if final is not None else [],
        'coverage': measured_coverage(final) if final is not None else 0.0,
        'timings': timings,
        'reallocations': list(reallocations),
    }
    if final is not None and final.feeder is not None:
        doc['final_feeder'] = final.feeder.to_dict()     # the blocks still in it (placed ones have left)
    if execution is not None:
        doc['execution'] = execution
    return doc


def final_scene(doc: dict) -> Scene | None:
    """The scene a rad-result/1 document ends with: its scene with the final blocks (and what is
    left in a feeder); None when it has no final blocks."""
    if not doc.get('final_blocks'):
        return None
    final = {**doc['scene'], 'blocks': doc['final_blocks']}
    final.pop('feeder', None)
    if doc.get('final_feeder'):
        final['feeder'] = doc['final_feeder']
    return Scene.from_dict(final)
