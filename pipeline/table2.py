"""The paper's Table II (section 6.1.2): where each target is in each of ten scenes."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from objsearch.agent.geometry import Vec3

from .errors import BuildError
from .home import SourceHome
from .room_objects import Static
from .scenario import Scenario
from .vocabulary import SEMI_DYNAMIC_NAMES, STATIC_NAMES


def _row(cells: str) -> tuple[str, ...]:
    return tuple(cells.split())


# Transcribed from the paper's Table II, one row per target, scenes 1-10; the paper's "Bad" is Bed.
TABLE2: dict[str, tuple[str, ...]] = {
    "Apple": _row("Sink   Sink   Sink   Sink   Fridge Fridge Fridge Fridge Table  Table"),
    "Cup": _row("Table  Table  Sink   Sink   Sink   Table  Table  Sink   Sink   Table"),
    "Bowl": _row("Table  Sink   Sink   Table  Table  Table  Sink   Sink   Table  Table"),
    "Phone": _row("Table  Table  Table  Desk   Desk   Desk   Desk   Table  Table  Table"),
    "Laptop": _row("Sofa   Sofa   Bed    Bed    Bed    Table  Table  Table  Desk   Desk"),
    "Pillow": _row("Bed    Bed    Bed    Bed    Sofa   Sofa   Bed    Bed    Bed    Bed"),
    "Vase": _row("Shelf  Shelf  Shelf  Table  Table  Table  Shelf  Shelf  Shelf  Shelf"),
    "ToiletPaper": _row("Toilet Toilet Toilet Toilet Shelf  Shelf  Shelf  Toilet Toilet Toilet"),
}
SCENES = 10

NOTES = (
    "Paper Table II ('Bad' read as Bed). Each class is resolved to one static instance of the "
    "home: the instance of that static class whose box center is nearest (3-D) to where the object "
    "was in the previous scene (for scene 1: its position in the Table I scenario); ties go to the "
    "smallest id. center: the support's rest point (where AI2-THOR rests pickupable objects on or "
    "in it) nearest the previous position where it overlaps no object placed before it in the scene "
    "(in the order of the table's rows), raised by half the object's own height; a support "
    "without rest points: a container's box center, else x, y of the support's box center and z = "
    "box top + half the object's height (or, when an object already lies there, the nearest free "
    "point of a 3 x 3 grid over the top). 'object' is the Table I instance that is moved."
)


@dataclass(frozen=True)
class Table2Placement:
    object: str
    static_class: str
    support: str
    inside: bool
    center: Vec3

    def to_json(self) -> dict[str, Any]:
        return {
            "object": self.object,
            "static_class": self.static_class,
            "support": self.support,
            "inside": self.inside,
            "center": self.center,
        }


def _check_table() -> None:
    # The table is data typed by hand; a typo must fail the build, not produce a silent gap.
    if set(TABLE2) != set(SEMI_DYNAMIC_NAMES):
        raise BuildError(f"Table II rows {sorted(TABLE2)} differ from the targets")
    for cls, row in TABLE2.items():
        if len(row) != SCENES or not set(row) <= set(STATIC_NAMES):
            raise BuildError(f"Table II row {cls}: {row} is not {SCENES} static classes")


def place_on(
    support: Static,
    obj_size: Vec3,
    previous: Vec3,
    taken: Sequence[tuple[Vec3, Vec3]] = (),
) -> Vec3:
    """Where an object of size ``obj_size`` goes on/in ``support``.

    On the support's rest point nearest the object's previous position when AI2-THOR rests
    anything there (so an object returning to its own support returns to its own spot), leaving
    out rest points where its footprint would overlap an object already placed (``taken``: centre
    and size of each) — two objects on one spot lie inside each other and the one hides the other from
    every view; otherwise the container's centre, or the top of the support's box above its centre.
    """
    half = obj_size[2] / 2

    def free(spots: list[Vec3]) -> list[Vec3]:
        return [
            p
            for p in spots
            if not any(
                abs(c[0] - p[0]) < (size[0] + obj_size[0]) / 2
                and abs(c[1] - p[1]) < (size[1] + obj_size[1]) / 2
                for c, size in taken
            )
        ]

    c, s = support.box.center, support.box.size
    top = c[2] + s[2] / 2 + half
    # When every spot is taken: the nearest free point of a 3 × 3 grid over the top (a sink
    # basin holding an apple, a cup and a bowl; a bed with two rest points and three objects).
    grid = [(c[0] + i * s[0] / 4, c[1] + j * s[1] / 4, top) for i in (-1, 0, 1) for j in (-1, 0, 1)]
    grid.sort(key=lambda p: (math.dist(p, (c[0], c[1], top)), p))
    if support.rest_points:
        spots = [(x, y, z + half) for x, y, z in support.rest_points]
        open_spots = free(spots)
        if open_spots or not free(grid):
            return min(open_spots or spots, key=lambda p: (math.dist(p, previous), p))
        return free(grid)[0]
    if support.container:
        return c
    return (free(grid) or grid)[0]


def table2(home: SourceHome, scenario: Scenario) -> dict[str, Any]:
    _check_table()
    objects = {o.id: o for o in home.objects}
    where = {cls: objects[oid].box.center for cls, oid in scenario.targets.items()}
    scenes = []
    for k in range(SCENES):
        placements: dict[str, Table2Placement] = {}
        for cls in SEMI_DYNAMIC_NAMES:
            wanted = TABLE2[cls][k]
            options = [s for s in home.statics if s.cls == wanted]
            if not options:
                raise BuildError(
                    f"home {home.name!r} has no {wanted}, needed by Table II ({cls}, scene {k + 1})"
                )
            prev = where[cls]
            support = min(options, key=lambda s: (math.dist(s.box.center, prev), s.id))
            obj = objects[scenario.targets[cls]]
            taken = [
                (q.center, objects[q.object].box.size)
                for q in placements.values()
                if q.support == support.id
            ]
            center = place_on(support, obj.box.size, prev, taken)
            placements[cls] = Table2Placement(obj.id, wanted, support.id, support.container, center)
            where[cls] = center
        scenes.append(
            {"scene": k + 1, "placements": {c: p.to_json() for c, p in placements.items()}}
        )
    return {
        "format": "objsearch.schedule/1",
        "home": home.name,
        "name": "table2",
        "scenario": scenario.name,
        "notes": NOTES,
        "scenes": scenes,
    }
