"""Graph attention transformer network (GATN) of the LVWS paper, section III-B.

* :class:`GATLayer` — Eqs. 1-2, multi-head: h_i' = a_ii W h_i + LeakyReLU(sum_{j != i,
  P_ij != 0} a_ij W h_j), with a_ij a softmax over i's neighbours (and i itself) of
  LeakyReLU(a^T [W h_i || W h_j]). The robot graph uses Q = all ones; the task graph
  uses P (P_ij = 1: task i is a prerequisite of task j), so a task attends to the
  tasks waiting on it.
* :class:`TransformerLayer` — Eqs. 3-5: a global embedding g attends over the node
  embeddings (beta_j = softmax(U2 g . U3 h_j / sqrt(d))), g_bar = LN(sum_j beta_j U1 h_j + g),
  g' = LN(MLP(g_bar) + g_bar); the same layer updates every node embedding with the
  nodes as keys.
* :class:`GATN` — GATs and transformers for robots and tasks, then the reward MLP of
  Eq. 6, R_ij = psi(h_i^r || h_j^t || g^r || g^t), for every robot and every task plus
  the idle task. ``use_transformer=False`` gives the DBGM-style GAT-only network.

Everything is batched over padded graphs with masks, and permutation-equivariant in
robots and tasks (no positional encodings, masked sums only).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass

import numpy as np
import torch
from torch import Tensor, nn

from lvws_ros.learning.features import PAIR_FEATURES, ROBOT_FEATURES, TASK_FEATURES, GraphFeatures

NEG = -1e9  # masked logits


@dataclass(frozen=True)
class GATNConfig:
    hidden: int = 64
    gat_layers: int = 2
    gat_heads: int = 4
    transformer_layers: int = 2
    transformer_heads: int = 4
    mlp_hidden: int = 128
    use_transformer: bool = True

    def to_dict(self) -> dict[str, int | bool]:
        return asdict(self)


class GATLayer(nn.Module):
    """Eqs. 1-2 with K heads (concatenated)."""

    def __init__(self, dim_in: int, dim_out: int, heads: int) -> None:
        super().__init__()
        if dim_out % heads:
            raise ValueError("dim_out must be divisible by heads")
        self.heads, self.dh = heads, dim_out // heads
        self.w = nn.Linear(dim_in, dim_out, bias=False)
        self.a_src = nn.Parameter(torch.randn(heads, self.dh) / math.sqrt(self.dh))
        self.a_dst = nn.Parameter(torch.randn(heads, self.dh) / math.sqrt(self.dh))
        self.act = nn.LeakyReLU(0.2)

    def forward(self, h: Tensor, adj: Tensor, mask: Tensor) -> Tensor:
        """h: (B, n, d_in); adj: (B, n, n) bool, adj[b, i, j] = P_ij; mask: (B, n) real nodes."""
        b, n, _ = h.shape
        wh = self.w(h).view(b, n, self.heads, self.dh)  # W h
        # a^T [W h_i || W h_j] = a_src . W h_i + a_dst . W h_j
        e = (wh * self.a_src).sum(-1).unsqueeze(2) + (wh * self.a_dst).sum(-1).unsqueeze(1)  # (B, n, n, H)
        eye = torch.eye(n, dtype=torch.bool, device=h.device).unsqueeze(0)
        allowed = (adj | eye) & mask.unsqueeze(1) & mask.unsqueeze(2)
        e = self.act(e).masked_fill(~allowed.unsqueeze(-1), NEG)
        alpha = torch.softmax(e, dim=2)  # over neighbours j (and i itself)
        self_term = torch.diagonal(alpha, dim1=1, dim2=2).permute(0, 2, 1).unsqueeze(-1) * wh
        neigh = alpha.masked_fill(eye.unsqueeze(-1), 0.0)
        neigh_term = torch.einsum("bijh,bjhd->bihd", neigh, wh)
        out = self_term + self.act(neigh_term)
        return out.reshape(b, n, -1) * mask.unsqueeze(-1)


class TransformerLayer(nn.Module):
    """Eqs. 3-5 for the global embedding g, and the same layer for every node."""

    def __init__(self, dim: int, heads: int, mlp_hidden: int) -> None:
        super().__init__()
        if dim % heads:
            raise ValueError("dim must be divisible by heads")
        self.heads, self.dh = heads, dim // heads
        self.u1 = nn.Linear(dim, dim, bias=False)
        self.u2 = nn.Linear(dim, dim, bias=False)
        self.u3 = nn.Linear(dim, dim, bias=False)
        self.ln1 = nn.LayerNorm(dim)
        self.ln2 = nn.LayerNorm(dim)
        self.mlp = nn.Sequential(nn.Linear(dim, mlp_hidden), nn.ReLU(), nn.Linear(mlp_hidden, dim))

    def _attend(self, queries: Tensor, h: Tensor, mask: Tensor) -> Tensor:
        b, q, d = queries.shape
        n = h.shape[1]
        qh = self.u2(queries).view(b, q, self.heads, self.dh)
        kh = self.u3(h).view(b, n, self.heads, self.dh)
        vh = self.u1(h).view(b, n, self.heads, self.dh)
        logits = torch.einsum("bqhd,bnhd->bhqn", qh, kh) / math.sqrt(self.dh)
        logits = logits.masked_fill(~mask[:, None, None, :], NEG)
        beta = torch.softmax(logits, dim=-1)  # Eq. 4
        mixed = torch.einsum("bhqn,bnhd->bqhd", beta, vh).reshape(b, q, d)
        bar = self.ln1(mixed + queries)  # Eq. 3
        return self.ln2(self.mlp(bar) + bar)  # Eq. 5

    def forward(self, g: Tensor, h: Tensor, mask: Tensor) -> tuple[Tensor, Tensor]:
        """g: (B, d) global; h: (B, n, d) nodes; mask: (B, n)."""
        out = self._attend(torch.cat([g.unsqueeze(1), h], dim=1), h, mask)
        return out[:, 0], out[:, 1:] * mask.unsqueeze(-1)


class GraphEncoder(nn.Module):
    """Input projection, GAT layers, then transformer layers; returns (g, H)."""

    def __init__(self, dim_in: int, cfg: GATNConfig) -> None:
        super().__init__()
        self.inp = nn.Linear(dim_in, cfg.hidden)
        self.gats = nn.ModuleList(GATLayer(cfg.hidden, cfg.hidden, cfg.gat_heads) for _ in range(cfg.gat_layers))
        self.transformers = nn.ModuleList(
            TransformerLayer(cfg.hidden, cfg.transformer_heads, cfg.mlp_hidden)
            for _ in range(cfg.transformer_layers if cfg.use_transformer else 0)
        )
        self.g0 = nn.Parameter(torch.zeros(cfg.hidden))
        self.use_transformer = cfg.use_transformer

    def forward(self, x: Tensor, adj: Tensor, mask: Tensor) -> tuple[Tensor, Tensor]:
        h = self.inp(x) * mask.unsqueeze(-1)
        for gat in self.gats:
            h = h + gat(h, adj, mask)  # residual keeps deep stacks trainable
        g = self.g0.expand(x.shape[0], -1)
        if not self.use_transformer:
            return torch.zeros_like(g), h  # DBGM-style: no global context
        for layer in self.transformers:
            g, h = layer(g, h, mask)
        return g, h


class GATN(nn.Module):
    """R = GATN(robot graph, task graph): (B, N, M+1) rewards, last column idle (Eq. 6)."""

    def __init__(self, cfg: GATNConfig | None = None) -> None:
        super().__init__()
        self.cfg = cfg or GATNConfig()
        d = self.cfg.hidden
        self.robot_encoder = GraphEncoder(ROBOT_FEATURES, self.cfg)
        self.task_encoder = GraphEncoder(TASK_FEATURES, self.cfg)
        # psi's first layer split over (h_r || h_t || g_r || g_t): an N x (M+1) sum
        # of broadcast terms instead of materialising every concatenation.
        self.psi_r = nn.Linear(d, self.cfg.mlp_hidden)
        self.psi_t = nn.Linear(d, self.cfg.mlp_hidden, bias=False)
        self.psi_g = nn.Linear(2 * d, self.cfg.mlp_hidden, bias=False)
        self.psi_p = nn.Linear(PAIR_FEATURES, self.cfg.mlp_hidden, bias=False)  # our pair features
        self.psi_out = nn.Sequential(nn.ReLU(), nn.Linear(self.cfg.mlp_hidden, self.cfg.mlp_hidden), nn.ReLU(),
                                     nn.Linear(self.cfg.mlp_hidden, 1))

    def forward(self, batch: Batch, rows: Tensor | None = None, cols: Tensor | None = None) -> Tensor:
        """(B, N, M+1) rewards; with ``rows``/``cols`` (index tensors, one graph) only
        the entries a decision reads, (1, len(rows), len(cols)): Eq. 6 for the free
        robots x the ready tasks and the idle task, the encoders over whole graphs."""
        b, n = batch.robot_mask.shape
        full = torch.ones(b, n, n, dtype=torch.bool, device=batch.robots.device)  # Q = ones
        g_r, h_r = self.robot_encoder(batch.robots, full, batch.robot_mask)
        g_t, h_t = self.task_encoder(batch.tasks, batch.task_adjacency, batch.task_mask)
        pairs = batch.pairs
        if rows is not None and cols is not None:
            h_r, h_t, pairs = h_r[:, rows], h_t[:, cols], pairs[:, rows][:, :, cols]
        z = (self.psi_r(h_r).unsqueeze(2) + self.psi_t(h_t).unsqueeze(1)
             + self.psi_g(torch.cat([g_r, g_t], dim=-1))[:, None, None, :] + self.psi_p(pairs))
        return self.psi_out(z).squeeze(-1)


@dataclass
class Batch:
    robots: Tensor  # (B, N, Fr)
    robot_mask: Tensor  # (B, N)
    tasks: Tensor  # (B, M+1, Ft) with each graph's idle vertex at its own index m_b
    task_mask: Tensor  # (B, M+1)
    task_adjacency: Tensor  # (B, M+1, M+1)
    idle_index: Tensor  # (B,) column of each graph's idle task
    pairs: Tensor  # (B, N, M+1, PAIR_FEATURES)

    def reward_mask(self) -> Tensor:
        """(B, N, M+1): real robot x real task (or idle) entries."""
        return self.robot_mask.unsqueeze(2) & self.task_mask.unsqueeze(1)


def collate(graphs: Sequence[GraphFeatures]) -> Batch:
    """Pad graphs of different sizes into one batch. Graph b keeps its idle task at
    column m_b (its own M); padded columns after it are masked out."""
    bsz = len(graphs)
    n = max(g.robots.shape[0] for g in graphs)
    m1 = max(g.tasks.shape[0] for g in graphs)
    robots = np.zeros((bsz, n, ROBOT_FEATURES), np.float32)
    rmask = np.zeros((bsz, n), bool)
    tasks = np.zeros((bsz, m1, TASK_FEATURES), np.float32)
    tmask = np.zeros((bsz, m1), bool)
    adj = np.zeros((bsz, m1, m1), bool)
    idle = np.zeros(bsz, np.int64)
    pairs = np.zeros((bsz, n, m1, PAIR_FEATURES), np.float32)
    for k, g in enumerate(graphs):
        nr, nt = g.robots.shape[0], g.tasks.shape[0]
        robots[k, :nr], rmask[k, :nr] = g.robots, True
        tasks[k, :nt], tmask[k, :nt] = g.tasks, True
        adj[k, :nt, :nt] = g.task_adjacency
        idle[k] = nt - 1
        pairs[k, :nr, :nt] = g.pairs
    return Batch(torch.from_numpy(robots), torch.from_numpy(rmask), torch.from_numpy(tasks),
                 torch.from_numpy(tmask), torch.from_numpy(adj), torch.from_numpy(idle), torch.from_numpy(pairs))


def reward_matrix(model: GATN, features: GraphFeatures, rows: Sequence[int] | None = None,
                  cols: Sequence[int] | None = None) -> np.ndarray:
    """One forward pass for one decision step: the N x (M+1) reward matrix. With
    ``rows`` and ``cols`` only those entries are computed (the rest is NaN): Eq. 6 for
    what the matching reads."""
    with torch.inference_mode():
        batch = collate([features])
        if rows is None or cols is None:
            return model(batch)[0].numpy().astype(np.float64)
        r = np.full((features.robots.shape[0], features.tasks.shape[0]), np.nan)
        part = model(batch, torch.as_tensor(list(rows)), torch.as_tensor(list(cols)))[0].numpy()
        r[np.ix_(list(rows), list(cols))] = part
        return r
