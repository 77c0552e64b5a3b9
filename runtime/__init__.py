"""The on-robot runtime: the agent as a ROS 2 participant over Zenoh (rmw_zenoh) or Cyclone DDS."""
