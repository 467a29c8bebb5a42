"""The scheduler node's garbage collection paced by its decisions: what is alive after a
decision is frozen (a collection inside the next decision does not scan it), and every
FULL_COLLECTION_EVERY decisions everything is collected, so a cycle that became garbage
after it was frozen is freed then, not leaked."""

from __future__ import annotations

import gc
import weakref

from lvws_ros.ros.scheduler_node import FULL_COLLECTION_EVERY, collect_after_decision


class Node:
    def __init__(self) -> None:
        self.me = self  # a cycle: only the collector frees it


def test_a_cycle_frozen_after_a_decision_is_freed_at_the_next_full_collection() -> None:
    try:
        cycle = Node()
        gone = weakref.ref(cycle)
        collect_after_decision(1)
        assert gc.get_freeze_count() > 0
        del cycle
        gc.collect()
        assert gone() is not None  # frozen: the collections between decisions leave it
        for step in range(2, FULL_COLLECTION_EVERY + 1):
            collect_after_decision(step)
        assert gone() is None
    finally:
        gc.unfreeze()
