"""The ROS message layer the offline pipeline and the on-robot runtime share.

The typestore (rosbags' standard stores plus the repository's ``.msg`` files), the topic map and
frame names, the builders of the messages the robot publishes (odometry, TF, detections, the
agent's events), a TF buffer, the QoS profiles and the rosbag2 MCAP writer. It knows the agent's
records (poses, detections, events) and nothing of the simulator, the pipeline or the runtime.
"""
