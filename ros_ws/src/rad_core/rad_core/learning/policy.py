"""A trained Q-network as a `sequencing.Policy`: the scores are Q-values.

scores(env, actions, rng) returns Q(s, a) for every candidate and Q(s, stop)
last, so `ranked_actions` keeps exactly the actions the network values above
terminating. The greedy choice needs no randomness; rng is accepted for the
common interface (a search adds its own exploration).

Graphs below `ONE_THREAD_BELOW` nodes are scored on one thread. A forward of a
few hundred nodes takes about 10 ms on one core; torch's default of a thread per
core makes it 20-30 times slower whenever another process holds a core (the twin,
a node beside it, a solver), as the threads wait on each other.
"""

from __future__ import annotations

from contextlib import contextmanager
from pathlib import Path

import numpy as np
import torch

from rad_core.env.mdp import Action, AssemblyEnv
from rad_core.learning import checkpoint as ckpt
from rad_core.learning.graph import Observer
from rad_core.learning.network import NetConfig, QNetwork, collate


ONE_THREAD_BELOW = 1024
"""Node count from which a forward uses torch's own thread count."""


@contextmanager
def _threads_for(nodes: int):
    """One torch thread for a graph below ONE_THREAD_BELOW nodes, the process's setting otherwise."""
    before = torch.get_num_threads()
    if nodes >= ONE_THREAD_BELOW or before == 1:
        yield
        return
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(before)


class QPolicy:
    def __init__(self, net: QNetwork, name: str = 'q', actions: str = 'milp', source: str = '',
                 device: str | torch.device = 'cpu', support: str = 'none'):
        self.net = net.to(device).eval()
        self.name, self.actions, self.source, self.device = name, actions, source, torch.device(device)
        self.support = support   # the allocation's support rule in the training data ('none' or 'stable')
        self._observer: tuple | None = None   # (scene, Observer) of the last scene asked about

    @classmethod
    def load(cls, name_or_path: str | Path, device: str | torch.device = 'cpu') -> 'QPolicy':
        """A shipped agent by name ('milp-dqn', 'dqn', 'dqn-rel', 'milp-dqn-mixed') or a
        model file (runs/NAME/model.pt); a bad file raises CheckpointError naming it."""
        path = ckpt.resolve(name_or_path)
        # Model files only, read with torch's weights-only unpickler: a file from
        # elsewhere cannot run code here. (A training checkpoint's model is the
        # model.pt beside it.)
        doc = ckpt.read(path, ckpt.MODEL_FORMAT)
        for key in ('net', 'weights', 'method', 'actions'):
            if key not in doc:
                raise ckpt.CheckpointError(f'checkpoint {str(path)!r} lacks {key!r}')
        try:
            net = QNetwork(NetConfig(**doc['net']))
        except (TypeError, ValueError, AssertionError) as e:
            raise ckpt.CheckpointError(f'checkpoint {str(path)!r}: bad network sizes {doc["net"]!r} ({e})') from None
        ckpt.load_weights(net, doc['weights'], path)
        support = str(doc.get('support', 'none'))   # model files before it was recorded: the paper's MILP
        if support not in ('none', 'stable'):
            raise ckpt.CheckpointError(f'checkpoint {str(path)!r}: unknown allocation support {support!r}')
        return cls(net, str(doc['method']), str(doc['actions']), str(path), device, support)

    def observer(self, env: AssemblyEnv) -> Observer:
        if self._observer is None or self._observer[0] is not env.scene:
            self._observer = (env.scene, Observer(env))
        return self._observer[1]

    @torch.no_grad()
    def scores(self, env: AssemblyEnv, actions: list[Action], rng: np.random.Generator | None = None) -> np.ndarray:
        obs = self.observer(env)(env, actions)
        with _threads_for(obs.num_nodes):
            qa, qs = self.net(collate([obs], self.device))
        return np.concatenate([qa.cpu().numpy(), qs.cpu().numpy()]).astype(float)
