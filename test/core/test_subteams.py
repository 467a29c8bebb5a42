"""Constructive subteams (no enumeration) against the brute-force enumeration of every
subset on small teams: what they build covers (Eqs. 10-11) and is inclusion-minimal,
they find a subteam exactly when one exists, and tasks needing 17+ robots or teams of 40
are served."""

from __future__ import annotations

from unittest.mock import patch

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from lvws_ros.core.datasets import subteam_heavy_instance
from lvws_ros.core.executor import simulate
from lvws_ros.core.problem import Instance, Robot, Task
from lvws_ros.core.schedule import check_schedule
from lvws_ros.core.subteams import cover_with, covers, earliest_cover, lightest_cover, minimal_subteams, random_cover
from lvws_ros.registry import make_policy


@st.composite
def teams(draw: st.DrawFn) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    n, k = draw(st.integers(1, 9)), draw(st.integers(1, 4))
    caps = np.array(draw(st.lists(st.lists(st.booleans(), min_size=k, max_size=k), min_size=n, max_size=n)))
    payloads = np.array(draw(st.lists(st.sampled_from([0.5, 1.0, 2.0, 3.0, 5.0, 8.0]), min_size=n, max_size=n)))
    need = np.array(draw(st.lists(st.booleans(), min_size=k, max_size=k)))
    need[draw(st.integers(0, k - 1))] = True
    return caps, payloads, need, float(draw(st.sampled_from([0.0, 1.0, 2.5, 4.0, 7.0, 12.0, 30.0])))


@settings(max_examples=400, deadline=None, derandomize=True)
@given(case=teams(), seed=st.integers(0, 1000))
def test_constructive_subteams_cover_and_are_minimal(case, seed):
    caps, payloads, need, need_payload = case
    minimal = set(minimal_subteams(caps, payloads, need, need_payload))  # brute force over 2^n subsets
    built = [lightest_cover(caps, payloads, need, need_payload),
             random_cover(caps, payloads, need, need_payload, np.random.default_rng(seed))]
    for team in built:
        assert (team is None) == (not minimal)  # found exactly when one exists
        if team is not None:
            assert covers(caps[list(team)], payloads[list(team)], need, need_payload)
            assert team in minimal  # inclusion-minimal
    for member in range(len(caps)):
        team = cover_with(caps, payloads, need, need_payload, member)
        if team is not None:
            assert member in team and team in minimal


@settings(max_examples=300, deadline=None, derandomize=True)
@given(case=teams(), times=st.lists(st.sampled_from([0.0, 1.0, 2.0, 3.5, 7.0, float("inf")]), min_size=9,
                                    max_size=9))
def test_earliest_cover_is_the_first_time_the_robots_there_cover_the_task(case, times):
    """Against the definition: the least robot time t with the robots there by t a cover."""
    caps, payloads, need, need_payload = case
    t = np.array(times[:len(caps)])
    finite = sorted({x for x in t if np.isfinite(x)})
    expect = next((x for x in finite if covers(caps[t <= x], payloads[t <= x], need, need_payload)), np.inf)
    got = earliest_cover(np.stack([t, t[::-1]], axis=1), caps, payloads, np.stack([need, need]),
                         np.array([need_payload, need_payload]))
    assert got[0] == expect
    rev = t[::-1]
    assert got[1] == next((x for x in finite if covers(caps[rev <= x], payloads[rev <= x], need, need_payload)),
                          np.inf)  # the same robots at other times
    with patch("lvws_ros.core.subteams.COVER_CHUNK", 1):  # one task per chunk: the same
        assert np.array_equal(earliest_cover(np.stack([t, t[::-1]], axis=1), caps, payloads, np.stack([need, need]),
                                             np.array([need_payload, need_payload])), got)


def test_the_lightest_cover_is_the_lightest_minimal_subteam_almost_always():
    """GRP's subteam against the exhaustive minimum on 1000 random small cases (seed 0)."""
    rng = np.random.default_rng(0)
    found = optimal = 0
    for _ in range(1000):
        n, k = int(rng.integers(1, 10)), int(rng.integers(1, 5))
        caps, payloads = rng.random((n, k)) < 0.5, rng.choice([0.5, 1.0, 2.0, 3.0, 5.0, 8.0], size=n)
        need = rng.random(k) < 0.5
        need[rng.integers(k)] = True
        need_payload = float(rng.choice([0.0, 1.0, 2.5, 4.0, 7.0, 12.0]))
        minimal = minimal_subteams(caps, payloads, need, need_payload)
        if not minimal:
            continue
        team = lightest_cover(caps, payloads, need, need_payload)
        assert team is not None
        found += 1
        optimal += float(payloads[list(team)].sum()) <= min(float(payloads[list(t)].sum()) for t in minimal) + 1e-9
    assert optimal >= 0.95 * found, (optimal, found)


def test_a_task_needing_seventeen_robots_and_forty_robot_teams_are_scheduled_by_every_policy():
    robots = tuple(Robot(f"r{i}", (1, int(i % 2 == 0)), 1.0) for i in range(40))
    tasks = (Task("big", (1, 0), 17.0, 3.0), Task("wide", (1, 1), 12.0, 2.0, ("big",)),
             Task("small", (0, 1), 1.0, 1.0))
    inst = Instance("fleet", ("lift", "drive"), robots, tasks)
    for name in ("grp", "rand", "rand_subteam", "exact", "lvws", "dbgm", "lvws_rollout", "lvws_beam"):
        sched = simulate(inst, make_policy(name, **({"workers": 2, "time_limit": 30} if name == "exact" else {})))
        assert check_schedule(inst, sched.schedule) == [], name
        assert len(sched.schedule.by_task()["big"].robots) == 17, name


def test_the_expert_beyond_sixteen_robots_is_valid_and_never_worse_than_grp():
    from lvws_ros.policies.exact import solve_exact

    inst = subteam_heavy_instance(np.random.default_rng([3, 20, 40]), 20, 40, "20r-40t-heavy")
    grp = simulate(inst, make_policy("grp")).schedule
    res = solve_exact(inst, workers=2, time_limit=20)
    assert res.schedule is not None and check_schedule(inst, res.schedule) == []
    assert res.makespan is not None and res.makespan <= grp.makespan + 1e-9
    assert res.bound <= res.makespan + 1e-9 and (res.status == "optimal") == (res.gap == 0.0)


def test_both_expert_formulations_agree_on_small_instances():
    from lvws_ros.core.datasets import DATASETS, dataset_instance
    from lvws_ros.policies.exact import solve_exact

    for k in range(800, 804):
        inst = dataset_instance(DATASETS["I"], k, 0)
        a = solve_exact(inst, workers=2, formulation="coalition")
        b = solve_exact(inst, workers=2, formulation="boolean", time_limit=30)
        assert a.proven and b.proven and a.makespan == b.makespan
        assert b.schedule is not None and check_schedule(inst, b.schedule) == []


def test_nan_is_never_covered():
    from lvws_ros.core.subteams import covered

    assert not covered([True], 1.0, [True], float("nan"))
    assert not covered([True], float("nan"), [True], 1.0)


def test_the_boolean_model_never_accepts_a_short_subteam_and_accepts_exact_fractions():
    from lvws_ros.policies.exact import solve_exact

    short = Instance("short", ("a",), tuple(Robot(f"r{i}", (1,), 0.4996) for i in range(4)),
                     (Task("t0", (1,), 0.9995, 1.0), Task("t1", (1,), 0.9995, 1.0)))
    res = solve_exact(short, workers=2, formulation="boolean", time_limit=20)
    assert res.schedule is not None and check_schedule(short, res.schedule) == []
    thirds = Instance("thirds", ("a",), tuple(Robot(f"r{i}", (1,), 1 / 3) for i in range(3)),
                      (Task("t0", (1,), 1.0, 1.0),))
    res = solve_exact(thirds, workers=2, formulation="boolean", time_limit=20)
    assert res.proven and res.schedule is not None and check_schedule(thirds, res.schedule) == []


@settings(max_examples=400, deadline=None)
@given(st.integers(1, 14), st.integers(1, 4), st.integers(0, 2**32 - 1))
def test_the_role_rule_is_the_same_whichever_search_decides_it(n, k, seed):
    """Roles (each member fills one trait): the plain-float search for a few members, the
    greedy assignment and the array search for many give the same answer; checked against
    an exhaustive assignment of members to traits."""
    import itertools

    from lvws_ros.core import subteams

    rng = np.random.default_rng(seed)
    caps = rng.integers(0, 4, size=(n, k)).astype(float) * (rng.random((n, k)) < 0.6)
    need = rng.integers(0, 6, size=k).astype(float)
    got = []
    for small in (0, subteams.SMALL_ROLE_TEAM):
        with patch.object(subteams, "SMALL_ROLE_TEAM", small):
            got.append(subteams.role_cover(caps, need))
    if n <= 7:  # every assignment of each member to one trait or none
        brute = any(all(sum(caps[i, c] for i in range(n) if pick[i] == c) >= need[c] - 1e-9 for c in range(k))
                    for pick in itertools.product(range(-1, k), repeat=n))
        got.append(brute)
    assert len(set(got)) == 1, (caps.tolist(), need.tolist(), got)


@settings(max_examples=200, deadline=None)
@given(st.integers(1, 7), st.integers(1, 4), st.integers(0, 2**32 - 1))
def test_the_role_rule_kept_for_a_team_is_the_searched_one_in_any_order(n, k, seed):
    """The answer kept for a small team (GRP asks again about the teams it grows and
    trims) is the one a fresh search gives for its members in any order."""
    from lvws_ros.core import subteams

    rng = np.random.default_rng(seed)
    caps = np.round(rng.random((n, k)) * 4, 1) * (rng.random((n, k)) < 0.6)
    need = np.round(rng.random(k) * 6, 1) * (rng.random(k) < 0.8)
    subteams._role_memo.clear()
    first = subteams.role_cover(caps, need)
    for _ in range(3):
        perm = rng.permutation(n)
        assert subteams.role_cover(caps[perm], need) == first  # kept
        subteams._role_memo.clear()
        assert subteams.role_cover(caps[perm], need) == first  # searched again
    if n <= 6:  # every assignment of each member to one trait or none
        import itertools
        brute = any(all(sum(caps[i, c] for i in range(n) if pick[i] == c) >= need[c] - 1e-6 for c in range(k))
                    for pick in itertools.product(range(-1, k), repeat=n))
        assert first == brute, (caps.tolist(), need.tolist())


@settings(max_examples=300, deadline=None, derandomize=True)
@given(payloads=st.lists(st.sampled_from([0.0, 0.1, 0.2, 0.3, 0.5, 1.0, 2.5, 4.0]), min_size=1, max_size=24),
       need=st.sampled_from([0.0, 0.3, 0.6, 1.0, 2.9, 7.5, 20.0, 100.0]), data=st.data())
def test_the_ascending_payload_fill_adds_the_lightest_robots_one_by_one(payloads, need, data):
    """grow's "ascending" fill (tested a block of team sizes at a time) against its
    definition: from the start team, the lightest robot not in the team (lower index on
    ties) joins until the team's own sum reaches the need; None when all fall short."""
    from lvws_ros.core.subteams import TOLERANCE, grow

    pay = np.array(payloads)
    n = len(pay)
    start = data.draw(st.lists(st.integers(0, n - 1), unique=True, max_size=3))
    team, got = list(start), None
    while True:
        if pay[team].sum() >= need - TOLERANCE:
            got = team
            break
        rest = [i for i in range(n) if i not in team]
        if not rest:
            break
        team = [*team, min(rest, key=lambda i: (pay[i], i))]
    caps = np.ones((n, 1))
    assert grow(caps, pay, np.zeros(1), need, start, fill="ascending") == got  # no trait needed


@settings(max_examples=500, deadline=None, derandomize=True)
@given(n=st.integers(1, 60), k=st.sampled_from([1, 2, 3, 4, 61, 62]), kinds=st.integers(1, 12),
       need_payload=st.integers(0, 40), zero=st.booleans(), spread=st.booleans(), seed=st.integers(0, 10_000))
def test_with_whole_payloads_the_kinds_give_the_arrays_answer(n, k, kinds, need_payload, zero, spread, seed):
    """lightest_cover's construction in plain Python over the kinds of robot (0/1
    capabilities, whole payloads; a CoverPool) gives the subteam its array version gives,
    on teams with many copies of a kind, robots carrying nothing, up to and beyond
    SEED_EVERY_HOLDER candidates, up to MASK_BITS capabilities, and after robots left the
    pool (against the arrays of the robots left)."""
    from lvws_ros.core.subteams import CoverPool, _array_cover

    rng = np.random.default_rng(seed)
    kind_caps = rng.random((kinds, k)) < rng.random()
    kind_payload = rng.integers(0 if zero else 1, 9, kinds).astype(float)
    pick = rng.integers(0, kinds, n)
    caps, payloads = kind_caps[pick].astype(float), kind_payload[pick]
    if spread:  # every robot a payload of its own: many kinds
        payloads = payloads + 16 * np.arange(n)
    pool, left = CoverPool(caps, payloads), np.arange(n)
    for _ in range(3):
        need = (rng.random(k) < 0.5).astype(float)
        if not need.any() and need_payload == 0:
            need[0] = 1.0
        want = None
        if covers(caps[left], payloads[left], need, float(need_payload)):
            found = _array_cover(caps[left], payloads[left], need, float(need_payload), False, None)
            want = tuple(int(left[i]) for i in found)
        assert pool.lightest(need, float(need_payload)) == want
        gone = rng.choice(left, size=min(len(left), int(rng.integers(1, 4))), replace=False)
        pool.remove(gone.tolist())
        left = np.setdiff1d(left, gone)
        if not len(left):
            break


def test_a_pool_keeps_the_last_capability_of_mask_bits_apart_whatever_the_payloads():
    """Robots that differ only in capability MASK_BITS - 1 stay different kinds with 8
    payloads about (a kind key of bits times payloads once wrapped around 2^64 there)."""
    from lvws_ros.core.subteams import MASK_BITS, CoverPool, _array_cover

    caps = np.zeros((9, MASK_BITS))
    caps[1, MASK_BITS - 1] = 1
    payloads = np.array([1.0, 1, 2, 3, 4, 5, 6, 7, 8])
    need = np.zeros(MASK_BITS)
    need[MASK_BITS - 1] = 1
    assert _array_cover(caps, payloads, need, 1.0, False, None) == (1,)
    assert CoverPool(caps, payloads).lightest(need, 1.0) == (1,) == lightest_cover(caps, payloads, need, 1.0)
