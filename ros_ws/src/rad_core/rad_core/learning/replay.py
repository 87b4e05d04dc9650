"""Uniform experience replay of graph transitions.

A transition is (s, k, r, done, s'): k indexes the candidate actions of s
(-1: terminate). Observations are stored as they are (numpy arrays of any
size); s' of one step is s of the next, so consecutive transitions share the
same object and memory holds each state once.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from rad_core.learning.graph import GraphObs


class Transition(NamedTuple):
    obs: GraphObs
    action: int          # index into obs's candidate actions, -1 = terminate
    reward: float
    done: bool
    next_obs: GraphObs | None   # None when done


class ReplayBuffer:
    def __init__(self, capacity: int):
        self.capacity = int(capacity)
        self.items: list[Transition] = []
        self.next = 0   # where the next transition goes once full

    def __len__(self) -> int:
        return len(self.items)

    def add(self, t: Transition) -> None:
        if len(self.items) < self.capacity:
            self.items.append(t)
        else:
            self.items[self.next] = t
        self.next = (self.next + 1) % self.capacity

    def sample(self, n: int, rng: np.random.Generator) -> list[Transition]:
        idx = rng.integers(0, len(self.items), size=n)
        return [self.items[i] for i in idx]

    def state_dict(self) -> dict:
        return {'capacity': self.capacity, 'items': self.items, 'next': self.next}

    def load_state_dict(self, d: dict) -> None:
        self.capacity, self.next = int(d['capacity']), int(d['next'])
        self.items = [Transition(GraphObs(*t[0]), int(t[1]), float(t[2]), bool(t[3]),
                                 None if t[4] is None else GraphObs(*t[4])) for t in d['items']]
