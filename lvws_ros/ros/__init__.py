"""ROS 2 shells around the core: nodes, recorder, launcher. Only this sub-package imports rclpy."""
