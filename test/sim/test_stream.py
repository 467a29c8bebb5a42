"""The stream world: a cell that never stops, followed through its change batches, is the
world's cell at every tick; done work retires and never comes back; every task is accounted
for and none is assigned twice; the live cell stays bounded however many tasks are done."""

from __future__ import annotations

from lvws_ros.core.changes import ChangeFollower
from lvws_ros.core.executor import TaskStatus
from lvws_ros.core.online import OnlineScheduler
from lvws_ros.policies.baselines import GreedyPayloadPolicy
from lvws_ros.sim.stream import StreamWorld


def test_a_stream_followed_by_its_changes_is_the_world_and_every_task_is_accounted_for() -> None:
    world = StreamWorld(60, 0.4, seed=1)
    follower = ChangeFollower()
    follower.resync(*world.snapshots(), 0)
    core = OnlineScheduler(GreedyPayloadPolicy(), ack_timeout=1e9)
    started: set[str] = set()
    retired: set[str] = set()
    live = []
    for seq in range(1, 300):
        world.advance()
        batch = world.changes(seq)
        retired |= set(batch.retired)
        follower.take(batch)
        assert follower.cell is not None and not follower.needs_resync
        team, graph = follower.cell.snapshots()
        # in the world's order too: a node that resyncs holds the cell as one that followed
        # (policies break ties by the order; the resync's answer is not in the bag)
        assert graph.tasks == world.snapshots()[1].tasks
        assert [(r.id, r.available, r.current_task) for r in team.robots] == \
            [(r.id, r.available, r.current_task) for r in world.snapshots()[0].robots]
        core.offer_team(team)
        core.offer_graph(graph)
        decision = core.decide()
        for task, robots in decision.assignments if decision else ():
            assert task not in started
            started.add(task)
            world.assign(task, robots)
        live.append(world.live)
    c = world.counts
    assert c.done > 500 and c.retired > 400 and c.rejected == 0
    assert c.added == c.done + sum(1 for t in world.tasks.values() if t.status != TaskStatus.DONE)
    assert not retired & set(follower.cell.tasks)  # a retired task never comes back
    assert max(live[150:]) < 2 * max(live[:150]) + 50  # bounded: it does not grow with the tasks done
