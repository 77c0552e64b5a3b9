"""The paper's Table I set-up (section 6.1.1): one instance of each target in the home."""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass
from typing import Any

from .errors import BuildError
from .home import SourceHome
from .vocabulary import SEMI_DYNAMIC_NAMES

# "we removed the bowl, laptop, and pillow in the living room, phone, and vase in the bedroom and
# kept only one Toilet paper in the bathroom" -- as (room, class) pairs.
TABLE1_REMOVE_ALL: tuple[tuple[str, str], ...] = (
    ("living", "Bowl"),
    ("living", "Laptop"),
    ("living", "Pillow"),
    ("bedroom", "Phone"),
    ("bedroom", "Vase"),
)
TABLE1_KEEP_ONE: tuple[tuple[str, str], ...] = (("bathroom", "ToiletPaper"),)

NOTES = (
    "Paper section 6.1.1: 'we removed the bowl, laptop, and pillow in the living room, phone, and "
    "vase in the bedroom and kept only one Toilet paper in the bathroom'. Every instance of those "
    "classes in those rooms is removed; of the bathroom's toilet paper the first by sorted id is "
    "kept. 'targets' is the one instance of each class left in the home."
)


@dataclass(frozen=True)
class Scenario:
    home: str
    name: str
    removed: tuple[str, ...]
    targets: dict[str, str]  # class -> the remaining instance id

    def to_json(self) -> dict[str, Any]:
        return {
            "format": "objsearch.scenario/1",
            "home": self.home,
            "name": self.name,
            "notes": NOTES,
            "removed": list(self.removed),
            "targets": self.targets,
        }


def table1(home: SourceHome) -> Scenario:
    by_room_cls: dict[tuple[str, str], list[str]] = defaultdict(list)
    for room in home.rooms:
        for obj in room.objects:
            by_room_cls[(room.name, obj.cls)].append(obj.id)
    removed: set[str] = set()
    for key in TABLE1_REMOVE_ALL:
        removed.update(by_room_cls[key])
    for key in TABLE1_KEEP_ONE:
        removed.update(sorted(by_room_cls[key])[1:])
    left: dict[str, list[str]] = defaultdict(list)
    for obj in home.objects:
        if obj.id not in removed:
            left[obj.cls].append(obj.id)
    wrong = {c: left.get(c, []) for c in SEMI_DYNAMIC_NAMES if len(left.get(c, [])) != 1}
    if wrong:
        raise BuildError(
            f"home {home.name!r}: after the Table I removals each target must have exactly one "
            f"instance, but: {wrong}"
        )
    return Scenario(
        home=home.name,
        name="table1",
        removed=tuple(sorted(removed)),
        targets={c: left[c][0] for c in SEMI_DYNAMIC_NAMES},
    )
