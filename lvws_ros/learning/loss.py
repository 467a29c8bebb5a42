"""The imitation loss of Eq. 12 and the expert targets it compares with.

A :class:`Demo` is one decision step: its graph features, E (expert rewards, labelled
by :mod:`lvws_ros.learning.demonstrations`) and X (the feasibility mask). They are
padded here alike with the network's output, so Eq. 12 sees R, E and X of one shape.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import torch
from torch import Tensor, nn

from lvws_ros.core.subteams import BoolArray, FloatArray, helps
from lvws_ros.learning.features import GraphFeatures
from lvws_ros.learning.gatn import NEG, Batch, collate

__all__ = ["Demo", "batch_tensors", "feasibility_mask", "imitation_loss"]


@dataclass(frozen=True)
class Demo:
    features: GraphFeatures
    expert: npt.NDArray[np.float32]  # E, (N, M+1)
    mask: npt.NDArray[np.bool_]  # X, (N, M+1)


def feasibility_mask(robot_caps: BoolArray, task_caps: BoolArray, robot_payload: FloatArray,
                     task_payload: FloatArray) -> npt.NDArray[np.bool_]:
    """X of Eq. 12 at one step: robot i can help task j (has a needed capability, or
    the task needs payload); the idle column is always feasible."""
    return np.concatenate([helps(robot_caps, task_caps, task_payload), np.ones((len(robot_caps), 1), dtype=bool)],
                          axis=1)


def batch_tensors(demos: Sequence[Demo], use_idle: bool = True) -> tuple[Batch, Tensor, Tensor, Tensor]:
    """Collated graphs with E, X and the mask of real entries, padded alike."""
    batch = collate([d.features for d in demos])
    shape = batch.reward_mask().shape
    e = np.zeros(shape, np.float32)
    x = np.zeros(shape, np.float32)
    for k, d in enumerate(demos):
        n, m1 = d.expert.shape
        e[k, :n, :m1] = d.expert
        x[k, :n, :m1] = d.mask
    valid = batch.reward_mask().float()
    if not use_idle:
        cols = torch.arange(shape[2])[None, None, :]
        valid = valid * (cols != batch.idle_index[:, None, None]).float()
    return batch, torch.from_numpy(e), torch.from_numpy(x) * valid, valid


def imitation_loss(r: Tensor, e: Tensor, x: Tensor, valid: Tensor, lam: float,
                   choice_weight: float = 0.0, temperature: float = 0.1) -> Tensor:
    """Eq. 12: ||(R - E) o X||_1 + lambda ||R - E||_1, averaged over the real entries
    (``valid``) so that batches of different sizes weigh alike.

    With ``choice_weight`` > 0 (our addition, beyond the paper) a per-robot choice term
    is added: for each robot with feasible options (a row of X with a 1), the cross
    entropy of softmax(R / temperature) over those options against the expert's choice
    (the argmax of E in the row). Eq. 12 alone regresses a sparse E under L1 norms, whose
    minimiser is close to 0 everywhere; the choice term keeps the ranking that the
    greedy matching reads.
    """
    diff = (r - e).abs() * valid
    count = valid.sum().clamp(min=1)
    loss = (diff * x).sum() / count + lam * diff.sum() / count
    if choice_weight > 0:
        rows = x.sum(-1) > 0
        if rows.any():
            logits = (r / temperature).masked_fill(x <= 0, NEG)
            target = torch.where(x > 0, e, torch.full_like(e, -1.0)).argmax(-1)
            ce = nn.functional.cross_entropy(logits[rows], target[rows])
            loss = loss + choice_weight * ce
    return loss
