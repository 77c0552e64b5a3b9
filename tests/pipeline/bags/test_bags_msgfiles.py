"""One reader of ``.msg`` folders serves both the repository's definitions (``ros/msg/``) and the
Noetic texts the ROS 1 bag writer quotes (``pipeline/bags/msg_noetic/``)."""

from __future__ import annotations

from importlib import resources
from pathlib import Path

import pytest

from objsearch.pipeline.bags.ros1defs import NOETIC_ROOT, msg_texts
from objsearch.ros.msgfiles import read_msg_folder
from objsearch.ros.types import MSG_ROOT, message_definitions

ROS_MSG = Path(str(resources.files("objsearch.ros").joinpath(MSG_ROOT)))
NOETIC_MSG = Path(str(resources.files("objsearch.pipeline.bags").joinpath(NOETIC_ROOT)))


def _every_msg_file(root: Path) -> dict[str, str]:
    """Every ``.msg`` file anywhere under ``root``, named by its path: a file outside
    ``<package>/msg/`` gets a name the reader cannot give, so a missed file shows."""
    return {
        "/".join(p.relative_to(root).with_suffix("").parts): p.read_text(encoding="utf-8")
        for p in root.rglob("*.msg")
    }


@pytest.mark.parametrize("root", [ROS_MSG, NOETIC_MSG], ids=["ros", "noetic"])
def test_the_reader_finds_every_msg_file_under_the_folder(root: Path) -> None:
    expected = _every_msg_file(root)
    assert expected, f"no .msg files under {root}"
    assert read_msg_folder(root) == expected


def test_both_users_read_through_it() -> None:
    assert message_definitions() == read_msg_folder(ROS_MSG)
    assert msg_texts() == read_msg_folder(ROS_MSG) | read_msg_folder(NOETIC_MSG)


def test_other_files_and_folders_are_skipped(tmp_path: Path) -> None:
    (tmp_path / "pkg" / "msg").mkdir(parents=True)
    (tmp_path / "pkg" / "msg" / "Thing.msg").write_text("int32 x\n", encoding="utf-8")
    (tmp_path / "pkg" / "msg" / "notes.txt").write_text("not a message\n", encoding="utf-8")
    (tmp_path / "pkg" / "srv").mkdir()
    (tmp_path / "pkg" / "srv" / "Ask.srv").write_text("---\n", encoding="utf-8")
    (tmp_path / "nomsg").mkdir()
    (tmp_path / "README.md").write_text("# folder\n", encoding="utf-8")
    assert read_msg_folder(tmp_path) == {"pkg/msg/Thing": "int32 x\n"}
