"""The QoS profiles a ROS 2 bag records for each topic, as rosbag2 stores them.

``ros2 bag play`` publishes each topic with the reliability and durability of the profiles the
bag says its publishers offered (``offered_qos_profiles`` in ``metadata.yaml`` and in each MCAP
channel's metadata). A topic recorded with none (``[]``) is played volatile: ``/tf_static`` then
never reaches a tf2 listener that starts after its one message. So every topic we write carries
the profile the robot's publisher uses (:mod:`objsearch.ros.qos`, tf2_ros's and rclcpp's
defaults).

rosbags writes them in the format of the bag's metadata version: version 9 (Jazzy) names the
policies (``keep_last``, ``reliable``, ``transient_local``) in a YAML list; version 8 (ours,
:data:`~objsearch.ros.mcapstore.METADATA_VERSION`) and earlier a YAML string with rmw's
enum values (history keep_last 1, reliability reliable 1 / best_effort 2, durability
transient_local 1 / volatile 2, liveliness automatic 1), as the bags in rosbag2's own tests.
Durations not set are rmw's infinite duration (``RMW_DURATION_INFINITE``: 9223372036 s
854775807 ns), as rosbag2 records them since Iron.

Unlike a recording of a live system, whose profiles come from discovery (history unknown,
depth 0), these are the publishers' own, history and depth included.
"""

from __future__ import annotations

from typing import Final

from rosbags.interfaces import (
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)

from objsearch.ros import qos as rq

INFINITE: Final = QosTime(9_223_372_036, 854_775_807)


def profile(q: rq.QoS) -> Qos:
    """The rosbag2 profile of one of the runtime's KEEP_LAST profiles."""
    return Qos(
        history=QosHistory.KEEP_LAST,
        depth=q.depth,
        reliability=(
            QosReliability.RELIABLE
            if q.reliability is rq.Reliability.RELIABLE
            else QosReliability.BEST_EFFORT
        ),
        durability=(
            QosDurability.TRANSIENT_LOCAL
            if q.durability is rq.Durability.TRANSIENT_LOCAL
            else QosDurability.VOLATILE
        ),
        deadline=INFINITE,
        lifespan=INFINITE,
        liveliness=QosLiveliness.AUTOMATIC,
        liveliness_lease_duration=INFINITE,
        avoid_ros_namespace_conventions=False,
    )


#: rclcpp's ``QoS(10)``: reliable, volatile, depth 10.
DEFAULT: Final = profile(rq.DEFAULT)
#: tf2_ros's StaticTransformBroadcaster: reliable, transient local, depth 1.
TF_STATIC: Final = profile(rq.TF_STATIC)
#: tf2_ros's TransformBroadcaster: reliable, volatile, depth 100.
TF: Final = profile(rq.TF)
#: The agent's event stream (every append; a late subscriber replays the log instead).
EVENTS: Final = profile(rq.EVENTS)
#: A map server's map and other once-sent state: latched (reliable, transient local, depth 1).
LATCHED: Final = profile(rq.LATCHED)
