"""ROS 2 (rclpy and lvws_msgs are imported here, in robot and in rosbase only): topics and
QoS, the one message <-> snapshot conversion, the scheduler, simulator and recorder nodes,
replay, bag access and the launcher."""
