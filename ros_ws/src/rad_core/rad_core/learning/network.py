"""The attention GNN Q-network (the paper's Sec. IV-B, the predecessor's layout).

    embed:    Linear(5 -> d, no bias) + ReLU on [x, y, z, is_cell, filled]
    3 rounds: h <- h + MHA(h, h, h | mask);  h <- h + FF(h)   (d -> 512 -> d)
    readout:  Q(u, c, .) = MLP([h_u, h_c, mean(h)]) -> 4 rotations
              Q(terminate) = MLP(mean(h)) -> 1

The mask lets every node attend to every other except unplaced units of
different blocks (and itself always, so no row is empty). Only the candidate
(unit, cell) pairs are pushed through the readout. Nothing in the weights
depends on the number of nodes, blocks, block types, cells or regions.

A batch of graphs is padded to its largest graph; padded nodes attend only to
themselves and nobody attends to them, and the mean pool skips them.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import NamedTuple, Sequence

import numpy as np
import torch
from torch import nn

from rad_core.learning.graph import FEATURES, GraphObs, attention_allowed, node_features


@dataclass(frozen=True)
class NetConfig:
    """Sizes of the Q-network (defaults: the predecessor's)."""

    dim: int = 64
    """Width of the node encodings."""
    heads: int = 4
    """Attention heads per round (key size dim / heads)."""
    rounds: int = 3
    """Message-passing rounds."""
    ff: int = 512
    """Hidden width of each round's feed-forward block."""
    readout: int = 128
    """Hidden width of the pair and termination heads."""

    def to_dict(self) -> dict:
        return asdict(self)


class Batch(NamedTuple):
    feat: torch.Tensor        # [B, N, 5]
    blocked: torch.Tensor     # [B, N, N] bool, True where attention is not allowed
    node_valid: torch.Tensor  # [B, N] bool
    act_graph: torch.Tensor   # [A] long, which graph each candidate action belongs to
    act_unit: torch.Tensor    # [A] long, node index (within its graph) of the unit
    act_cell: torch.Tensor    # [A] long, node index of the cell
    act_rot: torch.Tensor     # [A] long
    offsets: torch.Tensor     # [B + 1] long, candidate actions of graph b: offsets[b]:offsets[b+1]


def collate(obs: Sequence[GraphObs], device: torch.device | str = 'cpu') -> Batch:
    b, n = len(obs), max(o.num_nodes for o in obs)
    feat = np.zeros((b, n, FEATURES), np.float32)
    allowed = np.zeros((b, n, n), bool)
    valid = np.zeros((b, n), bool)
    idx = np.arange(n)
    allowed[:, idx, idx] = True
    graphs, units, cells, rots, counts = [], [], [], [], []
    for i, o in enumerate(obs):
        k = o.num_nodes
        feat[i, :k] = node_features(o.pos, o.kind)
        allowed[i, :k, :k] = attention_allowed(o.kind, o.group)
        valid[i, :k] = True
        graphs.append(np.full(o.num_actions, i))
        units.append(o.pairs[:, 0])
        cells.append(o.pairs[:, 1])
        rots.append(o.rot)
        counts.append(o.num_actions)
    offsets = np.concatenate([[0], np.cumsum(counts)])

    def t(x, dtype=torch.long):
        return torch.as_tensor(np.concatenate(x) if isinstance(x, list) else x, dtype=dtype, device=device)

    return Batch(torch.as_tensor(feat, device=device), torch.as_tensor(~allowed, device=device),
                 torch.as_tensor(valid, device=device), t(graphs), t(units), t(cells), t(rots), t(offsets))


class _Round(nn.Module):
    def __init__(self, cfg: NetConfig):
        super().__init__()
        self.attn = nn.MultiheadAttention(cfg.dim, cfg.heads, batch_first=True)
        self.ff = nn.Sequential(nn.Linear(cfg.dim, cfg.ff), nn.ReLU(), nn.Linear(cfg.ff, cfg.dim))

    def forward(self, h: torch.Tensor, blocked: torch.Tensor) -> torch.Tensor:
        a, _ = self.attn(h, h, h, attn_mask=blocked, need_weights=False)
        h = h + a
        return h + self.ff(h)


class QNetwork(nn.Module):
    def __init__(self, cfg: NetConfig = NetConfig()):
        super().__init__()
        self.cfg = cfg
        self.embed = nn.Linear(FEATURES, cfg.dim, bias=False)
        self.rounds = nn.ModuleList(_Round(cfg) for _ in range(cfg.rounds))
        self.pair_head = nn.Sequential(nn.Linear(3 * cfg.dim, cfg.readout), nn.ReLU(), nn.Linear(cfg.readout, 4))
        self.stop_head = nn.Sequential(nn.Linear(cfg.dim, cfg.readout), nn.ReLU(), nn.Linear(cfg.readout, 1))

    def forward(self, batch: Batch) -> tuple[torch.Tensor, torch.Tensor]:
        """(Q of each candidate action [A], Q of terminating in each graph [B])."""
        h = torch.relu(self.embed(batch.feat))
        heads = self.cfg.heads
        blocked = batch.blocked.repeat_interleave(heads, dim=0)
        for layer in self.rounds:
            h = layer(h, blocked)
        w = batch.node_valid.unsqueeze(-1).to(h.dtype)
        pooled = (h * w).sum(1) / w.sum(1).clamp(min=1.0)
        g = batch.act_graph
        pair = torch.cat([h[g, batch.act_unit], h[g, batch.act_cell], pooled[g]], dim=-1)
        q_actions = self.pair_head(pair).gather(1, batch.act_rot.unsqueeze(1)).squeeze(1)
        q_stop = self.stop_head(pooled).squeeze(1)
        return q_actions, q_stop


def graph_max(q_actions: torch.Tensor, q_stop: torch.Tensor, batch: Batch) -> tuple[torch.Tensor, torch.Tensor]:
    """Per graph: the best Q over its candidates and terminate, and which one
    (the candidate's index within its graph, -1 for terminate)."""
    n = q_stop.shape[0]
    best = q_stop.clone()
    arg = torch.full((n,), -1, dtype=torch.long, device=q_stop.device)
    if q_actions.numel():
        amax = torch.full((n,), -torch.inf, device=q_stop.device, dtype=q_actions.dtype)
        amax = amax.scatter_reduce(0, batch.act_graph, q_actions, reduce='amax', include_self=True)
        # Index of the (first) maximiser per graph.
        hit = q_actions == amax[batch.act_graph]
        local = torch.arange(q_actions.numel(), device=q_stop.device) - batch.offsets[batch.act_graph]
        big = torch.iinfo(torch.long).max
        first = torch.full((n,), big, dtype=torch.long, device=q_stop.device).scatter_reduce(
            0, batch.act_graph, torch.where(hit, local, torch.full_like(local, big)), reduce='amin')
        better = amax > q_stop
        best = torch.where(better, amax, q_stop)
        arg = torch.where(better, first, arg)
    return best, arg


def pick(q_actions: torch.Tensor, q_stop: torch.Tensor, batch: Batch, k: torch.Tensor) -> torch.Tensor:
    """Per graph, the Q of its candidate k[b] (an index within the graph), or of
    terminating where k[b] < 0."""
    if not q_actions.numel():
        return q_stop
    idx = (batch.offsets[:-1] + k.clamp(min=0)).clamp(max=q_actions.numel() - 1)
    return torch.where(k >= 0, q_actions[idx], q_stop)
