"""Node features of the robot graph and the task DAG at a decision step (section III-A).

Robot vertex r_i = [a_i, c_i, w_i] plus what our model adds (time the robot is still
busy). Task vertex t_j = [s_j (ready, assigned, incomplete), c_j, w_j] plus what our
model adds: duration, critical-path tail (absolute and relative to the longest), share
of tasks depending on it, and an idle flag; the idle task t_{M+1} is an extra vertex
with no edges. Capability vectors are zero-padded to MAX_CAPABILITIES so one model
serves 2-3 capabilities. Site capabilities ("@cell_1", see
:data:`lvws_ros.core.problem.SITE_PREFIX`) are left out of the node features; the pair
features below see them.

Pair features (ours, for the reward MLP of Eq. 6), per robot i and task j: robot i
alone covers j (Eqs. 10-11), i holds a capability j needs, the share of j's
capabilities i holds, and i's payload relative to j's need (capped at 2).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from lvws_ros.core.executor import State
from lvws_ros.core.problem import Instance
from lvws_ros.core.subteams import covered
from lvws_ros.errors import PolicyError

MAX_CAPABILITIES = 3
PAYLOAD_SCALE = 30.0  # payloads are 1..30 in the paper's datasets
TIME_SCALE = 10.0  # durations are 1..10 s in ours
ROBOT_FEATURES = 1 + MAX_CAPABILITIES + 1 + 1
TASK_FEATURES = 3 + MAX_CAPABILITIES + 1 + 1 + 3 + 1
PAIR_FEATURES = 4
TAIL_SCALE = 50.0

F32 = npt.NDArray[np.float32]

# The dense network holds (M+1)^2 attention weights per head and layer: about
# DENSE_BYTES_PER_PAIR bytes per task pair at a decision step. Past DENSE_MEMORY_LIMIT
# the learned policies refuse the instance with a PolicyError (the CLI and the node
# then say so) instead of running out of memory: about 14,000 tasks.
DENSE_BYTES_PER_PAIR = 24
DENSE_MEMORY_LIMIT = 4 * 2**30


def check_size(inst: Instance) -> None:
    """PolicyError when the dense network would need more than DENSE_MEMORY_LIMIT."""
    need = DENSE_BYTES_PER_PAIR * ((inst.num_tasks + 1) ** 2 + inst.num_robots ** 2
                                   + inst.num_robots * (inst.num_tasks + 1) * PAIR_FEATURES)
    if need > DENSE_MEMORY_LIMIT:
        raise PolicyError(f"{inst.num_robots} robots x {inst.num_tasks} tasks need about {need / 2**30:.0f} GiB in the "
                          f"learned model (limit {DENSE_MEMORY_LIMIT / 2**30:.0f} GiB); use a baseline policy (grp)")


@dataclass(frozen=True)
class GraphFeatures:
    robots: F32  # (N, ROBOT_FEATURES)
    tasks: F32  # (M+1, TASK_FEATURES), last row: idle task
    task_adjacency: npt.NDArray[np.bool_]  # (M+1, M+1): P with the idle vertex unconnected
    pairs: F32  # (N, M+1, PAIR_FEATURES), zeros in the idle column


def _pad_caps(caps: npt.NDArray[np.bool_]) -> F32:
    k = caps.shape[1]
    if k > MAX_CAPABILITIES:
        raise PolicyError(f"the model handles at most {MAX_CAPABILITIES} skill capabilities, got {k}")
    out = np.zeros((caps.shape[0], MAX_CAPABILITIES), dtype=np.float32)
    out[:, :k] = caps
    return out


def encode_state(state: State, pairs: F32 | None = None) -> GraphFeatures:
    """Features of ``state``; ``pairs`` may pass :func:`pair_features` of the instance,
    which depend on the instance only, so a policy computes them once per run."""
    inst = state.instance
    robots = np.concatenate([
        state.robot_available().astype(np.float32)[:, None],
        _pad_caps(inst.robot_caps[:, list(inst.skill_columns)]),
        (inst.robot_payload / PAYLOAD_SCALE).astype(np.float32)[:, None],
        (state.busy_remaining() / TIME_SCALE).astype(np.float32)[:, None],
    ], axis=1)
    m = inst.num_tasks
    tasks = np.zeros((m + 1, TASK_FEATURES), dtype=np.float32)
    tasks[:m, 0:3] = state.task_state_vectors()
    tasks[:m, 3:3 + MAX_CAPABILITIES] = _pad_caps(inst.task_caps[:, list(inst.skill_columns)])
    tasks[:m, 3 + MAX_CAPABILITIES] = inst.task_payload / PAYLOAD_SCALE
    tasks[:m, 4 + MAX_CAPABILITIES] = inst.durations / TIME_SCALE
    tail = inst.critical_tail
    tasks[:m, 5 + MAX_CAPABILITIES] = tail / TAIL_SCALE
    tasks[:m, 6 + MAX_CAPABILITIES] = tail / tail.max()
    tasks[:m, 7 + MAX_CAPABILITIES] = inst.descendant_count / max(m, 1)
    tasks[m, 8 + MAX_CAPABILITIES] = 1.0  # the idle task t_{M+1}
    adjacency = np.zeros((m + 1, m + 1), dtype=bool)
    adjacency[:m, :m] = inst.precedence_matrix
    return GraphFeatures(robots, tasks, adjacency, pair_features(inst) if pairs is None else pairs)


def pair_features(inst: Instance) -> F32:
    """Static robot-task pair features (they depend on the instance only)."""
    rc = inst.robot_caps.astype(np.float32)
    tc = inst.task_caps.astype(np.float32)
    shared = rc @ tc.T  # (N, M)
    need = tc.sum(axis=1)[None, :]
    ratio = inst.robot_payload[:, None] / np.maximum(inst.task_payload[None, :], 1e-9)
    alone = covered(inst.robot_caps[:, None, :], inst.robot_payload[:, None], inst.task_caps[None, :, :],
                    inst.task_payload[None, :])  # Eqs. 10-11 for robot i alone
    out = np.zeros((inst.num_robots, inst.num_tasks + 1, PAIR_FEATURES), dtype=np.float32)
    out[:, :-1, 0] = alone
    out[:, :-1, 1] = shared > 0
    out[:, :-1, 2] = shared / need
    out[:, :-1, 3] = np.minimum(ratio, 2.0) / 2.0
    return out
