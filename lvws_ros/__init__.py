"""lvws_ros: heterogeneous multi-robot scheduling with dynamic subteaming and voluntary waiting.

The core modules (model, schedule, executor, matching, expert, policies, datasets,
metrics) import no ROS package; the ROS 2 nodes live in :mod:`lvws_ros.ros`.
"""

__version__ = "0.1.0"
