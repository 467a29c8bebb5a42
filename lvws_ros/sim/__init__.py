"""The assembly-cell case study as a pymunk world (no ROS): its configuration, the
world, an offline runner and rendering."""
