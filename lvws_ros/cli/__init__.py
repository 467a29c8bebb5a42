"""The ``lvws`` command (:mod:`lvws_ros.cli.main`), the paper's tables, bag reports,
Gantt charts and benchmarks: the top layer, above ROS, learning and the simulator."""
