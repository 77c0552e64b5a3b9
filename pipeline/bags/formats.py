"""The three bag formats and how to tell them apart on disk."""

from __future__ import annotations

import enum
from pathlib import Path

from objsearch.pipeline.bags.errors import BagError
from objsearch.ros.types import Distro

ROS1_MAGIC = b"#ROSBAG V2.0\n"
MCAP_MAGIC = b"\x89MCAP0\r\n"
SQLITE_MAGIC = b"SQLite format 3\x00"


class BagFormat(enum.Enum):
    ROS1 = "ros1"
    ROS2_SQLITE3 = "ros2-sqlite3"
    ROS2_MCAP = "ros2-mcap"

    @property
    def distro(self) -> Distro:
        return Distro.ROS1 if self is BagFormat.ROS1 else Distro.ROS2

    @classmethod
    def parse(cls, name: str) -> BagFormat:
        try:
            return cls(name)
        except ValueError:
            raise BagError(
                f"unknown bag format {name!r}; choose one of: {', '.join(f.value for f in cls)}"
            ) from None


def storage_files(path: Path) -> list[Path]:
    """The files holding a bag's bytes: the ``.bag`` file, or a ROS 2 directory's storage files."""
    if path.is_file():
        return [path]
    return sorted(p for p in path.iterdir() if p.suffix in (".db3", ".mcap"))


def detect(path: Path) -> BagFormat:
    """The format of the bag at ``path`` (a ``.bag`` file or a ROS 2 bag directory), by content."""
    if not path.exists():
        raise BagError(f"no bag at {path}: no such file or directory")
    files = storage_files(path) if path.is_dir() else [path]
    if not files:
        raise BagError(
            f"{path} is a directory without .db3 or .mcap files: not a ROS 2 bag"
            + ("" if (path / "metadata.yaml").exists() else " (and no metadata.yaml)")
        )
    with files[0].open("rb") as fh:
        head = fh.read(16)
    if head.startswith(ROS1_MAGIC[:-1]):
        if not head.startswith(ROS1_MAGIC):
            raise BagError(f"{files[0]} is a ROS 1 bag of an unsupported version: {head!r}")
        return BagFormat.ROS1
    if head.startswith(MCAP_MAGIC):
        return BagFormat.ROS2_MCAP
    if head.startswith(SQLITE_MAGIC):
        return BagFormat.ROS2_SQLITE3
    raise BagError(
        f"{files[0]} is not a ROS bag: its first bytes {head[:16]!r} are neither ROS 1 "
        "('#ROSBAG V2.0'), MCAP nor SQLite"
    )
