"""Node features of the robot graph and the task DAG at a decision step (section III-A).

Robot vertex r_i = [a_i, c_i, w_i] plus what our model adds (time the robot is still
busy). Task vertex t_j = [s_j (ready, assigned, incomplete), c_j, w_j] plus duration
and an idle flag; the idle task t_{M+1} is an extra vertex with no edges. Capability
vectors are zero-padded to MAX_CAPABILITIES so one model serves 2-3 capabilities.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from lvws_ros.executor import State

MAX_CAPABILITIES = 3
PAYLOAD_SCALE = 30.0  # payloads are 1..30 in the paper's datasets
TIME_SCALE = 10.0  # durations are 1..10 s in ours
ROBOT_FEATURES = 1 + MAX_CAPABILITIES + 1 + 1
TASK_FEATURES = 3 + MAX_CAPABILITIES + 1 + 1 + 1

F32 = npt.NDArray[np.float32]


@dataclass(frozen=True)
class GraphFeatures:
    robots: F32  # (N, ROBOT_FEATURES)
    tasks: F32  # (M+1, TASK_FEATURES), last row: idle task
    task_adjacency: npt.NDArray[np.bool_]  # (M+1, M+1): P with the idle vertex unconnected


def _pad_caps(caps: npt.NDArray[np.bool_]) -> F32:
    k = caps.shape[1]
    if k > MAX_CAPABILITIES:
        raise ValueError(f"the model handles at most {MAX_CAPABILITIES} capabilities, got {k}")
    out = np.zeros((caps.shape[0], MAX_CAPABILITIES), dtype=np.float32)
    out[:, :k] = caps
    return out


def encode_state(state: State) -> GraphFeatures:
    inst = state.instance
    robots = np.concatenate([
        state.robot_available().astype(np.float32)[:, None],
        _pad_caps(inst.robot_caps),
        (inst.robot_payload / PAYLOAD_SCALE).astype(np.float32)[:, None],
        (state.busy_remaining() / TIME_SCALE).astype(np.float32)[:, None],
    ], axis=1)
    m = inst.num_tasks
    tasks = np.zeros((m + 1, TASK_FEATURES), dtype=np.float32)
    tasks[:m, 0:3] = state.task_state_vectors()
    tasks[:m, 3:3 + MAX_CAPABILITIES] = _pad_caps(inst.task_caps)
    tasks[:m, 3 + MAX_CAPABILITIES] = inst.task_payload / PAYLOAD_SCALE
    tasks[:m, 4 + MAX_CAPABILITIES] = inst.durations / TIME_SCALE
    tasks[m, 5 + MAX_CAPABILITIES] = 1.0  # the idle task t_{M+1}
    adjacency = np.zeros((m + 1, m + 1), dtype=bool)
    adjacency[:m, :m] = inst.precedence_matrix
    return GraphFeatures(robots, tasks, adjacency)
