"""The shipped RViz2 config names live channels that exist, each with a display for its type and
the QoS it is published with (RViz2 itself cannot be run here: no display, no wheel)."""

from __future__ import annotations

from importlib.resources import files

import yaml

from objsearch.runtime import liveview as lv

DISPLAY_FOR = {
    lv.OCCUPANCY_GRID: "rviz_default_plugins/Map",
    lv.MARKER_ARRAY: "rviz_default_plugins/MarkerArray",
    lv.PATH: "rviz_default_plugins/Path",
    "geometry_msgs/msg/PoseStamped": "rviz_default_plugins/Pose",
}


def test_rviz_config_shows_the_live_channels() -> None:
    text = (files("objsearch.runtime") / "rviz" / "objsearch.rviz").read_text()
    config = yaml.safe_load(text)
    manager = config["Visualization Manager"]
    assert manager["Global Options"]["Fixed Frame"] == "map"
    shown = {d["Topic"]["Value"]: d for d in manager["Displays"] if "Topic" in d}
    drawable = {t for t, msgtype in lv.CHANNELS.items() if msgtype in DISPLAY_FOR}
    assert set(shown) == drawable  # detections (vision_msgs) are drawn as their markers
    for topic, display in shown.items():
        assert display["Class"] == DISPLAY_FOR[lv.CHANNELS[topic]], topic
        latched = topic in (lv.MAP, lv.STATICS)
        want = "Transient Local" if latched else "Volatile"
        assert display["Topic"]["Durability Policy"] == want, topic
        assert display["Topic"]["Reliability Policy"] == "Reliable", topic
