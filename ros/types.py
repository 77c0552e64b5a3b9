"""The message types the robot speaks that no rosbags typestore carries, from ``.msg`` text.

The definitions live in ``msg/<package>/msg/<Name>.msg`` beside this module (package data):
``objsearch_msgs/Event`` (the agent's events), ``vision_msgs`` detections (ROS 2 4.x layout) and
``tf2_msgs/TFMessage`` (missing from the Noetic store).
"""

from __future__ import annotations

import enum
from functools import cache
from importlib import resources
from typing import TYPE_CHECKING

from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from objsearch.ros.msgfiles import read_msg_folder

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

MSG_ROOT = "msg"


class Distro(enum.Enum):
    """Which ROS the bag's robot runs: decides the standard types and the wire format."""

    ROS1 = "ros1"
    ROS2 = "ros2"

    @property
    def store(self) -> Stores:
        return Stores.ROS1_NOETIC if self is Distro.ROS1 else Stores.ROS2_HUMBLE


def message_definitions() -> dict[str, str]:
    """``{"pkg/msg/Name": msg text}`` for every ``.msg`` file kept in the repository."""
    root = resources.files(__package__).joinpath(MSG_ROOT)
    found = read_msg_folder(root)
    if not found:
        raise RuntimeError(f"no .msg files found under {root}: the package data is missing")
    return found


@cache
def typestore(distro: Distro) -> Typestore:
    """The distro's standard typestore plus the repository's own definitions.

    A definition the store already has (``tf2_msgs/TFMessage`` on ROS 2) is kept from the store,
    so hashes match what a real ROS 2 robot writes.
    """
    store = get_typestore(distro.store)
    extra: dict[str, object] = {}
    for name, text in message_definitions().items():
        if name in store.fielddefs:
            continue
        extra.update(get_types_from_msg(text, name))
    store.register(extra)  # type: ignore[arg-type]
    return store
