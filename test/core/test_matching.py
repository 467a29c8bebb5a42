"""Subteam matching of Eqs. 7-11: greedy obeys the constraints, exact is optimal,
and how often greedy reaches the exact optimum."""

from __future__ import annotations

import numpy as np
import pytest

from lvws_ros.cli.bench import random_matching_case
from lvws_ros.core.matching import greedy_match
from lvws_ros.core.subteams import covers
from lvws_ros.errors import PolicyError
from lvws_ros.learning.loss import feasibility_mask
from lvws_ros.policies.exact import exact_match


def assert_valid(match, r, robot_caps, robot_payload, task_caps, task_payload):
    n, m = r.shape[0], r.shape[1] - 1
    used = [i for team in match.teams.values() for i in team] + list(match.waiting)
    assert len(used) == len(set(used)), "a robot in two places (Eq. 9)"
    assert sorted(used) == list(range(n)), "every robot takes a task or waits"
    for j, team in match.teams.items():
        assert 0 <= j < m
        idx = list(team)
        assert covers(robot_caps[idx], robot_payload[idx], task_caps[j], task_payload[j]), "Eqs. 10-11"


@pytest.mark.parametrize("seed", range(40))
def test_greedy_obeys_constraints(seed):
    rng = np.random.default_rng(seed)
    case = random_matching_case(rng, int(rng.integers(1, 9)), int(rng.integers(1, 8)))
    match = greedy_match(*case)
    assert_valid(match, *case)
    r = case[0]
    assert match.reward == pytest.approx(
        sum(r[i, j] for j, t in match.teams.items() for i in t) + sum(r[i, -1] for i in match.waiting))


def test_greedy_vs_exact_on_random_cases():
    rng = np.random.default_rng(7)
    equal = 0
    cases = 60
    for _ in range(cases):
        case = random_matching_case(rng, int(rng.integers(2, 7)), int(rng.integers(1, 6)))
        g = greedy_match(*case)
        e = exact_match(*case, time_limit=10)
        assert_valid(e, *case)
        assert e.reward >= g.reward - 1e-5, "exact is never worse than greedy"
        equal += abs(e.reward - g.reward) < 1e-5
    print(f"greedy == exact on {equal}/{cases} random cases")
    assert equal >= cases // 4  # greedy is a heuristic, but not a bad one


def test_partial_subteam_releases_its_robots():
    # r0 joins t0 (needs payload 10, two robots), r1 takes t1, r2 prefers to wait: t0 can
    # no longer be completed, so r0 is released and takes its next best option, t2.
    robot_caps = np.ones((3, 1), dtype=bool)
    robot_payload = np.array([5.0, 5.0, 5.0])
    task_caps = np.ones((3, 1), dtype=bool)
    task_payload = np.array([10.0, 5.0, 5.0])
    r = np.array([
        [5.0, 0.0, 0.1, -1.0],
        [0.0, 4.0, 0.0, -1.0],
        [0.0, 0.0, 0.0, 3.0],
    ])
    m = greedy_match(r, robot_caps, robot_payload, task_caps, task_payload)
    assert m.teams == {1: (1,), 2: (0,)}
    assert m.waiting == (2,)


def test_idle_column_makes_robots_wait():
    robot_caps = np.array([[1], [1]], dtype=bool)
    task_caps = np.array([[1]], dtype=bool)
    r = np.array([[1.0, 2.0], [3.0, -1.0]])
    m = greedy_match(r, robot_caps, np.array([5.0, 5.0]), task_caps, np.array([1.0]))
    assert m.teams == {0: (1,)} and m.waiting == (0,)


def test_shape_and_value_errors():
    caps = np.ones((2, 1), dtype=bool)
    with pytest.raises(ValueError, match="shape"):
        greedy_match(np.zeros((2, 2)), caps, np.ones(2), caps, np.ones(2))
    with pytest.raises(PolicyError, match="NaN"):
        greedy_match(np.full((2, 3), np.nan), caps, np.ones(2), caps, np.ones(2))


def test_feasibility_mask_has_idle_column():
    x = feasibility_mask(np.array([[1, 0], [0, 1]], bool), np.array([[1, 0]], bool), np.ones(2), np.zeros(1))
    assert x.tolist() == [[True, True], [False, True]]


def test_exact_matching_keeps_to_the_allowed_pairs_and_is_never_worse_than_greedy_there():
    rng = np.random.default_rng(11)
    for _ in range(25):
        case = random_matching_case(rng, int(rng.integers(2, 7)), int(rng.integers(1, 6)))
        n, m = case[0].shape[0], case[0].shape[1] - 1
        allowed = rng.random((n, m)) < 0.7
        g = greedy_match(*case, allowed)
        e = exact_match(*case, time_limit=10, allowed=allowed)
        assert_valid(e, *case)
        assert all(allowed[i, j] for j, team in e.teams.items() for i in team)
        assert e.reward >= g.reward - 1e-5


def _one_pick_at_a_time(r, caps, payload, need, need_payload, allowed, roles):
    """The greedy of Eqs. 7-11 as written: every pick one global argmax, everything the
    free robots bring recomputed from scratch (the reference the fast form must equal)."""
    from lvws_ros.core.subteams import covered, helps

    n, m = r.shape[0], r.shape[1] - 1
    allowed = np.ones((n, m), bool) if allowed is None else allowed
    free, waiting, open_task = np.ones(n, bool), np.zeros(n, bool), np.ones(m, bool)
    missing, missing_pay = need.astype(float).copy(), need_payload.astype(float).copy()
    member, teams = np.zeros((n, m), bool), {}
    while True:
        can = (allowed & free[:, None]).astype(float)
        completable = covered(can.T @ caps, can.T @ payload, missing, missing_pay)
        for q in np.flatnonzero(open_task & roles):
            pool = member[:, q] | (free & allowed[:, q])
            completable[q] = covers(caps[pool], payload[pool], need[q], need_payload[q], True)
        dead = np.flatnonzero(open_task & ~completable & member.any(axis=0))
        if len(dead):
            free |= member[:, dead[0]]
            member[:, dead[0]] = False
            open_task[dead[0]] = False
            continue
        if not free.any():
            break
        useful = helps(caps, missing, missing_pay)
        useful[:, roles] = helps(caps, need[roles], need_payload[roles])
        ok = free[:, None] & (open_task & completable)[None, :] & useful & allowed
        scores = np.concatenate([np.where(ok, r[:, :m], -np.inf), np.where(free, r[:, m], -np.inf)[:, None]], 1)
        i, j = divmod(int(np.argmax(scores)), m + 1)
        free[i] = False
        if j == m:
            waiting[i] = True
            continue
        member[i, j] = True
        missing[j] -= caps[i]
        missing_pay[j] -= payload[i]
        team = np.flatnonzero(member[:, j])
        if covers(caps[team], payload[team], need[j], need_payload[j], bool(roles[j])):
            kept = [int(x) for x in team]
            for q in sorted(kept, key=lambda q: r[q, j]):
                rest = [x for x in kept if x != q]
                if rest and covers(caps[rest], payload[rest], need[j], need_payload[j], bool(roles[j])):
                    kept = rest
            free[team] = True
            free[kept] = False
            member[:, j] = False
            member[kept, j] = True
            open_task[j] = False
            teams[j] = tuple(kept)
    return teams, tuple(int(i) for i in np.flatnonzero(waiting))


@pytest.mark.parametrize("seed", range(300))
def test_greedy_is_the_one_pick_at_a_time_greedy(seed):
    """The greedy's batched idle picks and updated sums give the same subteams and waits
    as taking every pick alone and recomputing everything: many robots, few tasks, idle
    rewards often the largest, allowed pairs, roles, partial subteams released."""
    rng = np.random.default_rng(seed)
    n, m, k = int(rng.integers(1, 40)), int(rng.integers(1, 6)), int(rng.integers(1, 4))
    caps = rng.integers(0, 3, (n, k)).astype(float) * (rng.random((n, k)) < 0.5)
    need = rng.integers(0, 4, (m, k)).astype(float) * (rng.random((m, k)) < 0.6)
    payload = np.round(rng.uniform(0, 3, n), 1)
    need_payload = np.round(rng.uniform(0, 6, m), 1) * (rng.random(m) < 0.6)
    r = rng.normal(size=(n, m + 1))
    r[:, m] += rng.uniform(-1, 2)  # sometimes most robots would rather wait
    allowed = None if seed % 3 == 0 else rng.random((n, m)) < 0.8
    roles = rng.random(m) < (0.3 if seed % 2 else 0.0)
    got = greedy_match(r, caps, payload, need, need_payload, allowed, roles)
    assert (got.teams, got.waiting) == _one_pick_at_a_time(r, caps, payload, need, need_payload, allowed, roles)
