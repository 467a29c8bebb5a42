"""ROS 2 (the only place importing rclpy and lvws_msgs): topics and QoS, the one
message <-> snapshot conversion, the scheduler, simulator and recorder nodes, replay,
bag access and the launcher."""
