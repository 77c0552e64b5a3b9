"""``objsearch agent replay BAG``'s bad input: a bag that holds no agent session is a clear
error (exit 2), not a traceback or a silent "same". The replay of a real session is tested end to
end in tests/runtime/test_detections_in.py."""

from __future__ import annotations

from pathlib import Path

import pytest
from rosbags.rosbag2 import StoragePlugin

from objsearch.agent.geometry import Pose
from objsearch.cli import main
from objsearch.ros.mcapstore import rosbag2_writer
from objsearch.runtime import messages as m


def test_a_bag_without_the_agent_s_events_is_a_clear_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = tmp_path / "odometry-only"
    writer = rosbag2_writer(bag, StoragePlugin.MCAP)
    writer.open()
    conn = writer.add_connection("/odom", m.ODOMETRY, typestore=m.store())
    for i in range(3):
        writer.write(conn, i, m.encode(m.odometry(Pose(1.0, 2.0, 0.0), i * 10**9), m.ODOMETRY))
    writer.close()
    assert main(["agent", "replay", str(bag), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("objsearch: error: ") and "no agent events" in err, err


def test_a_missing_bag_is_a_usage_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["agent", "replay", str(tmp_path / "nothing")]) == 2
    assert "no such file or folder" in capsys.readouterr().err
