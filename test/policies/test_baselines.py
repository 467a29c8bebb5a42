"""Every policy yields valid schedules (formats.md rules) on generated instances,
including one robot and one task; bad policies are stopped with a message."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lvws_ros.core.datasets import random_instance, subteam_heavy_instance
from lvws_ros.core.executor import Decision, State, simulate
from lvws_ros.core.schedule import check_schedule
from lvws_ros.core.subteams import _array_cover, covers
from lvws_ros.errors import PolicyError
from lvws_ros.policies.baselines import PRIORITIES, GreedyPayloadPolicy
from lvws_ros.registry import POLICY_NAMES, make_policy

BASELINES = ["grp", "rand", "rand_subteam"]


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 8), m=st.integers(1, 20),
       policy=st.sampled_from(BASELINES), policy_seed=st.integers(0, 1000))
def test_baselines_give_valid_schedules(seed, n, m, policy, policy_seed):
    inst = random_instance(np.random.default_rng(seed), n, m, "h")
    res = simulate(inst, make_policy(policy, seed=policy_seed))
    assert check_schedule(inst, res.schedule) == []
    assert res.schedule.decisions == len(res.steps) >= 1


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 5), m=st.integers(1, 9))
def test_exact_policy_gives_valid_optimal_schedules(seed, n, m):
    inst = random_instance(np.random.default_rng(seed), n, m, "h")
    policy = make_policy("exact", time_limit=20, workers=2)
    res = simulate(inst, policy)
    assert check_schedule(inst, res.schedule) == []
    assert policy.result.status == "optimal"
    assert res.schedule.makespan == pytest.approx(policy.result.makespan)
    for name in BASELINES:
        assert simulate(inst, make_policy(name)).schedule.makespan >= res.schedule.makespan - 1e-9


@pytest.mark.parametrize("n,m", [(1, 1), (1, 6), (5, 1)])
def test_edge_sizes(n, m):
    inst = random_instance(np.random.default_rng(3), n, m, "edge")
    for name in [*BASELINES, "exact"]:
        res = simulate(inst, make_policy(name, workers=2) if name == "exact" else make_policy(name))
        assert check_schedule(inst, res.schedule) == [], name


def test_single_robot_makespan_is_sum_of_durations():
    inst = random_instance(np.random.default_rng(11), 1, 7, "solo")
    for name in BASELINES:
        assert simulate(inst, make_policy(name)).schedule.makespan == pytest.approx(inst.durations.sum())


def test_same_seed_same_schedule():
    inst = random_instance(np.random.default_rng(5), 6, 18, "seeded")
    for name in ["rand", "rand_subteam"]:
        a = simulate(inst, make_policy(name, seed=4)).schedule.assignments
        b = simulate(inst, make_policy(name, seed=4)).schedule.assignments
        assert a == b


class Lazy:
    name = "lazy"

    def reset(self, instance):
        pass

    def decide(self, state: State) -> Decision:
        return Decision((), tuple(state.free_robots()))


class Cheater:
    name = "cheater"

    def reset(self, instance):
        pass

    def decide(self, state: State) -> Decision:
        queued = [j for j in range(state.instance.num_tasks) if j not in state.ready_tasks()]
        return Decision(((queued[0], (0,)),)) if queued else Decision(((state.ready_tasks()[0], (0,)),))


def test_no_progress_is_an_error_not_a_loop():
    inst = random_instance(np.random.default_rng(1), 3, 4, "x")
    with pytest.raises(PolicyError, match="no progress"):
        simulate(inst, Lazy())


def test_unready_task_or_uncovering_team_is_rejected():
    inst = random_instance(np.random.default_rng(2), 3, 6, "x")
    with pytest.raises(PolicyError, match=r"not ready|does not cover"):
        simulate(inst, Cheater())


def test_policy_names():
    assert set(BASELINES) | {"exact"} <= set(POLICY_NAMES)
    with pytest.raises(PolicyError, match="unknown policy"):
        make_policy("nope")


def test_voluntary_waits_are_free_robots_kept_from_a_task_they_could_start():
    from lvws_ros.core.executor import voluntary_waits
    from lvws_ros.core.problem import Instance, Robot, Task

    inst = Instance("w", ("a", "b"),
                    (Robot("r0", (1, 0), 5.0), Robot("r1", (1, 0), 5.0), Robot("r2", (0, 1), 5.0)),
                    (Task("heavy", (1, 0), 8.0, 2.0), Task("b_job", (0, 1), 1.0, 1.0),
                     Task("later", (1, 0), 1.0, 1.0, ("heavy",))))
    state = State.initial(inst)
    assert state.ready_tasks() == [0, 1]
    # both a-robots wait: together they could carry "heavy" (8 > 5 each), so both waits are voluntary
    assert voluntary_waits(state, Decision(((1, (2,)),))) == {0: (0,), 1: (0,)}
    # r0 + r1 on "heavy": r2 left while b_job is ready waits voluntarily
    assert voluntary_waits(state, Decision(((0, (0, 1)),))) == {2: (1,)}
    # everything ready is taken: nobody waits voluntarily
    assert voluntary_waits(state, Decision(((0, (0, 1)), (1, (2,))))) == {}
    # once r2 has started b_job, only "heavy" is ready: the a-robots still could carry it
    state.start(1, (2,))
    assert voluntary_waits(state, Decision()) == {0: (0,), 1: (0,)}
    state.robot_free_at[1] = 5.0  # r1 busy: r0 alone cannot carry "heavy"
    assert voluntary_waits(state, Decision()) == {}


def test_grp_in_critical_path_order_starts_the_longest_chain_first():
    """Two robots; two independent 5 s tasks listed first, then a 1 s task that a 10 s
    task waits for: in index order the chain starts at 5 s (16 s in all); longest path
    first it starts at once (11 s, the chain's length)."""
    from lvws_ros.core.problem import Instance, Robot, Task
    from lvws_ros.policies.baselines import GreedyPayloadPolicy

    inst = Instance("chain", ("a",), (Robot("r0", (1,), 1.0), Robot("r1", (1,), 1.0)),
                    (Task("x0", (1,), 0.0, 5.0), Task("x1", (1,), 0.0, 5.0), Task("head", (1,), 0.0, 1.0),
                     Task("tail", (1,), 0.0, 10.0, ("head",))))
    assert simulate(inst, GreedyPayloadPolicy()).schedule.makespan == pytest.approx(16.0)
    path = simulate(inst, GreedyPayloadPolicy(priority="critical-path")).schedule
    assert check_schedule(inst, path) == []
    assert path.makespan == pytest.approx(11.0)
    with pytest.raises(PolicyError, match="priority"):
        GreedyPayloadPolicy(priority="shortest")


def _pick_reachable_by_every_limit(pol, caps, payloads, need_caps, need_payload, arrival, roles):
    """GRP's choice among the robots there soonest as first written: every distinct arrival
    time in turn, the first whose robots cover wins."""
    for limit in np.unique(arrival[np.isfinite(arrival)]):
        near = np.flatnonzero(arrival <= limit)
        team = pol.pick(caps[near], payloads[near], need_caps, need_payload, roles)
        if team is not None:
            return tuple(int(near[i]) for i in team)
    return None


@settings(max_examples=300, deadline=None)
@given(st.integers(0, 10**6), st.integers(1, 12), st.booleans())
def test_grp_skipping_the_arrivals_that_cannot_add_up_chooses_as_every_arrival_in_turn(seed, n, roles):
    from lvws_ros.policies.baselines import GreedyPayloadPolicy

    rng = np.random.default_rng(seed)
    k = int(rng.integers(1, 4))
    caps = rng.choice([0.0, 0.5, 1.0, 2.0], size=(n, k))
    payloads = rng.choice([0.0, 1.0, 2.5], size=n)
    need = rng.choice([0.0, 1.0, 2.0, 3.0], size=k)
    arrival = np.where(rng.random(n) < 0.2, np.inf, rng.choice([0.0, 1.0, 2.0, 3.5, 4.0], size=n))
    pol = GreedyPayloadPolicy()
    pol.traits_from = 0 if rng.random() < 0.5 else None
    need_payload = float(rng.choice([0.0, 2.0]))
    assert pol.pick_reachable(caps, payloads, need, need_payload, arrival, roles) == \
        _pick_reachable_by_every_limit(pol, caps, payloads, need, need_payload, arrival, roles)


def test_randomized_grp_is_seeded_and_valid_and_without_noise_is_grp():
    from lvws_ros.core.families import family_instance
    from lvws_ros.policies.baselines import GreedyPayloadPolicy

    inst = family_instance("warehouse", 1, 0, num_robots=20, num_tasks=48)
    plain = simulate(inst, GreedyPayloadPolicy(priority="critical-path")).schedule
    assert simulate(inst, GreedyPayloadPolicy(priority="critical-path", noise=0.0, seed=5)).schedule.assignments == \
        plain.assignments
    runs = [simulate(inst, GreedyPayloadPolicy(priority="critical-path", noise=0.5, seed=s)).schedule for s in (1, 1, 2)]
    assert runs[0].assignments == runs[1].assignments
    assert all(check_schedule(inst, s) == [] for s in runs)
    with pytest.raises(PolicyError, match="noise"):
        GreedyPayloadPolicy(noise=-1.0)


class _GrpPickByPick(GreedyPayloadPolicy):
    """GRP asking for the lightest cover task by task, always in arrays (no CoverPool)."""

    def pool(self, inst, free):
        return None

    def pick(self, caps, payloads, need_caps, need_payload, roles=False):
        if len(caps) == 0 or not covers(caps, payloads, need_caps, need_payload, roles):
            return None
        return _array_cover(caps, payloads, need_caps, need_payload, roles, self.traits_from)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 60), m=st.integers(1, 40),
       family=st.sampled_from(["paper", "subteam-heavy", "fractional"]), priority=st.sampled_from(PRIORITIES))
def test_grp_from_its_cover_pool_decides_as_grp_pick_by_pick(seed, n, m, family, priority):
    """GRP's decisions from one CoverPool per decision (robots leaving it as they are
    given tasks) are those of asking for the lightest cover in arrays over the robots
    left each time, step by step through whole schedules (payloads that are not whole
    take the arrays in both)."""
    rng = np.random.default_rng(seed)
    if family == "subteam-heavy":
        inst = subteam_heavy_instance(rng, n, m, "s")
    else:
        inst = random_instance(rng, n, m, "h")
        if family == "fractional":
            inst = dataclasses.replace(inst, robots=tuple(dataclasses.replace(r, payload=r.payload + 0.25)
                                                          for r in inst.robots))
    pooled = simulate(inst, GreedyPayloadPolicy(priority=priority))
    by_pick = simulate(inst, _GrpPickByPick(priority=priority))
    assert [s.decision.assignments for s in pooled.steps] == [s.decision.assignments for s in by_pick.steps]
