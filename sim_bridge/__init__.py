"""sim_bridge: the PyBullet arm and pinhole camera (ROS-free core) and its ROS 2 node."""
