"""Graph attention transformer network (GATN) of the LVWS paper, section III-B (model ``lvws-gatn/2``).

* :class:`GATLayer` — Eqs. 1-2 on the robot graph (Q = all ones, dense over padded
  robots): h_i' = a_ii W h_i + LeakyReLU(sum_{j != i} a_ij W h_j), a_ij a softmax over
  i's neighbours and i of LeakyReLU(a^T [W h_i || W h_j]), multi-head.
* :class:`SparseGATLayer` — the same Eqs. 1-2 on the task DAG as message passing over
  its edges (P_ij = 1: task i is a prerequisite of j; a task attends to the tasks
  waiting on it): O(T + E) instead of the dense O(T^2) masks. Exactly the dense layer's
  function on the same graph (tested).
* :class:`GlobalAttention` — Eqs. 3-5: the global embedding g attends over the nodes of
  its graph (beta_j = softmax(U2 g . U3 h_j / sqrt(d))), g_bar = LN(sum_j beta_j U1 h_j + g),
  g' = LN(MLP(g_bar) + g_bar). Ours: every node then takes g in through a residual
  MLP, h_j' = LN(h_j + MLP([h_j || g'])) — O(n) per layer, where our first model let every
  node attend over every node (O(n^2), too slow at 5,000 tasks).
* :class:`GATN` — encoders for robots and tasks, then the reward MLP of Eq. 6,
  R_ij = psi(h_i^r || h_j^t || g^r || g^t || p_ij) with our pair features p_ij, computed
  only for the entries a decision reads (free robots x ready tasks and the idle task).
  ``use_transformer=False`` gives the DBGM-style GAT-only network (g = 0).
* The wait head (``wait_head=True``, ours, beyond the paper): a logit per free robot that
  it should wait voluntarily, from the hidden layer of Eq. 6's MLP at the robot's idle
  entry and its element-wise max over the robot's ready-task entries (what it would give
  up). The paper learns waiting only through the idle column of R; that column competes
  with every task entry of its row, and our calibration never found it worth using.

Graphs of a batch are flattened (robots padded per graph for the dense robot GAT,
tasks concatenated with a graph index), so one batch mixes any sizes; everything is
permutation-equivariant in robots and tasks.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import torch
from torch import Tensor, nn

from lvws_ros.learning.features import (
    LEGACY_PAIR_FEATURES,
    MODEL_FORMATS,
    PAIR_FEATURES,
    ROBOT_FEATURES,
    TASK_FEATURES,
    GraphFeatures,
)

NEG = -1e9  # masked logits
MODEL_FORMAT = MODEL_FORMATS[PAIR_FEATURES]
ENTRY_CHUNK = 1 << 18  # reward entries per chunk at inference: bounds memory at fleet scale
INFERENCE_THREADS = 1
ROW_CHUNK = 256  # attending robots per chunk of the dense robot GAT


@dataclass(frozen=True)
class GATNConfig:
    hidden: int = 64
    gat_layers: int = 2
    gat_heads: int = 4
    transformer_layers: int = 2
    transformer_heads: int = 4
    mlp_hidden: int = 64
    use_transformer: bool = True
    wait_head: bool = False
    pair_features: int = PAIR_FEATURES  # the first ones read: LEGACY_/TRAVEL_/BUSY_PAIR_FEATURES for lvws-gatn/2-4

    def to_dict(self) -> dict[str, int | bool]:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> GATNConfig:
        """A checkpoint's config; one written before the travel features (lvws-gatn/2)
        has no ``pair_features`` and reads the first LEGACY_PAIR_FEATURES."""
        return cls(**{"pair_features": LEGACY_PAIR_FEATURES, **data})


def segment_softmax(logits: Tensor, segment: Tensor, count: int) -> Tensor:
    """Softmax of ``logits`` (E, H) within each segment id of ``segment`` (E,)."""
    if count == 1:
        return torch.softmax(logits, dim=0)  # one segment: the plain softmax (a decision's one graph)
    heads = logits.shape[1]
    top = torch.full((count, heads), NEG, dtype=logits.dtype, device=logits.device)
    top = top.scatter_reduce(0, segment[:, None].expand(-1, heads), logits, reduce="amax", include_self=True)
    ex = torch.exp(logits - top[segment])
    den = torch.zeros((count, heads), dtype=logits.dtype, device=logits.device).index_add_(0, segment, ex)
    return ex / den[segment].clamp(min=1e-30)


class _GATWeights(nn.Module):
    """W, a (split as a_src, a_dst) and the LeakyReLU of Eqs. 1-2, K heads concatenated."""

    def __init__(self, dim_in: int, dim_out: int, heads: int) -> None:
        super().__init__()
        if dim_out % heads:
            raise ValueError("dim_out must be divisible by heads")
        self.heads, self.dh = heads, dim_out // heads
        self.w = nn.Linear(dim_in, dim_out, bias=False)
        self.a_src = nn.Parameter(torch.randn(heads, self.dh) / math.sqrt(self.dh))
        self.a_dst = nn.Parameter(torch.randn(heads, self.dh) / math.sqrt(self.dh))
        self.act = nn.LeakyReLU(0.2)


class GATLayer(_GATWeights):
    """Eqs. 1-2, dense over padded graphs (the robot graph)."""

    def forward(self, h: Tensor, adj: Tensor | None, mask: Tensor) -> Tensor:
        """h: (B, n, d_in); adj: (B, n, n) bool neighbours (None: all, Q = ones); mask: (B, n) real nodes.
        Attending rows go in chunks of ROW_CHUNK: memory O(ROW_CHUNK n) per graph."""
        b, n, _ = h.shape
        wh = self.w(h).view(b, n, self.heads, self.dh)  # W h
        # a^T [W h_i || W h_j] = a_src . W h_i + a_dst . W h_j
        s_src, s_dst = (wh * self.a_src).sum(-1), (wh * self.a_dst).sum(-1)  # (B, n, H)
        if adj is None and not self.training and n and bool(mask.all()):  # every node attends to every node
            return self._complete(wh, s_src, s_dst).reshape(b, n, -1)
        out = [self._rows(wh, s_src, s_dst, adj, mask, a, min(n, a + ROW_CHUNK)) for a in range(0, n, ROW_CHUNK)]
        return torch.cat(out, dim=1).reshape(b, n, -1) * mask.unsqueeze(-1) if out else h.new_zeros(b, 0, wh[0, 0].numel())

    def _complete(self, wh: Tensor, s_src: Tensor, s_dst: Tensor) -> Tensor:
        """Eqs. 1-2 on a complete graph in O(n log n) per head instead of O(n^2): with
        e_ij = LeakyReLU(s_i + t_j), exp(e_ij) factors as exp(s_i) exp(t_j) where
        t_j > -s_i and as exp(0.2 s_i) exp(0.2 t_j) elsewhere, so with the t_j sorted each
        row's softmax sums are a suffix sum plus a prefix sum (in float64; every factor
        is scaled to at most 1 by the row's largest logit, LeakyReLU(s_i + max t)). The
        same values as the dense rows up to float rounding. wh: (B, n, H, d)."""
        slope = float(self.act.negative_slope)
        s, t_own = s_src.permute(0, 2, 1).double(), s_dst.permute(0, 2, 1).double()  # (B, H, n)
        t, order = torch.sort(t_own, dim=-1)
        v = torch.gather(wh.permute(0, 2, 1, 3).double(), 2, order.unsqueeze(-1).expand(-1, -1, -1, wh.shape[-1]))
        top = t[..., -1:]  # (B, H, 1)
        high, low = torch.exp(t - top), torch.exp(slope * (t - top))  # (B, H, n), at most 1

        def cum(w: Tensor) -> tuple[Tensor, Tensor]:  # prefix sums with a leading zero: of w and of w v
            zero = w.new_zeros(*w.shape[:-1], 1)
            return (torch.cat([zero, w.cumsum(-1)], -1),
                    torch.cat([zero.unsqueeze(-1).expand(-1, -1, -1, v.shape[-1]), (w.unsqueeze(-1) * v).cumsum(2)], 2))

        high_w, high_v = cum(high)
        low_w, low_v = cum(low)
        k = torch.searchsorted(t.contiguous(), (-s).contiguous(), right=True)  # (B, H, n): t_q > -s_i from k on
        peak = self.act(s + top)  # the row's largest logit
        a_high, a_low = torch.exp(s + top - peak), torch.exp(slope * (s + top) - peak)  # at most 1
        kv = k.unsqueeze(-1).expand(-1, -1, -1, v.shape[-1])
        num = a_high.unsqueeze(-1) * (high_v[:, :, -1:] - torch.gather(high_v, 2, kv)) \
            + a_low.unsqueeze(-1) * torch.gather(low_v, 2, kv)
        den = a_high * (high_w[..., -1:] - torch.gather(high_w, -1, k)) + a_low * torch.gather(low_w, -1, k)
        own = (torch.exp(self.act(s + t_own) - peak) / den).unsqueeze(-1)  # alpha_ii
        mine = wh.permute(0, 2, 1, 3).double()
        out = own * mine + self.act(num / den.unsqueeze(-1) - own * mine)  # (B, H, n, d)
        return out.permute(0, 2, 1, 3).to(wh.dtype)

    def _rows(self, wh: Tensor, s_src: Tensor, s_dst: Tensor, adj: Tensor | None, mask: Tensor, a: int,
              z: int) -> Tensor:
        n = wh.shape[1]
        e = s_src[:, a:z].unsqueeze(2) + s_dst.unsqueeze(1)  # (B, rows, n, H)
        eye = (torch.arange(a, z)[:, None] == torch.arange(n)[None, :]).unsqueeze(0)
        allowed = mask.unsqueeze(1) & mask[:, a:z].unsqueeze(2)
        if adj is not None:
            allowed = allowed & (adj[:, a:z] | eye)
        e = self.act(e).masked_fill(~allowed.unsqueeze(-1), NEG)
        alpha = torch.softmax(e, dim=2)  # over neighbours j (and i itself)
        self_term = (alpha * eye.unsqueeze(-1)).sum(2).unsqueeze(-1) * wh[:, a:z]
        neigh = alpha.masked_fill(eye.unsqueeze(-1), 0.0)
        neigh_term = torch.einsum("bijh,bjhd->bihd", neigh, wh)
        return self_term + self.act(neigh_term)


class SparseGATLayer(_GATWeights):
    """Eqs. 1-2 by message passing over an edge list (node i attends to itself and to
    every j with an edge i -> j)."""

    def forward(self, h: Tensor, edges: Tensor, mask: Tensor | None = None) -> Tensor:
        """h: (T, d_in) flat nodes; edges: (2, E) [i, j] pairs."""
        t = h.shape[0]
        wh = self.w(h).view(t, self.heads, self.dh)
        s_src = (wh * self.a_src).sum(-1)  # (T, H)
        s_dst = (wh * self.a_dst).sum(-1)
        src, dst = edges[0], edges[1]
        loop = torch.arange(t, device=h.device)
        seg = torch.cat([loop, src])  # the self term first, then the edges
        other = torch.cat([loop, dst])
        alpha = segment_softmax(self.act(s_src[seg] + s_dst[other]), seg, t)
        self_term = alpha[:t].unsqueeze(-1) * wh
        msg = alpha[t:].unsqueeze(-1) * wh[dst]
        neigh = torch.zeros_like(wh).index_add_(0, src, msg)
        return (self_term + self.act(neigh)).reshape(t, -1)


class GlobalAttention(nn.Module):
    """Eqs. 3-5 for the global embedding of each graph; then our O(n) node update."""

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
        self.node = nn.Sequential(nn.Linear(2 * dim, mlp_hidden), nn.ReLU(), nn.Linear(mlp_hidden, dim))
        self.ln3 = nn.LayerNorm(dim)

    def forward(self, g: Tensor, h: Tensor, graph: Tensor) -> tuple[Tensor, Tensor]:
        """g: (B, d); h: (n, d) flat nodes; graph: (n,) the graph of each node."""
        b, d = g.shape
        q = self.u2(g).view(b, self.heads, self.dh)[graph]  # (n, H, dh)
        k = self.u3(h).view(-1, self.heads, self.dh)
        v = self.u1(h).view(-1, self.heads, self.dh)
        beta = segment_softmax((q * k).sum(-1) / math.sqrt(self.dh), graph, b)  # Eq. 4
        if b == 1:
            mixed = (beta.unsqueeze(-1) * v).sum(0).reshape(1, d)
        else:
            mixed = torch.zeros((b, self.heads, self.dh), dtype=h.dtype, device=h.device)
            mixed = mixed.index_add_(0, graph, beta.unsqueeze(-1) * v).reshape(b, d)
        bar = self.ln1(mixed + g)  # Eq. 3
        g_new = self.ln2(self.mlp(bar) + bar)  # Eq. 5
        g_nodes = g_new.expand(len(h), -1) if b == 1 else g_new[graph]
        h_new = self.ln3(h + self.node(torch.cat([h, g_nodes], dim=-1)))  # ours
        return g_new, h_new


class Encoder(nn.Module):
    """Input projection, GAT layers (dense or sparse), global attention; returns (g, h)."""

    def __init__(self, dim_in: int, cfg: GATNConfig, sparse: bool) -> None:
        super().__init__()
        kind = SparseGATLayer if sparse else GATLayer
        self.inp = nn.Linear(dim_in, cfg.hidden)
        self.gats = nn.ModuleList(kind(cfg.hidden, cfg.hidden, cfg.gat_heads) for _ in range(cfg.gat_layers))
        self.globals = nn.ModuleList(
            GlobalAttention(cfg.hidden, cfg.transformer_heads, cfg.mlp_hidden)
            for _ in range(cfg.transformer_layers if cfg.use_transformer else 0))
        self.g0 = nn.Parameter(torch.zeros(cfg.hidden))

    def run_globals(self, h: Tensor, graph: Tensor, count: int) -> tuple[Tensor, Tensor]:
        g = self.g0.expand(count, -1)
        if not len(self.globals):
            return torch.zeros_like(g), h  # DBGM-style: no global context
        for layer in self.globals:
            g, h = layer(g, h, graph)
        return g, h


class GATN(nn.Module):
    """Rewards R_ij (Eq. 6) for the entries of each graph's ``rows`` x ``cols``."""

    def __init__(self, cfg: GATNConfig | None = None) -> None:
        super().__init__()
        self.cfg = cfg or GATNConfig()
        d, hid = self.cfg.hidden, self.cfg.mlp_hidden
        self.robot_encoder = Encoder(ROBOT_FEATURES, self.cfg, sparse=False)
        self.task_encoder = Encoder(TASK_FEATURES, self.cfg, sparse=True)
        # psi's first layer split over (h_r || h_t || g_r || g_t || p): a sum of
        # gathered terms instead of materialising every concatenation.
        self.psi_r = nn.Linear(d, hid)
        self.psi_t = nn.Linear(d, hid, bias=False)
        self.psi_g = nn.Linear(2 * d, hid, bias=False)
        if not 1 <= self.cfg.pair_features <= PAIR_FEATURES:
            raise ValueError(f"pair_features must be in 1..{PAIR_FEATURES}, got {self.cfg.pair_features}")
        self.psi_p = nn.Linear(self.cfg.pair_features, hid, bias=False)
        self.psi_out = nn.Sequential(nn.ReLU(), nn.Linear(hid, hid), nn.ReLU(), nn.Linear(hid, 1))
        self.wait = nn.Sequential(nn.Linear(2 * hid, hid), nn.ReLU(), nn.Linear(hid, 1)) if self.cfg.wait_head \
            else None

    def psi_pairs(self, pairs: Tensor) -> Tensor:
        """psi's pair term on the pair features this model reads (the first
        ``cfg.pair_features``: a lvws-gatn/2 model reads no travel features)."""
        return self.psi_p(pairs[..., : self.cfg.pair_features])

    def encode(self, batch: Batch) -> tuple[Tensor, Tensor, Tensor, Tensor]:
        """(h_r flat over real robots, h_t flat, g_r, g_t)."""
        b = batch.robot_mask.shape[0]
        enc = self.robot_encoder
        hr = enc.inp(batch.robots) * batch.robot_mask.unsqueeze(-1)
        for gat in enc.gats:
            hr = hr + gat(hr, None, batch.robot_mask)  # Q = ones; residual keeps deep stacks trainable
        hr_flat = hr[batch.robot_mask]
        g_r, hr_flat = enc.run_globals(hr_flat, batch.robot_graph, b)
        enc = self.task_encoder
        ht = enc.inp(batch.tasks)
        for gat in enc.gats:
            ht = ht + gat(ht, batch.edges)
        g_t, ht = enc.run_globals(ht, batch.task_graph, b)
        return hr_flat, ht, g_r, g_t

    def _hidden(self, batch: Batch) -> Tensor:
        """(entries, mlp_hidden): the first layer of Eq. 6's MLP psi, before its ReLU."""
        hr, ht, g_r, g_t = self.encode(batch)
        g = self.psi_g(torch.cat([g_r, g_t], dim=-1))
        return self.psi_r(hr)[batch.entry_robot] + self.psi_t(ht)[batch.entry_task] + g[batch.entry_graph] \
            + self.psi_pairs(batch.entry_pairs)

    def forward(self, batch: Batch) -> Tensor:
        """(number of entries,) rewards, in the order of ``batch.entry_*``."""
        return self.psi_out(self._hidden(batch)).squeeze(-1)

    def forward_with_wait(self, batch: Batch) -> tuple[Tensor, Tensor | None]:
        """(rewards of the entries, wait logits of the rows or None without a wait head)."""
        z = self._hidden(batch)
        r = self.psi_out(z).squeeze(-1)
        if self.wait is None:
            return r, None
        return r, self._wait_logits(torch.relu(z), batch.entry_row, batch.entry_idle, batch.rows)

    def _wait_logits(self, zr: Tensor, row: Tensor, idle: Tensor, rows: int) -> Tensor:
        assert self.wait is not None
        at_idle = zr.new_zeros((rows, zr.shape[1])).index_copy_(0, row[idle], zr[idle])
        tasks = ~idle
        best = zr.new_zeros((rows, zr.shape[1])).scatter_reduce_(0, row[tasks, None].expand(-1, zr.shape[1]),
                                                                 zr[tasks], "amax", include_self=True)
        return self.wait(torch.cat([at_idle, best], dim=-1)).squeeze(-1)

    def rewards_one(self, batch: Batch, rows: int, cols: int) -> tuple[Tensor, Tensor | None]:
        """(rows, cols) rewards of a one-graph batch whose entries are its rows x cols,
        computed by broadcasting in chunks of rows (bounded memory at fleet scale), and
        the (rows,) wait logits (None without a wait head)."""
        hr, ht, g_r, g_t = self.encode(batch)
        pr = self.psi_r(hr)[batch.entry_robot.view(rows, cols)[:, 0]] if cols else hr[:0]
        pt = self.psi_t(ht)[batch.entry_task[:cols]] + self.psi_g(torch.cat([g_r, g_t], dim=-1))[0]
        pairs = batch.entry_pairs.view(rows, cols, -1)
        step = max(1, ENTRY_CHUNK // max(cols, 1))
        out, waits = [], []
        for a in range(0, rows, step):
            z = pr[a:a + step, None, :] + pt[None, :, :] + self.psi_pairs(pairs[a:a + step])
            out.append(self.psi_out(z).squeeze(-1))
            if self.wait is not None:
                zr = torch.relu(z)  # the idle entry is the last column
                best = zr[:, :-1].amax(dim=1) if cols > 1 else torch.zeros_like(zr[:, 0])
                waits.append(self.wait(torch.cat([zr[:, -1], best], dim=-1)).squeeze(-1))
        r = torch.cat(out, dim=0) if out else torch.zeros((0, cols))
        if self.wait is None:
            return r, None
        return r, torch.cat(waits) if waits else torch.zeros(0)


@dataclass
class Batch:
    robots: Tensor  # (B, N, Fr) padded
    robot_mask: Tensor  # (B, N)
    robot_graph: Tensor  # (sum N_b,) graph of each real robot, in flat order
    tasks: Tensor  # (sum T_b + 1, Ft) flat
    task_graph: Tensor  # (sum T_b + 1,)
    edges: Tensor  # (2, sum E_b) flat indices
    entry_robot: Tensor  # (entries,) flat robot index
    entry_task: Tensor  # (entries,) flat task index
    entry_graph: Tensor  # (entries,)
    entry_pairs: Tensor  # (entries, PAIR_FEATURES)
    entry_row: Tensor  # (entries,) flat row id (graph, robot) for per-robot terms
    entry_idle: Tensor  # (entries,) bool: the idle column
    rows: int  # number of flat rows

    def to(self, device: torch.device | str) -> Batch:
        """The batch on ``device`` (itself when already there)."""
        moved: dict[str, Any] = {k: v.to(device) if isinstance(v, Tensor) else v for k, v in self.__dict__.items()}
        return Batch(**moved)


def collate(graphs: Sequence[GraphFeatures]) -> Batch:
    """Flatten graphs of any sizes into one batch; the entries of graph b are its
    rows x cols in row-major order, graph after graph."""
    bsz = len(graphs)
    n = max((g.robots.shape[0] for g in graphs), default=0)
    robots = np.zeros((bsz, n, ROBOT_FEATURES), np.float32)
    rmask = np.zeros((bsz, n), bool)
    robot_off = task_off = row_off = 0
    parts: dict[str, list[np.ndarray]] = {k: [] for k in ("tasks", "tgraph", "edges", "er", "et", "eg", "ep", "erow",
                                                          "eidle")}
    for b, g in enumerate(graphs):
        nr, nt = g.robots.shape[0], g.tasks.shape[0]
        robots[b, :nr], rmask[b, :nr] = g.robots, True
        parts["tasks"].append(g.tasks)
        parts["tgraph"].append(np.full(nt, b, np.int64))
        parts["edges"].append(g.edges + task_off)
        r, c = len(g.rows), len(g.cols)
        parts["er"].append(np.repeat(g.rows + robot_off, c))
        parts["et"].append(np.tile(g.cols + task_off, r))
        parts["eg"].append(np.full(r * c, b, np.int64))
        parts["ep"].append(g.pairs.reshape(r * c, PAIR_FEATURES))
        parts["erow"].append(np.repeat(np.arange(r) + row_off, c))
        parts["eidle"].append(np.tile(g.cols == nt - 1, r))
        robot_off, task_off, row_off = robot_off + nr, task_off + nt, row_off + r
    robot_graph = np.repeat(np.arange(bsz), rmask.sum(axis=1))

    def cat(key: str, dtype: type, shape: tuple[int, ...]) -> Tensor:
        return torch.from_numpy(np.concatenate(parts[key], axis=-1 if key == "edges" else 0).astype(dtype)) \
            if parts[key] else torch.zeros(shape)

    return Batch(torch.from_numpy(robots), torch.from_numpy(rmask), torch.from_numpy(robot_graph),
                 cat("tasks", np.float32, (0, TASK_FEATURES)), cat("tgraph", np.int64, (0,)),
                 cat("edges", np.int64, (2, 0)), cat("er", np.int64, (0,)), cat("et", np.int64, (0,)),
                 cat("eg", np.int64, (0,)), cat("ep", np.float32, (0, PAIR_FEATURES)), cat("erow", np.int64, (0,)),
                 cat("eidle", np.bool_, (0,)), row_off)


def decision_outputs(model: GATN, features: GraphFeatures) -> tuple[np.ndarray, np.ndarray | None]:
    """One forward pass for one decision step: R of Eq. 6 as a (len(rows), len(cols))
    matrix, the free robots x the ready tasks and (last column) the idle task; and each
    free robot's probability of waiting voluntarily (None without a wait head).

    Runs on INFERENCE_THREADS intra-op threads: a decision's tensors are small, and
    torch's thread pool, when the other cores are busy (a simulator, DDS, CP-SAT),
    spins: measured 100x slower (1.0 s instead of 10 ms a decision at 100 x 500)."""
    threads = torch.get_num_threads()
    torch.set_num_threads(INFERENCE_THREADS)
    try:
        with torch.inference_mode():
            r, c = len(features.rows), len(features.cols)
            rewards, wait = model.rewards_one(collate([features]), r, c)
            return (rewards.numpy().astype(np.float64),
                    None if wait is None else torch.sigmoid(wait).numpy().astype(np.float64))
    finally:
        torch.set_num_threads(threads)


def batch_decision_outputs(model: GATN, features: Sequence[GraphFeatures]
                           ) -> list[tuple[np.ndarray, np.ndarray | None]]:
    """:func:`decision_outputs` of many decision steps (of any instances and sizes) in one
    batched forward pass: each graph's (rows, cols) R and its rows' wait probabilities.
    One graph goes through :func:`decision_outputs` itself (the same numbers as LVWS)."""
    if len(features) <= 1:
        return [decision_outputs(model, f) for f in features]
    threads = torch.get_num_threads()
    torch.set_num_threads(INFERENCE_THREADS)
    try:
        with torch.inference_mode():
            r, wait = model.forward_with_wait(collate(features))
            rewards = r.numpy().astype(np.float64)
            waits = None if wait is None else torch.sigmoid(wait).numpy().astype(np.float64)
    finally:
        torch.set_num_threads(threads)
    out: list[tuple[np.ndarray, np.ndarray | None]] = []
    entry = row = 0
    for f in features:
        nr, nc = len(f.rows), len(f.cols)
        out.append((rewards[entry:entry + nr * nc].reshape(nr, nc), None if waits is None else waits[row:row + nr]))
        entry, row = entry + nr * nc, row + nr
    return out


def reward_matrix(model: GATN, features: GraphFeatures) -> np.ndarray:
    """R of :func:`decision_outputs` alone."""
    return decision_outputs(model, features)[0]
