"""The scheduling core (numpy only, no ROS, torch, OR-Tools or pymunk): problem model,
the two file formats, the schedule rules, subteam coverage (Eqs. 10-11), matching
(Eqs. 7-11), the executor, online scheduling, datasets and metrics."""
