"""The imitation loss of Eq. 12 and the expert targets it compares with.

A :class:`Demo` is one decision step: its graph features, E (expert rewards, labelled
by :mod:`lvws_ros.learning.demonstrations`) and X (the feasibility mask), both over
the entries a decision reads: the free robots x the ready tasks and the idle task
(``features.rows`` x ``features.cols``). Entries no decision reads (busy robots, tasks
not ready) are left out of Eq. 12: the policy never looks at them (ours; the paper sums
over all N x (M+1) entries).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import torch
from torch import Tensor

from lvws_ros.core.subteams import AmountArray, FloatArray, helps
from lvws_ros.learning.features import GraphFeatures
from lvws_ros.learning.gatn import NEG, Batch, collate, segment_softmax

__all__ = ["Demo", "Targets", "batch_tensors", "feasibility_mask", "imitation_loss", "wait_targets"]


@dataclass(frozen=True)
class Demo:
    features: GraphFeatures
    expert: npt.NDArray[np.float32]  # E, (R, C)
    mask: npt.NDArray[np.bool_]  # X, (R, C)


@dataclass
class Targets:
    e: Tensor  # (entries,)
    x: Tensor  # (entries,) 0/1
    valid: Tensor  # (entries,) 0/1: entries in the loss (all but idle ones for DBGM)
    choice: Tensor  # (rows,) flat entry index of each row's expert choice
    choice_valid: Tensor  # (rows,) bool: the row has an expert choice among its entries in the loss
    wait: Tensor  # (rows,) 0/1: the expert waits voluntarily with this robot (see wait_targets)
    wait_valid: Tensor  # (rows,) bool: rows in the wait head's term (see wait_targets)

    def to(self, device: torch.device | str) -> Targets:
        """The targets on ``device``."""
        return Targets(**{k: v.to(device) for k, v in self.__dict__.items()})


def feasibility_mask(robot_caps: AmountArray, task_caps: AmountArray, robot_payload: FloatArray,
                     task_payload: FloatArray) -> npt.NDArray[np.bool_]:
    """X of Eq. 12: robot i can help task j (has a needed capability, or the task needs
    payload); the idle column (last) is always feasible."""
    return np.concatenate([helps(robot_caps, task_caps, task_payload), np.ones((len(robot_caps), 1), dtype=bool)],
                          axis=1)


def wait_targets(demo: Demo) -> tuple[npt.NDArray[np.bool_], npt.NDArray[np.bool_]]:
    """(wait, valid) of each row of one demonstration, for the wait head (ours). The expert
    waits voluntarily with robot i when it keeps i waiting although a ready task that i
    covers alone (Eqs. 10-11; pair feature 0) is left unstarted at this step. Rows in the
    term: those robots, and every robot the expert puts to work; not the ones it leaves
    waiting for want of a task they could start alone (the matching never starts those)."""
    e, mask = demo.expert, demo.mask
    scored = np.where(mask, e, -1.0)
    chosen = scored.max(axis=1, initial=-1.0) > 0
    idle = scored.argmax(axis=1) == e.shape[1] - 1
    unstarted = np.logical_not((e[:, :-1] > 0).any(axis=0))
    alone = demo.features.pairs[:, :-1, 0] > 0
    wait = chosen & idle & (mask[:, :-1] & alone & unstarted[None, :]).any(axis=1)
    return wait, wait | (chosen & ~idle)


def batch_tensors(demos: Sequence[Demo], use_idle: bool = True) -> tuple[Batch, Targets]:
    """Collated graphs with E, X, the entries in the loss, and each row's expert choice
    (the argmax of E over the row's feasible entries, used by the choice term)."""
    batch = collate([d.features for d in demos])
    e = np.concatenate([d.expert.reshape(-1) for d in demos]).astype(np.float32)
    x = np.concatenate([d.mask.reshape(-1) for d in demos]).astype(np.float32)
    valid = np.ones_like(x) if use_idle else (~batch.entry_idle.numpy()).astype(np.float32)
    x *= valid
    choice = np.zeros(batch.rows, np.int64)
    has_choice = np.zeros(batch.rows, bool)
    waits = np.zeros(batch.rows, np.float32)
    wait_valid = np.zeros(batch.rows, bool)
    start = row = 0
    for d in demos:
        r, c = d.expert.shape
        scored = np.where(d.mask.reshape(r, c) & (valid[start:start + r * c].reshape(r, c) > 0), d.expert, -1.0)
        choice[row:row + r] = start + np.arange(r) * c + scored.argmax(axis=1)
        # a row has a choice only where the expert's pick is an entry in the loss (not so
        # for a robot the expert keeps waiting when the idle column is left out: DBGM)
        has_choice[row:row + r] = scored.max(axis=1, initial=-1.0) > 0
        if use_idle:
            waits[row:row + r], wait_valid[row:row + r] = wait_targets(d)
        start, row = start + r * c, row + r
    return batch, Targets(torch.from_numpy(e), torch.from_numpy(x), torch.from_numpy(valid), torch.from_numpy(choice),
                          torch.from_numpy(has_choice), torch.from_numpy(waits), torch.from_numpy(wait_valid))


def imitation_loss(r: Tensor, t: Targets, rows: Tensor, lam: float, choice_weight: float = 0.0,
                   temperature: float = 0.1, wait_logits: Tensor | None = None, wait_weight: float = 0.0,
                   wait_pos_weight: float = 1.0) -> Tensor:
    """Eq. 12: ||(R - E) o X||_1 + lambda ||R - E||_1, averaged over the entries in the
    loss so that batches of different sizes weigh alike. ``rows`` is each entry's row.

    With ``choice_weight`` > 0 (our addition, beyond the paper) a per-robot choice term
    is added: for each robot whose expert choice is an entry in the loss, the cross
    entropy of softmax(R / temperature) over its feasible entries against that choice. Eq. 12 alone regresses a sparse E
    under L1 norms, whose minimiser is close to 0 everywhere; the choice term keeps the
    ranking that the greedy matching reads.

    With ``wait_logits`` (the wait head, ours) and ``wait_weight`` > 0, the binary cross
    entropy of the rows :func:`wait_targets` selects (the expert's voluntary waits and the
    robots it puts to work) against the expert waiting, the waits weighted by
    ``wait_pos_weight`` (class balance: they are rare).
    """
    diff = (r - t.e).abs() * t.valid
    count = t.valid.sum().clamp(min=1)
    loss = (diff * t.x).sum() / count + lam * diff.sum() / count
    if choice_weight > 0 and bool(t.choice_valid.any()):
        logits = (r / temperature).masked_fill(t.x <= 0, NEG)[:, None]
        p = segment_softmax(logits, rows, len(t.choice))[:, 0]
        loss = loss - choice_weight * torch.log(p[t.choice[t.choice_valid]].clamp(min=1e-12)).mean()
    if wait_logits is not None and wait_weight > 0 and bool(t.wait_valid.any()):
        loss = loss + wait_weight * torch.nn.functional.binary_cross_entropy_with_logits(
            wait_logits[t.wait_valid], t.wait[t.wait_valid], pos_weight=torch.tensor(wait_pos_weight))
    return loss
