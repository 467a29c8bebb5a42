"""The planner (above the models it runs): one whole plan, dispatched from at once and
improved while the robots work (``planner``), its repair and dispatch (``follow``), its
process beside a node (``worker``), and ``auto`` as its face (``auto``); ``auto`` within a
budget per decision step (``budgeted``); a quick plan for robots that set out on their
own (``ahead``)."""

PLANNER_NICENESS = 10  # the planner's process runs this far below its parent's CPU priority (os.nice): decisions first
