"""Subteam coverage (the constraints of Eqs. 10-11): the one coverage test and the one
tolerance of lvws_ros.

A subteam covers a task when the element-wise OR of its capability vectors has every
capability the task needs (Eq. 10) and its payloads add up to the task's need (Eq. 11).
Because a task's duration does not depend on who does it, only *inclusion-minimal*
covering subteams matter: any superset only ties up more robots.

Every other module (matching, the exact expert, the baselines, schedule checking,
instance validation, the network's pair features) asks :func:`shortfall`,
:func:`covered` or :func:`covers`; none of them writes the test again.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

__all__ = [
    "MAX_ENUMERATED",
    "TOLERANCE",
    "BoolArray",
    "FloatArray",
    "covered",
    "covers",
    "helps",
    "minimal_subteams",
    "shortfall",
    "shortlist",
    "team_candidates",
]

BoolArray = npt.NDArray[np.bool_]
FloatArray = npt.NDArray[np.float64]

# The one tolerance: payload sums and times within it count as equal (formats.md
# compares times with 1e-6).
TOLERANCE = 1e-6
MAX_ENUMERATED = 16


def shortfall(team_caps: npt.ArrayLike, team_payload: npt.ArrayLike, need_caps: npt.ArrayLike,
              need_payload: npt.ArrayLike) -> tuple[BoolArray, FloatArray]:
    """What a subteam lacks for a task, broadcast over leading axes.

    ``team_caps`` (..., K) is the OR of the members' capability vectors and
    ``team_payload`` (...) the sum of their payloads; ``need_caps`` (..., K) and
    ``need_payload`` (...) are the task's. Returns the capabilities still missing
    (..., K) (Eq. 10) and the payload still missing (...), 0 when met within
    TOLERANCE (Eq. 11).
    """
    missing = np.asarray(need_caps, dtype=bool) & ~np.asarray(team_caps, dtype=bool)
    short = np.asarray(need_payload, dtype=np.float64) - np.asarray(team_payload, dtype=np.float64)
    return missing, np.where(short > TOLERANCE, short, 0.0)


def covered(team_caps: npt.ArrayLike, team_payload: npt.ArrayLike, need_caps: npt.ArrayLike,
            need_payload: npt.ArrayLike) -> BoolArray:
    """Eqs. 10-11, broadcast like :func:`shortfall`: True where nothing is missing."""
    missing, short = shortfall(team_caps, team_payload, need_caps, need_payload)
    return np.asarray(~missing.any(axis=-1) & (short == 0.0))


def covers(caps: BoolArray, payloads: FloatArray, need_caps: BoolArray, need_payload: float) -> bool:
    """Eqs. 10-11 for the robots whose capability rows (n, K) and payloads (n,) are given."""
    return bool(covered(caps.any(axis=0), payloads.sum(), need_caps, need_payload))


def helps(robot_caps: BoolArray, need_caps: BoolArray, need_payload: FloatArray) -> BoolArray:
    """(n, m): robot i can contribute to task j, i.e. holds a capability j still needs,
    or j still needs payload (any robot carries some)."""
    shared = robot_caps.astype(np.int32) @ need_caps.T.astype(np.int32) > 0
    return np.asarray(shared | (np.asarray(need_payload) > TOLERANCE)[None, :])


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
    bits = ((masks[:, None] >> np.arange(n, dtype=np.int64)) & 1).astype(bool)  # (2^n, n)
    cap_or = bits.astype(np.int32) @ caps.astype(np.int32) > 0  # (2^n, K)
    feasible = covered(cap_or, bits @ payloads, need_caps, need_payload)
    minimal = feasible.copy()
    for i in range(n):
        has_i = bits[:, i]
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
