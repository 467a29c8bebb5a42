"""lvws_ros: heterogeneous multi-robot scheduling with dynamic subteaming and voluntary waiting.

Layers, top to bottom, as ``.importlinter`` holds them (imports point down only, and the
two layers sharing a line do not import each other; ``make lint`` enforces it)::

    cli             the lvws command, paper tables, bag reports, Gantt charts, benchmarks
    ros | robot     rclpy: topics, conversion, nodes, recorder, replay, bags, launcher | the robots' action servers
    rosbase         what ros and robot share of rclpy: the namespace check, one turn of an executor
    registry        policy names -> policies
    planning        the planner, dispatch from its plan, its worker process; auto (whole-run and per decision)
    learning | sim  torch only here: features, GATN, loss, training, learned policies | pymunk world of the case study
    policies        baselines; exact, LNS and the cumulative model (OR-Tools only here)
    core            numpy only: problem, formats, schedule rules, subteams, matching, executor, online
    errors          LvwsError and its subclasses

The paper's equations, where they live:

==========  ==========================================================================
Eq. 1-2     GAT layer (attention weights, aggregation): learning/gatn.py:GATLayer.forward
Eq. 3-5     transformer for the global embedding: learning/gatn.py:GlobalAttention.forward
Eq. 6       reward MLP R_ij = psi(h_i^r, h_j^t, g^r, g^t): learning/gatn.py:GATN.forward
Eq. 7       maximise sum A_ij R_ij: core/matching.py:greedy_match (exact: policies/exact.py:exact_match)
Eq. 8-9     one task (or the idle task) per robot: core/matching.py:greedy_match,
            core/executor.py:check_decision
Eq. 10-11   subteam covers capabilities and payload: core/subteams.py:shortfall / covered / covers
Eq. 12      imitation loss with E and X: learning/loss.py:imitation_loss, learning/loss.py:feasibility_mask,
            expert rewards E: learning/demonstrations.py:label_state
==========  ==========================================================================
"""

__version__ = "0.1.0"
