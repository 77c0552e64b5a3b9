from __future__ import annotations

from pathlib import Path

import pytest

from objsearch.ros.errors import TopicMapError
from objsearch.ros.topics import DEFAULT_TOPICS, Role, TopicMap
from objsearch.ros.types import Distro, message_definitions, typestore


def test_msg_files_are_package_data_and_register() -> None:
    defs = message_definitions()
    assert {"objsearch_msgs/msg/Event", "vision_msgs/msg/Detection2DArray"} <= set(defs)
    for distro in Distro:
        store = typestore(distro)
        for name in defs:
            assert name in store.fielddefs, (distro, name)
    fields = [f[0] for f in typestore(Distro.ROS2).fielddefs["objsearch_msgs/msg/Event"][1]]
    assert fields[:3] == ["header", "event_id", "stream"] and "payload_json" in fields


def test_default_map_has_every_role() -> None:
    assert set(DEFAULT_TOPICS.values()) == set(Role)


def test_toml_and_json_overrides(tmp_path: Path) -> None:
    toml = tmp_path / "t.toml"
    toml.write_text(
        '[topics]\n"/odometry/filtered" = "odometry"\n"/odom" = "ignore"\n[frames]\nbase = "base_footprint"\n'
    )
    m = TopicMap.load(toml)
    assert m.role("/odometry/filtered") is Role.ODOMETRY and m.role("/odom") is None
    assert m.frames.base == "base_footprint" and m.role("/tf") is Role.TF
    js = tmp_path / "t.json"
    js.write_text('{"topics": {"/dets": "detections"}}')
    assert TopicMap.load(js).role("/dets") is Role.DETECTIONS


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ('[topics]\n"/x" = "lidar"\n', "unknown role 'lidar'"),
        ('[topics]\n"x" = "tf"\n', "must be a string starting with '/'"),
        ("[frames]\nworld = 'w'\n", "frames takes"),
        ("[extra]\n", "unknown section"),
        ("topics = [", "not valid"),
    ],
)
def test_bad_topic_maps_are_refused(tmp_path: Path, text: str, match: str) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(TopicMapError, match=match):
        TopicMap.load(path)
    with pytest.raises(TopicMapError, match="cannot read"):
        TopicMap.load(tmp_path / "missing.toml")
