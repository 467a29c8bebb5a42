"""What ros and robot share of rclpy, below both: the check of a namespace
(:mod:`lvws_ros.rosbase.names`) and one turn of an executor (:mod:`lvws_ros.rosbase.spin`)."""
