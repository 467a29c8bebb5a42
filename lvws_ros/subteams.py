"""Which robots can form a subteam for a task (the constraints of Eqs. 10-11).

A subteam covers a task when the element-wise OR of its capability vectors has every
capability the task needs (Eq. 10) and its payloads add up to the task's need (Eq. 11).
Because a task's duration does not depend on who does it, only *inclusion-minimal*
covering subteams matter: any superset only ties up more robots.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from lvws_ros.model import BoolArray, FloatArray

PAYLOAD_TOL = 1e-9
MAX_ENUMERATED = 16


def covers(caps: BoolArray, payloads: FloatArray, need_caps: BoolArray, need_payload: float) -> bool:
    """Eqs. 10-11 for the robots whose capability rows and payloads are given."""
    has = caps.any(axis=0) if len(caps) else np.zeros_like(need_caps)
    return bool(np.all(has | ~need_caps)) and float(payloads.sum()) >= need_payload - PAYLOAD_TOL


def _cap_bits(caps: BoolArray) -> npt.NDArray[np.int64]:
    return (caps.astype(np.int64) << np.arange(caps.shape[1], dtype=np.int64)).sum(axis=1)


def minimal_subteams(
    caps: BoolArray, payloads: FloatArray, need_caps: BoolArray, need_payload: float
) -> list[tuple[int, ...]]:
    """All inclusion-minimal covering subteams, as sorted index tuples into ``caps``.

    Enumerates the 2^n subsets with numpy; n is at most MAX_ENUMERATED (use
    :func:`shortlist` to pick candidates from a larger team).
    """
    n = len(caps)
    if n > MAX_ENUMERATED:
        raise ValueError(f"minimal_subteams enumerates at most {MAX_ENUMERATED} robots, got {n}")
    if n == 0:
        return []
    masks = np.arange(1 << n, dtype=np.int64)
    bits = (masks[:, None] >> np.arange(n, dtype=np.int64)) & 1  # (2^n, n)
    payload_sum = bits @ payloads
    robot_bits = _cap_bits(caps)
    cap_or = np.zeros(len(masks), dtype=np.int64)
    for i in range(n):
        cap_or |= np.where(bits[:, i] == 1, robot_bits[i], 0)
    need = int(_cap_bits(need_caps[None, :])[0])
    feasible = ((cap_or & need) == need) & (payload_sum >= need_payload - PAYLOAD_TOL)
    minimal = feasible.copy()
    for i in range(n):
        has_i = bits[:, i] == 1
        minimal[has_i] &= ~feasible[masks[has_i] ^ (1 << i)]
    return [tuple(int(i) for i in np.flatnonzero(bits[m])) for m in np.flatnonzero(minimal)]


def shortlist(caps: BoolArray, payloads: FloatArray, need_caps: BoolArray, limit: int = MAX_ENUMERATED) -> list[int]:
    """Up to ``limit`` candidate robots for a task from a larger team.

    Keeps the robots holding the most needed capabilities, then the largest payloads;
    used by the baselines when more than MAX_ENUMERATED robots are free.
    """
    useful = caps[:, need_caps].sum(axis=1) if need_caps.any() else np.zeros(len(caps))
    order = np.lexsort((-payloads, -useful))
    return sorted(int(i) for i in order[:limit])


def team_candidates(
    caps: BoolArray, payloads: FloatArray, need_caps: BoolArray, need_payload: float
) -> list[tuple[int, ...]]:
    """Minimal covering subteams among the given robots (shortlisted when many)."""
    if len(caps) <= MAX_ENUMERATED:
        return minimal_subteams(caps, payloads, need_caps, need_payload)
    keep = shortlist(caps, payloads, need_caps)
    teams = minimal_subteams(caps[keep], payloads[keep], need_caps, need_payload)
    return [tuple(keep[i] for i in team) for team in teams]
