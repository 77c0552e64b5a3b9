"""A folder of ROS ``.msg`` files read as the typestore names them.

The layout is ROS's own, ``<package>/msg/<Name>.msg``, and each file becomes ``pkg/msg/Name``
(rosbags' spelling). Two folders are read this way: the repository's own definitions
(``ros/msg/``, :func:`objsearch.ros.types.message_definitions`) and ROS 1 Noetic's standard ones
the ROS 1 bag writer quotes (``pipeline/bags/msg_noetic/``); one reader keeps them named alike.
"""

from __future__ import annotations

from importlib.resources.abc import Traversable
from pathlib import Path


def read_msg_folder(root: Path | Traversable) -> dict[str, str]:
    """``{"pkg/msg/Name": .msg text}`` for every ``<package>/msg/<Name>.msg`` under ``root``,
    sorted by package then name; a package folder without ``msg/`` is skipped."""
    found: dict[str, str] = {}
    for package in sorted(root.iterdir(), key=lambda p: p.name):
        msg_dir = package.joinpath("msg")
        if not msg_dir.is_dir():
            continue
        for entry in sorted(msg_dir.iterdir(), key=lambda p: p.name):
            if entry.name.endswith(".msg"):
                name = f"{package.name}/msg/{entry.name.removesuffix('.msg')}"
                found[name] = entry.read_text(encoding="utf-8")
    return found
