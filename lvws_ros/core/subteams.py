"""Subteam coverage (the constraints of Eqs. 10-11, generalised to additive traits): the
one coverage test and the one tolerance of lvws_ros.

The rule: robots bring *amounts* of traits and tasks *require* amounts; a subteam covers a
task when, for every trait, its members' amounts add up to the requirement, and its
payloads add up to the task's payload (Eq. 11). The paper's model is the special case
where each capability is a trait of amount 0 or 1 required 0 or 1 times: a sum of 0/1
amounts reaches 1 exactly when their OR is 1 (Eq. 10). So the "capability" arrays below
hold amounts (booleans are amounts of 0 and 1) and the "team" arrays their sums.

With *roles* (the multi-skill project scheduling rule) each member counts toward one
required trait only: the subteam covers when its members can be assigned to the traits
(each to at most one) so that every trait's assigned amounts add up (:func:`role_cover`).

Because a task's duration does not depend on who does it, only *inclusion-minimal*
covering subteams matter: any superset only ties up more robots.

Every other module (matching, the exact expert, the baselines, schedule checking,
instance validation, the network's pair features) asks :func:`shortfall`,
:func:`covered` or :func:`covers`; none of them writes the test again.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

__all__ = [
    "COVER_CHUNK",
    "MAX_ENUMERATED",
    "TOLERANCE",
    "AmountArray",
    "BoolArray",
    "CoverPool",
    "FloatArray",
    "covered",
    "covers",
    "covers_alone",
    "earliest_cover",
    "fewest_carriers",
    "helps",
    "minimal_subteams",
    "role_cover",
    "role_shortfall",
    "shortfall",
    "shortlist",
    "team_candidates",
    "whole_numbers",
]

BoolArray = npt.NDArray[np.bool_]
FloatArray = npt.NDArray[np.float64]
AmountArray = npt.NDArray[Any]  # trait amounts: float, or bool for 0/1 capabilities
IntArray = npt.NDArray[np.int64]

# The one tolerance: payload sums and times within it count as equal (formats.md
# compares times with 1e-6).
TOLERANCE = 1e-6
MAX_ENUMERATED = 16  # minimal_subteams (the exact expert's coalition model, tests) lists subsets of at most this
SEED_EVERY_HOLDER = 8  # lightest_cover seeds with every capability holder up to this many candidates
MASK_BITS = 62  # lightest_cover takes capabilities as the bits of an int64 up to this many, else arrays


def shortfall(team_caps: npt.ArrayLike, team_payload: npt.ArrayLike, need_caps: npt.ArrayLike,
              need_payload: npt.ArrayLike) -> tuple[FloatArray, FloatArray]:
    """What a subteam lacks for a task, broadcast over leading axes.

    ``team_caps`` (..., K) is the sum of the members' amounts (for 0/1 capabilities their
    OR gives the same answer) and ``team_payload`` (...) the sum of their payloads;
    ``need_caps`` (..., K) and ``need_payload`` (...) are the task's. Returns the amount
    of each trait still missing (..., K) (Eq. 10: a missing capability is 1) and the
    payload still missing (...), 0 where met within TOLERANCE (Eq. 11).
    """
    missing = np.asarray(need_caps, dtype=np.float64) - np.asarray(team_caps, dtype=np.float64)
    short = np.asarray(need_payload, dtype=np.float64) - np.asarray(team_payload, dtype=np.float64)
    # NaN stays NaN: not covered
    return np.where(missing <= TOLERANCE, 0.0, missing), np.where(short <= TOLERANCE, 0.0, short)


def covered(team_caps: npt.ArrayLike, team_payload: npt.ArrayLike, need_caps: npt.ArrayLike,
            need_payload: npt.ArrayLike) -> BoolArray:
    """Eqs. 10-11, broadcast like :func:`shortfall`: True where nothing is missing (without
    roles; with roles this is a necessary condition, :func:`covers` the rule)."""
    # shortfall's comparisons, without building what is missing (NaN: not covered)
    missing = np.asarray(need_caps, dtype=np.float64) - np.asarray(team_caps, dtype=np.float64)
    short = np.asarray(need_payload, dtype=np.float64) - np.asarray(team_payload, dtype=np.float64)
    return np.asarray((missing <= TOLERANCE).all(axis=-1) & (short <= TOLERANCE))


def covers(caps: npt.ArrayLike, payloads: FloatArray, need_caps: npt.ArrayLike, need_payload: float,
           roles: bool = False) -> bool:
    """The coverage rule for the robots whose amount rows (n, K) and payloads (n,) are
    given: sums reach the needs (Eqs. 10-11); with ``roles``, by members that each count
    toward one trait (:func:`role_cover`)."""
    caps = np.asarray(caps, dtype=np.float64)
    if not covered(caps.sum(axis=0), payloads.sum(), need_caps, need_payload):
        return False
    return not roles or role_cover(caps, need_caps)


def covers_alone(caps: npt.ArrayLike, payloads: npt.ArrayLike, need_caps: npt.ArrayLike, need_payload: npt.ArrayLike,
                 roles: npt.ArrayLike = False) -> BoolArray:
    """The rule for one robot alone, broadcast like :func:`covered` (a robot's amounts are
    its sums): with ``roles`` a robot fills one trait, so it covers only a task needing at
    most one."""
    one_trait = (np.asarray(need_caps) > TOLERANCE).sum(axis=-1) <= 1
    return np.asarray(covered(caps, payloads, need_caps, need_payload) & (~np.asarray(roles, dtype=bool) | one_trait))


def role_cover(caps: npt.ArrayLike, need_caps: npt.ArrayLike) -> bool:
    """Whether the members (amount rows (n, K)) can each be given at most one of the
    required traits so that every trait's given amounts add up to its need: the
    multi-skill project scheduling rule (a worker fills one skill slot of an activity).
    A depth-first search over the members (the most constrained first, the largest
    contribution tried first), pruned by what the members left can still bring to each
    trait and in all (each fills one slot: at most its largest useful amount), by the
    remaining needs already seen, and by symmetry (identical members take traits in
    order). Exponential in the worst case (with general amounts the problem is NP-hard),
    fast for subteams of tens of robots."""
    caps = np.atleast_2d(np.asarray(caps, dtype=np.float64))
    need_all = np.asarray(need_caps, dtype=np.float64)
    if len(caps) <= SMALL_ROLE_TEAM:
        return _role_cover_small_memo(caps.tolist(), need_all.tolist())
    cols = np.flatnonzero(need_all > TOLERANCE)
    a, need = caps[:, cols], need_all[cols]
    a = a[(a > 0).any(axis=1)]
    if not len(need):
        return True
    if len(a) <= SMALL_ROLE_TEAM:
        return _role_cover_small_memo(a.tolist(), need.tolist())
    if _role_cover_greedy(a, need):  # an assignment found at once: no search needed
        return True
    a = a[np.lexsort((*a.T[::-1], (a > 0).sum(axis=1)))]  # fewest traits first; identical rows adjacent
    n, k_all = a.shape
    same = np.zeros(n, dtype=bool)
    same[1:] = (a[1:] == a[:-1]).all(axis=1)
    rest = np.vstack([np.cumsum(a[::-1], axis=0)[::-1], np.zeros((1, k_all))])  # what rows i.. bring
    seen: set[tuple[int, bytes, int]] = set()
    stack = [(0, need, 0)]  # (member, what is left, the choice of the member before when identical)
    while stack:
        i, left, floor = stack.pop()
        if (left <= TOLERANCE).all():
            return True
        want = np.maximum(left, 0.0)
        if i == n or (rest[i] < left - TOLERANCE).any() or \
                np.minimum(a[i:], want[None, :]).max(axis=1).sum() < want.sum() - TOLERANCE:
            continue
        key = (i, np.round(want, 9).tobytes(), floor if same[i] else -1)
        if key in seen:
            continue
        seen.add(key)
        low = floor if same[i] else 0
        nxt_same = i + 1 < n and same[i + 1]
        stack.append((i + 1, left, k_all if nxt_same else 0))  # this member fills no slot (tried last)
        useful = [k for k in np.flatnonzero((a[i] > 0) & (left > TOLERANCE)) if k >= low]
        for k in sorted(useful, key=lambda c: (min(a[i, c], left[c]), -c)):
            nxt = left.copy()
            nxt[k] -= a[i, k]
            stack.append((i + 1, nxt, int(k)))  # the largest contribution (then the first trait) is popped first
    return False


SMALL_ROLE_TEAM = 12  # role_cover: up to this many members, a search in plain Python (no array per node)
ROLE_MEMO_SIZE = 1 << 14  # role_cover: answers kept for small teams (then forgotten all at once; about 12 MB)
_role_memo: dict[tuple[tuple[tuple[float, ...], ...], tuple[float, ...]], bool] = {}


def _role_cover_small_memo(a: list[list[float]], need: list[float]) -> bool:
    """:func:`role_cover` for a few members (rows ``a`` over all traits) by
    :func:`_role_cover_small` on the needed traits and the members holding one, its answer
    kept for the same such members (in any order) and needs: GRP asks again about the
    teams it grows and trims, task after task."""
    cols = [c for c, w in enumerate(need) if w > TOLERANCE]
    rows = [[row[c] for c in cols] for row in a if any(row[c] > 0 for c in cols)]
    key = (tuple(sorted(map(tuple, rows))), tuple(need[c] for c in cols))
    got = _role_memo.get(key)
    if got is None:
        if len(_role_memo) >= ROLE_MEMO_SIZE:
            _role_memo.clear()
        got = _role_memo[key] = not cols or _role_cover_small(rows, list(key[1]))
    return got


def _role_cover_greedy(a: FloatArray, need: FloatArray) -> bool:
    """A sufficient test for :func:`role_cover`: the traits in turn, the largest need
    first, each filled by the members not yet given one with the most of it (True: every
    trait filled so, an assignment that proves the cover; False says nothing)."""
    free = np.ones(len(a), dtype=bool)
    for c in np.argsort(-need, kind="stable"):
        have = np.where(free, a[:, c], 0.0)
        order = np.argsort(-have, kind="stable")
        got = np.cumsum(have[order])
        enough = int(np.searchsorted(got, need[c] - TOLERANCE))
        if enough >= len(order) or have[order[enough]] <= 0:
            return False
        free[order[:enough + 1]] = False
    return True


def _role_cover_small(a: list[list[float]], need: list[float]) -> bool:
    """:func:`role_cover` for a few members (rows ``a``, the needed traits only): the same
    depth-first search in plain floats, pruned by what the members left can bring to each
    trait and by their number (one per trait still short), memoised on (member, what is
    left)."""
    n, k = len(a), len(need)
    if n < k:  # every needed trait takes a member of its own
        return False
    rest = [[0.0] * k for _ in range(n + 1)]  # what members i.. bring to each trait
    for i in range(n - 1, -1, -1):
        rest[i] = [rest[i + 1][c] + a[i][c] for c in range(k)]
    seen: set[tuple[int, tuple[float, ...]]] = set()

    def search(i: int, left: tuple[float, ...]) -> bool:
        if all(x <= TOLERANCE for x in left):
            return True
        if i == n or any(left[c] > rest[i][c] + TOLERANCE for c in range(k)) or \
                sum(x > TOLERANCE for x in left) > n - i:  # a member per trait still short
            return False
        key = (i, tuple(round(x, 9) for x in left))
        if key in seen:
            return False
        seen.add(key)
        row = a[i]
        useful = sorted((c for c in range(k) if row[c] > 0 and left[c] > TOLERANCE),
                        key=lambda c: (-min(row[c], left[c]), c))  # the largest contribution first
        for c in useful:
            if search(i + 1, (*left[:c], left[c] - row[c], *left[c + 1:])):
                return True
        return search(i + 1, left)  # this member fills no slot

    if sum(max(min(x, w) for x, w in zip(row, need, strict=True)) for row in a) < sum(need) - TOLERANCE:
        return False  # each member fills one slot: even their largest useful amounts fall short
    return search(0, tuple(need))


def role_shortfall(caps: npt.ArrayLike, need_caps: npt.ArrayLike) -> FloatArray:
    """(K,): what the members still lack with roles: zero when :func:`role_cover` holds,
    else what is left after giving each member, in turn, the trait it fills most of."""
    need = np.asarray(need_caps, dtype=np.float64)
    caps = np.atleast_2d(np.asarray(caps, dtype=np.float64))
    if role_cover(caps, need):
        return np.zeros_like(need)
    left = need.copy()
    for row in caps:
        gain = np.minimum(row, np.maximum(left, 0.0))
        if gain.max() > TOLERANCE:
            k = int(np.argmax(gain))
            left[k] -= row[k]
    return np.where(left <= TOLERANCE, 0.0, left)  # not all zero: that would be a role cover


COVER_CHUNK = 1 << 22  # earliest_cover: robots x tasks x max(capabilities, 8) per chunk of tasks


def earliest_cover(times: FloatArray, caps: AmountArray, payloads: FloatArray, need_caps: AmountArray,
                   need_payload: FloatArray) -> FloatArray:
    """(m,): for each task j the least t at which the robots with ``times[:, j] <= t``
    together cover it (Eqs. 10-11, without roles: a lower bound with them), inf when all
    those with a finite time do not.
    ``times`` (n, m) (inf: never), ``caps`` (n, K), ``payloads`` (n,), ``need_caps``
    (m, K), ``need_payload`` (m,). O(n log n + n K) per task, in chunks of tasks."""
    n, m = times.shape
    out = np.full(m, np.inf)
    if n == 0:
        return out
    step = max(1, COVER_CHUNK // (n * max(caps.shape[1], 8)))  # the (n, c) float arrays count too
    for lo in range(0, m, step):
        cols = slice(lo, min(m, lo + step))
        order = np.argsort(times[:, cols], axis=0, kind="stable")  # (n, c): soonest first
        soon = np.take_along_axis(times[:, cols], order, axis=0)
        have = np.cumsum(caps[order], axis=0, dtype=np.float64)  # (n, c, K): the first k robots' amounts
        load = np.cumsum(payloads[order], axis=0)
        ok = covered(have, load, need_caps[None, cols], need_payload[None, cols]) & np.isfinite(soon)
        first = ok.argmax(axis=0)
        out[cols] = np.where(ok.any(axis=0), soon[first, np.arange(soon.shape[1])], np.inf)
    return out


def fewest_carriers(robot_payload: FloatArray, need_payload: FloatArray) -> IntArray:
    """(m,): the fewest robots whose payloads add up to each need (Eq. 11): the heaviest
    first; one more than the team when even all of them fall short."""
    ordered = np.sort(np.asarray(robot_payload, dtype=np.float64))[::-1].cumsum()
    return np.searchsorted(ordered, np.asarray(need_payload, dtype=np.float64) - TOLERANCE).astype(np.int64) + 1


def helps(robot_caps: AmountArray, need_caps: AmountArray, need_payload: FloatArray) -> BoolArray:
    """(n, m): robot i can contribute to task j, i.e. holds a trait (capability) j still
    needs, or j still needs payload (any robot carries some)."""
    shared = (np.asarray(robot_caps) > 0).astype(np.int32) @ (np.asarray(need_caps) > TOLERANCE).T.astype(np.int32) > 0
    return np.asarray(shared | (np.asarray(need_payload) > TOLERANCE)[None, :])


def prune(team: list[int], caps: AmountArray, payloads: FloatArray, need_caps: AmountArray, need_payload: float,
          keep: int | None = None, roles: bool = False) -> list[int]:
    """Drop members while the rest still covers, in ``team``'s order (``keep`` never):
    the result covers and, but for ``keep``, is inclusion-minimal. O(t^2 K) for t members."""
    out = list(team)
    for q in list(team):
        if q == keep or len(out) == 1:
            continue
        rest = [x for x in out if x != q]
        if covers(caps[rest], payloads[rest], need_caps, need_payload, roles):
            out = rest
    return out


def _gain(caps: FloatArray, missing: FloatArray, need: FloatArray) -> FloatArray:
    """(n,): how much of what is missing each robot brings, each trait as a share of its
    need (for 0/1 capabilities: how many missing capabilities it holds)."""
    share = np.minimum(caps, missing[None, :]) / np.where(need > TOLERANCE, need, 1.0)[None, :]
    return np.asarray(share.sum(axis=1), dtype=np.float64)


def grow(caps: AmountArray, payloads: FloatArray, need_caps: AmountArray, need_payload: float,
         start: Sequence[int] = (), order: IntArray | None = None, fill: str = "single",
         roles: bool = False) -> list[int] | None:
    """Add robots to ``start`` until the team covers the task, or None when all of them
    cannot (Eqs. 10-11). Traits (capabilities) first: the robot bringing the most of what
    is missing (:func:`_gain`), the first in ``order`` (default: lightest payload first)
    on ties; then payload, with ``fill`` "single": the lightest robot that fills what is
    missing alone, else the heaviest one; "ascending": the lightest robots first. With
    ``roles``, what the members lack once each counts toward one trait is filled the same
    way. O(n t K)."""
    team = _grow_traits(caps, payloads, need_caps, start, order, roles)
    return None if team is None else _fill_payload(payloads, need_caps, need_payload, team, fill)


def _grow_traits(caps: AmountArray, payloads: FloatArray, need_caps: AmountArray, start: Sequence[int],
                 order: IntArray | None, roles: bool) -> list[int] | None:
    """:func:`grow`'s first part: ``start`` and the robots added until the traits
    (capabilities) are covered, or None when all of them cannot cover them."""
    n = len(caps)
    rank = np.empty(n, dtype=np.int64)
    rank[np.argsort(payloads, kind="stable") if order is None else order] = np.arange(n)
    team = list(start)
    used = np.zeros(n, dtype=bool)
    used[team] = True
    amounts = np.asarray(caps, dtype=np.float64)
    need = np.asarray(need_caps, dtype=np.float64)

    def lacking() -> FloatArray:
        missing = shortfall(amounts[team].sum(axis=0), 0.0, need, 0.0)[0]
        if roles and not missing.any() and team:
            return role_shortfall(amounts[team], need)
        return missing

    missing = lacking()
    while missing.any():
        gain = np.where(used, -1.0, _gain(amounts, missing, need))
        best = float(gain.max())
        if best <= 0 and roles:  # what the members lack may come from a new assignment: every helper joins
            team += [int(i) for i in np.flatnonzero(~used & helps(amounts, need[None, :], np.zeros(1))[:, 0])]
            used[team] = True
            return None if lacking().any() else team
        if best <= 0:
            return None
        tie = gain == best
        pick = int(np.flatnonzero(tie)[np.argmin(rank[tie])])
        team.append(pick)
        used[pick] = True
        missing = lacking()
    return team


def _fill_payload(payloads: FloatArray, need_caps: AmountArray, need_payload: float, start: list[int],
                  fill: str) -> list[int] | None:
    """:func:`grow`'s second part: robots added to ``start`` (a team covering the
    traits) by ``fill`` until the payloads add up, or None when all of them fall short."""
    team = list(start)
    short = float(shortfall(need_caps, payloads[team].sum(), need_caps, need_payload)[1])
    if not short > 0:  # the payloads add up already
        return team
    if fill == "ascending":
        return _fill_ascending(payloads, need_payload, start)
    used = np.zeros(len(payloads), dtype=bool)
    used[team] = True
    while short > 0:
        if used.all():
            return None
        fills = ~used & (payloads >= short - TOLERANCE)
        pool = np.flatnonzero(fills) if fills.any() and fill == "single" else np.flatnonzero(~used)
        pick = int(pool[np.argmin(payloads[pool])] if fills.any() else pool[np.argmax(payloads[pool])])
        team.append(pick)
        used[pick] = True
        short = float(shortfall(need_caps, payloads[team].sum(), need_caps, need_payload)[1])
    return team


FILL_BLOCK = 8  # _fill_ascending: team sizes tried at once


def _fill_ascending(payloads: FloatArray, need_payload: float, start: list[int]) -> list[int] | None:
    """:func:`grow`'s "ascending" payload fill: the robots not in ``start``, lightest
    first (lower index on ties), join one by one until the payloads add up. The sums of
    the teams in turn (each as the team's own sum) are tested a block at a time."""
    others = np.ones(len(payloads), dtype=bool)
    others[start] = False
    rest = np.flatnonzero(others)
    seq = np.concatenate([np.asarray(start, dtype=np.int64), rest[np.argsort(payloads[rest], kind="stable")]])
    for lo in range(len(start), len(seq) + 1, FILL_BLOCK):
        sizes = range(lo, min(lo + FILL_BLOCK, len(seq) + 1))
        short = shortfall(0.0, np.array([payloads[seq[:j]].sum() for j in sizes]), 0.0, need_payload)[1]
        done = np.flatnonzero(~(short > 0))
        if len(done):
            return [int(i) for i in seq[:sizes[int(done[0])]]]
    return None


def lightest_cover(caps: AmountArray, payloads: FloatArray, need_caps: AmountArray,
                   need_payload: float, roles: bool = False, traits_from: int | None = None) -> tuple[int, ...] | None:
    """GRP's subteam: an inclusion-minimal covering subteam of small total payload (ties:
    fewer robots, then lower indices), or None when all of them cannot cover. With
    additive traits (columns ``traits_from`` on), the least surplus after the payload: the
    amounts of those traits the subteam ties up beyond the need, each trait in units of
    the largest amount a candidate has of it.

    Built constructively, never by enumerating subsets: the lightest robot that covers
    alone; the teams :func:`grow` builds (both payload fills) and :func:`prune` trims
    (heaviest members tried first); and the same seeded with each holder of a needed capability (up to
    SEED_EVERY_HOLDER candidates; beyond, the lightest holder of each needed capability).
    The lightest wins. O(n^2 t K) up to SEED_EVERY_HOLDER candidates, O(K n t K) beyond,
    for n candidates and teams of t. A minimum-weight cover is NP-hard; this finds the
    lightest minimal subteam in 99.3 % of random small cases (a test holds it to 95 %),
    and GRP's makespans on the first 200 / 600 test instances of Datasets I / II equal
    those of the former exhaustive search in every schedule. With 0/1 capabilities and
    whole payloads (and at most MASK_BITS capabilities), the same steps in plain Python
    over the kinds of robot (:class:`CoverPool`, a test holds the answers equal);
    otherwise in arrays."""
    if len(caps) == 0 or not covers(caps, payloads, need_caps, need_payload, roles):
        return None
    if not roles and traits_from is None and CoverPool.serves(need_caps, need_payload) \
            and whole_numbers(caps, payloads):
        return CoverPool(caps, payloads).lightest(need_caps, need_payload)
    return _array_cover(caps, payloads, need_caps, need_payload, roles, traits_from)


def _array_cover(caps: AmountArray, payloads: FloatArray, need_caps: AmountArray, need_payload: float,
                 roles: bool, traits_from: int | None) -> tuple[int, ...]:
    """:func:`lightest_cover` over candidates that cover, in arrays (any amounts)."""
    options: list[list[int]] = []
    alone = [int(i) for i in np.flatnonzero(covers_alone(caps, payloads, need_caps[None, :], need_payload, roles))]
    if alone and traits_from is None:
        options.append([min(alone, key=lambda i: (float(payloads[i]), i))])
    else:
        options += [[i] for i in alone]
    place = np.empty(len(caps), dtype=np.int64)  # each robot's place, the heaviest first (lower index on ties)
    place[np.argsort(-payloads, kind="stable")] = np.arange(len(caps))
    heaviest_first = place.tolist()
    seeds: list[int | None] = [None]
    holds = (np.asarray(caps) > 0) & (np.asarray(need_caps) > TOLERANCE)[None, :]
    if len(caps) <= SEED_EVERY_HOLDER:  # every holder of a needed capability (trait)
        seeds += [int(i) for i in np.flatnonzero(holds.any(axis=1))]
    else:  # the lightest holder of each needed capability (trait)
        for c in np.flatnonzero(holds.any(axis=0)):
            holders = np.flatnonzero(holds[:, c])
            seeds.append(int(holders[np.argmin(payloads[holders])]))
    pruned: dict[tuple[int, ...], list[int]] = {}  # a team grown twice is pruned once
    lightest_first = np.argsort(payloads, kind="stable")  # grow's default order, for every seed
    for seed in dict.fromkeys(seeds):
        core = _grow_traits(caps, payloads, need_caps, () if seed is None else (seed,), lightest_first, roles)
        for fill in ("single", "ascending"):  # grow's two payload fills, on the one trait cover
            team = None if core is None else _fill_payload(payloads, need_caps, need_payload, core, fill)
            if team is not None:
                key = tuple(sorted(team, key=heaviest_first.__getitem__))
                if key not in pruned:
                    pruned[key] = prune(list(key), caps, payloads, need_caps, need_payload, roles=roles)
                options.append(pruned[key])
    options = [list(t) for t in dict.fromkeys(tuple(t) for t in options)]  # each team (in its order) once
    if traits_from is None:
        best = min(options, key=lambda t: (float(payloads[t].sum()), len(t), sorted(t)))
        return tuple(sorted(best))
    amounts = np.asarray(caps, dtype=np.float64)[:, traits_from:]
    unit = np.where(amounts.max(axis=0, initial=0.0) > 0, amounts.max(axis=0, initial=0.0), 1.0)
    need = np.asarray(need_caps, dtype=np.float64)[traits_from:]

    def surplus(t: list[int]) -> float:
        return float(((amounts[t].sum(axis=0) - need) / unit).sum())

    best = min(options, key=lambda t: (float(payloads[t].sum()), round(surplus(t), 9), len(t), sorted(t)))
    return tuple(sorted(best))


def _zero_one(values: npt.ArrayLike) -> bool:
    """Every value 0 or 1 (capabilities as amounts)."""
    v = np.asarray(values)
    return bool(((v == 0) | (v == 1)).all())


def _whole(values: npt.ArrayLike) -> bool:
    """Whole numbers >= 0 whose sum stays below 2^52: every sum of some of them is exact
    in floating point, in any order."""
    v = np.asarray(values, dtype=np.float64)
    return bool(np.isfinite(v).all() and (v >= 0).all() and (v == np.round(v)).all() and v.sum() < 2.0 ** 52)


def whole_numbers(caps: AmountArray, payloads: FloatArray) -> bool:
    """0/1 capabilities (at most MASK_BITS) and whole payloads (:func:`_whole`): every sum
    :func:`lightest_cover` forms is exact in any order, so :class:`CoverPool` gives its
    very answer (for tasks whose needs are whole too: :meth:`CoverPool.serves`)."""
    caps = np.asarray(caps)
    return caps.ndim == 2 and caps.shape[1] <= MASK_BITS and _zero_one(caps) and _whole(payloads)


def _parts(items: IntArray, starts: IntArray) -> list[list[int]]:
    """``items`` cut before each of the places ``starts`` (the first is 0; none: no part),
    as lists."""
    flat, cuts = items.tolist(), starts.tolist()
    ends = [*cuts[1:], len(flat)] if cuts else []
    return [flat[a:b] for a, b in zip(cuts, ends, strict=True)]


class CoverPool:
    """Candidates as kinds of robot (the same capabilities and payload), for 0/1
    capabilities and whole payloads (:func:`whole_numbers`): :meth:`lightest` gives
    :func:`lightest_cover`'s answer built step by step in plain Python, and robots that
    are given a task :meth:`remove`, so GRP asks task after task without building it
    again. Each step of the construction takes the first robot of an order where a kind's
    copies are ties broken by index, as the array version does, at a cost per kind, not
    per candidate. Robots are named by their places in the arrays it was made from."""

    def __init__(self, caps: AmountArray, payloads: FloatArray) -> None:
        caps, payloads = np.asarray(caps), np.asarray(payloads, dtype=np.float64)
        k = caps.shape[1]
        self.weights = np.int64(1) << np.arange(k, dtype=np.int64)
        bits = (caps > 0).astype(np.int64) @ self.weights
        self.mask, self.payload = bits.tolist(), payloads.tolist()
        light = np.argsort(payloads, kind="stable")  # the lightest first, lower index on ties
        _, of_value = np.unique(payloads[light], return_index=True)
        self.lightest_first = _parts(light, of_value)  # per payload, by index
        by_kind = np.lexsort((np.arange(len(bits)), payloads, bits))  # each kind's copies by index
        b, p = bits[by_kind], payloads[by_kind]
        starts = np.flatnonzero(np.r_[True, (b[1:] != b[:-1]) | (p[1:] != p[:-1])])  # where a kind begins
        copies = _parts(by_kind, starts[:len(b)])  # no robot: no kind
        # the kinds, the lightest first (then by their first copy): (payload, bits, copies)
        self.kinds = sorted(((self.payload[c[0]], self.mask[c[0]], c) for c in copies), key=lambda x: (x[0], x[2][0]))
        of_payload = {self.payload[g[0]]: g for g in self.lightest_first}
        self.group = {i: (copies, of_payload[payload]) for payload, _, copies in self.kinds for i in copies}
        self.n = len(payloads)
        self.total = float(sum(self.payload))
        self.need, self.need_payload = 0, 0.0

    @staticmethod
    def serves(need_caps: AmountArray, need_payload: float) -> bool:
        """Whether the task's needs are 0/1 capabilities and a whole payload."""
        return _zero_one(need_caps) and _whole([need_payload])

    def remove(self, team: Sequence[int]) -> None:
        """The robots ``team`` leave the candidates."""
        for i in team:
            copies, group = self.group.pop(i)
            copies.remove(i)
            group.remove(i)
            self.n -= 1
            self.total -= self.payload[i]

    def lightest(self, need_caps: AmountArray, need_payload: float) -> tuple[int, ...] | None:
        """:func:`lightest_cover`'s subteam of the candidates left, or None (the task's
        needs: :meth:`serves`)."""
        self.need = int((np.asarray(need_caps) > TOLERANCE).astype(np.int64) @ self.weights)
        self.need_payload = float(need_payload)
        got = 0
        for _, bits, copies in self.kinds:
            if copies:
                got |= bits
        if not self.n or got & self.need != self.need or self.need_payload - self.total > TOLERANCE:
            return None
        options: list[list[int]] = []
        alone = self._first(set(), lambda bits, payload: bits & self.need == self.need
                            and self.need_payload - payload <= TOLERANCE)
        if alone is not None:
            options.append([alone])
        pruned: dict[tuple[int, ...], list[int]] = {}
        for seed in dict.fromkeys(self._seeds()):
            core = self._grow([] if seed is None else [seed])
            for fill in ("single", "ascending"):
                team = None if core is None else self._fill(core, fill)
                if team is not None:
                    key = tuple(sorted(team, key=lambda i: (-self.payload[i], i)))
                    if key not in pruned:
                        pruned[key] = self._prune(list(key))
                    options.append(pruned[key])
        best = min(dict.fromkeys(tuple(t) for t in options),
                   key=lambda t: (sum(self.payload[i] for i in t), len(t), sorted(t)))
        return tuple(sorted(best))

    def _covers(self, team: list[int]) -> bool:
        got, total = 0, 0.0
        for i in team:
            got |= self.mask[i]
            total += self.payload[i]
        return got & self.need == self.need and self.need_payload - total <= TOLERANCE

    def _first(self, used: set[int], match: Callable[..., bool], heaviest: bool = False) -> int | None:
        """The first candidate not ``used`` whose kind ``match`` takes (bits, payload):
        the lightest (``heaviest``: the heaviest), then the lowest index."""
        best: tuple[float, int] | None = None
        for payload, bits, copies in reversed(self.kinds) if heaviest else self.kinds:
            if best is not None and payload != best[0]:
                break  # the kinds further on are heavier (lighter)
            if copies and match(bits, payload):
                i = next((c for c in copies if c not in used), None)
                if i is not None and (best is None or i < best[1]):
                    best = (payload, i)
        return None if best is None else best[1]

    def _grow(self, start: list[int]) -> list[int] | None:
        team, used = list(start), set(start)
        got = 0
        for i in team:
            got |= self.mask[i]
        missing = self.need & ~got
        while missing:
            top = max((bin(bits & missing).count("1") for _, bits, copies in self.kinds
                       if bits & missing and copies and (copies[0] not in used  # the usual case, at once
                                                          or any(c not in used for c in copies))),
                      default=0)
            if top <= 0:
                return None
            pick = self._first(used, lambda bits, payload, m=missing, g=top: bin(bits & m).count("1") == g)
            assert pick is not None
            team.append(pick)
            used.add(pick)
            missing &= ~self.mask[pick]
        return team

    def _fill(self, start: list[int], fill: str) -> list[int] | None:
        team, used = list(start), set(start)
        total = sum(self.payload[i] for i in team)
        if fill == "ascending":
            for robots in self.lightest_first:
                for i in robots:
                    if self.need_payload - total <= TOLERANCE:
                        return team
                    if i not in used:
                        team.append(i)
                        total += self.payload[i]
            return team if self.need_payload - total <= TOLERANCE else None
        while self.need_payload - total > TOLERANCE:
            if len(used) == self.n:
                return None
            short = self.need_payload - total
            pick = self._first(used, lambda bits, payload, s=short: payload >= s - TOLERANCE)
            if pick is None:  # none fills it alone: the heaviest
                pick = self._first(used, lambda bits, payload: True, heaviest=True)
            assert pick is not None
            team.append(pick)
            used.add(pick)
            total += self.payload[pick]
        return team

    def _prune(self, team: list[int]) -> list[int]:
        out = list(team)
        for q in team:
            if len(out) > 1:
                rest = [x for x in out if x != q]
                if self._covers(rest):
                    out = rest
        return out

    def _seeds(self) -> list[int | None]:
        if self.n <= SEED_EVERY_HOLDER:  # every holder of a needed capability
            return [None, *sorted(i for _, bits, copies in self.kinds if bits & self.need for i in copies)]
        seeds: list[int | None] = [None]
        for c in range(self.need.bit_length()):
            if self.need >> c & 1:
                pick = self._first(set(), lambda bits, payload, c=c: bool(bits >> c & 1))
                if pick is not None:
                    seeds.append(pick)
        return seeds


def random_cover(caps: AmountArray, payloads: FloatArray, need_caps: AmountArray, need_payload: float,
                 rng: np.random.Generator, roles: bool = False) -> tuple[int, ...] | None:
    """A random inclusion-minimal covering subteam (RAND w/ subteams), or None: robots
    join in a random order until the team covers, then members leave in a random order
    while it still does. O(n t K)."""
    if len(caps) == 0 or not covers(caps, payloads, need_caps, need_payload, roles):
        return None
    order = rng.permutation(len(caps))
    useful = helps(caps, need_caps[None, :], np.array([need_payload]))[:, 0]
    team: list[int] = []
    for i in order:
        if useful[i]:
            team.append(int(i))
            if covers(caps[team], payloads[team], need_caps, need_payload, roles):
                break
    team = prune([team[k] for k in rng.permutation(len(team))], caps, payloads, need_caps, need_payload,
                 roles=roles)
    return tuple(sorted(team))


def cover_with(caps: AmountArray, payloads: FloatArray, need_caps: AmountArray, need_payload: float,
               member: int, roles: bool = False) -> tuple[int, ...] | None:
    """An inclusion-minimal covering subteam that includes ``member``, found
    constructively (grown from it, trimmed without it), or None when none is found:
    whether ``member`` could start the task now with other robots. O(n t K)."""
    if not helps(caps[[member]], need_caps[None, :], np.array([need_payload]))[0, 0]:
        return None
    team = grow(caps, payloads, need_caps, need_payload, (member,), roles=roles)
    if team is None:
        return None
    team = prune(team[::-1], caps, payloads, need_caps, need_payload, keep=member, roles=roles)
    rest = [x for x in team if x != member]
    if rest and covers(caps[rest], payloads[rest], need_caps, need_payload, roles):
        return None  # the member is not needed in the team found
    return tuple(sorted(team))


def minimal_subteams(
    caps: AmountArray, payloads: FloatArray, need_caps: AmountArray, need_payload: float, roles: bool = False
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
    cap_sum = bits.astype(np.float64) @ np.asarray(caps, dtype=np.float64)  # (2^n, K)
    feasible = covered(cap_sum, bits @ payloads, need_caps, need_payload)
    if roles:
        for m in np.flatnonzero(feasible):
            feasible[m] = role_cover(caps[bits[m]], need_caps)
    minimal = feasible.copy()
    for i in range(n):
        has_i = bits[:, i]
        minimal[has_i] &= ~feasible[masks[has_i] ^ (1 << i)]
    return [tuple(int(i) for i in np.flatnonzero(bits[m])) for m in np.flatnonzero(minimal)]


def shortlist(caps: AmountArray, payloads: FloatArray, need_caps: AmountArray, limit: int = MAX_ENUMERATED) -> list[int]:
    """Up to ``limit`` candidate robots for a task from a larger team.

    Keeps the robots holding the most needed capabilities, then the largest payloads;
    used by the baselines when more than MAX_ENUMERATED robots are free.
    """
    useful = ((caps > 0) & (need_caps > TOLERANCE)[None, :]).sum(axis=1)
    order = np.lexsort((-payloads, -useful))
    return sorted(int(i) for i in order[:limit])


def team_candidates(
    caps: AmountArray, payloads: FloatArray, need_caps: AmountArray, need_payload: float, roles: bool = False
) -> list[tuple[int, ...]]:
    """Minimal covering subteams among the given robots (shortlisted when many)."""
    if len(caps) <= MAX_ENUMERATED:
        return minimal_subteams(caps, payloads, need_caps, need_payload, roles)
    keep = shortlist(caps, payloads, need_caps)
    teams = minimal_subteams(caps[keep], payloads[keep], need_caps, need_payload, roles)
    return [tuple(keep[i] for i in team) for team in teams]
