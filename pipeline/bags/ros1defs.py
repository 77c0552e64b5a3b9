"""ROS 1 connection definitions as ``rosbag record`` stores them: the ``.msg`` text, comments and all.

A ROS 1 bag's connection record carries the message's full definition: the ``.msg`` file's text,
then each type it embeds (depth first, each once) as a line of 80 ``=``, ``MSG: pkg/Type`` and
that type's text — genmsg's ``compute_full_text``. rosbags generates the definition from its
typestore, which has the fields but not the comments; the MD5 is the same, but ``rosbag check``
compares the text with the installed message's and asks for a migration between identical MD5s.
So the texts come from the ``.msg`` files: ROS 1 Noetic's standard ones (``msg_noetic/``) and the
repository's own (``msg/``).
"""

from __future__ import annotations

from functools import cache
from importlib import resources
from typing import TYPE_CHECKING, Any

from objsearch.ros.msgfiles import read_msg_folder
from objsearch.ros.types import message_definitions

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

NOETIC_ROOT = "msg_noetic"
SEPARATOR = "=" * 80
#: ROS 1's builtin ``time`` and ``duration``, which rosbags' typestore spells as these messages.
BUILTINS = frozenset({"builtin_interfaces/msg/Time", "builtin_interfaces/msg/Duration"})


@cache
def msg_texts() -> dict[str, str]:
    """``{"pkg/msg/Name": .msg text}``: Noetic's standard files, then the repository's own."""
    found = read_msg_folder(resources.files(__package__).joinpath(NOETIC_ROOT))
    for name, text in message_definitions().items():
        found.setdefault(name, text)  # tf2_msgs/TFMessage: Noetic's text, not our annotated copy
    return found


def _embedded(store: Typestore, msgtype: str) -> list[str]:
    """The types ``msgtype``'s fields embed, in field order, each once (genmsg's depends)."""
    out: list[str] = []
    fields: Any = store.fielddefs[msgtype][1]
    for _, (kind, detail) in fields:
        # A field is (NODETYPE, detail); arrays and sequences hold their element in detail[0].
        inner = detail[0] if kind.name in ("ARRAY", "SEQUENCE") else (kind, detail)
        ikind, idetail = inner
        if ikind.name == "NAME" and idetail not in BUILTINS and idetail not in out:
            out.append(idetail)
    return out


def full_definition(store: Typestore, msgtype: str) -> str | None:
    """genmsg's full text of ``msgtype`` from the ``.msg`` files, or None if one is missing
    (the caller falls back to rosbags' generated definition)."""
    texts = msg_texts()
    order: list[str] = []

    def walk(name: str) -> None:
        for dep in _embedded(store, name):
            order.append(dep)
            walk(dep)

    walk(msgtype)
    unique = list(dict.fromkeys(order))
    if msgtype not in texts or any(d not in texts for d in unique):
        return None
    parts = [texts[msgtype], "\n"]
    for dep in unique:
        parts += [SEPARATOR, "\n", f"MSG: {_ros1_name(dep)}\n", texts[dep], "\n"]
    return "".join(parts)[:-1]


def _ros1_name(msgtype: str) -> str:
    """``pkg/msg/Name`` → ``pkg/Name``, as ROS 1 writes it."""
    package, _, name = msgtype.partition("/msg/")
    return f"{package}/{name}"
