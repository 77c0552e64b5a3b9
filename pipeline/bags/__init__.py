"""ROS bags: the robot's interface (message definitions, topic map), recording simulated runs to
bags, reading bags of any format into events, salvaging damaged bags, ingesting into the lake.

See ``docs/pipeline.md``.
"""
