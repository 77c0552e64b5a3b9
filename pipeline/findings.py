"""What a build finds wrong with a home, and which of those findings a build may go ahead with.

A home can convert without an error and still be a poor place to search: a room that lost most of
its grid points to furniture, a ProcTHOR room cut off from the rest of the house, a room without a
single static object to search at. The build names each as a :class:`Finding` and refuses to write
anything while one is not accepted (``objsearch data build --accept KIND,...``). A room whose
viewpoints fall into pieces is refused with its own error (:class:`SplitRoomError`), because every
search there would fail; accepted, the room keeps only its largest piece.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Collection, Iterable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from .errors import BuildError

if TYPE_CHECKING:  # the CLI reads FINDING_KINDS at start-up; the converter stays unloaded
    from .home import SourceHome

LOST_GRID_POINTS = "lost-grid-points"
DROPPED_ROOMS = "dropped-rooms"
EMPTY_ROOMS = "empty-rooms"
SPLIT_ROOMS = "split-rooms"
FINDING_KINDS: tuple[str, ...] = (LOST_GRID_POINTS, DROPPED_ROOMS, EMPTY_ROOMS, SPLIT_ROOMS)

#: An iTHOR room that loses more than this share of its ALFRED grid points is reported. ALFRED's
#: grid already holds only the places AI2-THOR's agent could stand, so every point we drop is our
#: obstacle rule disagreeing with it; the 100 iTHOR scenes lose 0-17 %, except FloorPlan316 (40 %).
LOST_SHARE_ITHOR = 0.25
#: A ProcTHOR room that loses more than this share of the lattice points of its floor (those at
#: least the wall clearance from its walls) is reported. That lattice runs under the furniture,
#: which covers 3-46 % (median 21 %) of the 66 rooms kept in the 16 houses we import; more than
#: half is a room mostly filled or cut off.
LOST_SHARE_PROCTHOR = 0.5


@dataclass(frozen=True)
class Finding:
    """One thing a build found wrong with one room of one home."""

    kind: str
    home: str
    room: str
    source: str  # the FloorPlan, or the house file and room id
    detail: str

    @property
    def key(self) -> tuple[str, str, str]:
        return (self.kind, self.home, self.room)

    def text(self) -> str:
        return f"{self.kind}: {self.home}/{self.room} ({self.source}): {self.detail}"

    def to_json(self) -> dict[str, Any]:
        return {
            "kind": self.kind,
            "home": self.home,
            "room": self.room,
            "source": self.source,
            "detail": self.detail,
        }


def counts_text(counts: Mapping[str, int]) -> str:
    return ", ".join(f"{k} {v}" for k, v in sorted(counts.items()))


def lost_grid_points(
    home: str,
    room: str,
    source: str,
    kept: int,
    inside_furniture: Iterable[str],
    cut_off: int,
    limit: float,
) -> Finding | None:
    """A finding when more than ``limit`` (a share) of a room's grid points were lost.

    ``inside_furniture``: the type of the obstacle each lost point lay in; ``cut_off``: points
    outside the furniture but not connected to the piece the robot walks.
    """
    obstacles = Counter(inside_furniture)
    lost = sum(obstacles.values()) + cut_off
    total = kept + lost
    if total == 0 or lost <= limit * total:
        return None
    return Finding(
        LOST_GRID_POINTS,
        home,
        room,
        source,
        f"lost {lost} of its {total} grid points ({lost / total:.1%} > {limit:.0%}): "
        f"{sum(obstacles.values())} inside furniture"
        + (f" [{counts_text(obstacles)}]" if obstacles else "")
        + f", {cut_off} cut off from the piece the robot walks; {kept} viewpoints left",
    )


def empty_room(home: str, room: str, source: str, statics: int) -> Finding | None:
    if statics:
        return None
    return Finding(
        EMPTY_ROOMS,
        home,
        room,
        source,
        "has no static object of our classes: a search there only looks around the room",
    )


def split_rooms(home: SourceHome) -> list[Finding]:
    """One finding per room whose viewpoints fall into pieces the robot cannot walk between."""
    return [
        Finding(
            SPLIT_ROOMS,
            home.name,
            r.name,
            r.source_scene,
            f"viewpoints in {len(r.walkable_piece_sizes)} pieces of "
            f"{' and '.join(str(n) for n in r.walkable_piece_sizes)} that the robot cannot walk "
            "between (a diagonal step would cut a corner)",
        )
        for r in home.rooms
        if r.walkable_components != 1
    ]


class SplitRoomError(BuildError):
    """Rooms whose viewpoints fall into pieces the robot cannot walk between."""

    def __init__(self, home: str, split: Collection[Finding]) -> None:
        self.findings = tuple(split)
        rooms = "; ".join(f"the {f.room} ({f.source}): {f.detail}" for f in self.findings)
        super().__init__(
            f"home {home!r}: {rooms}; every search in such a room would fail. Pick another "
            "FloorPlan for that room (the held-out rule skips such scenes too), or build it with "
            "--accept split-rooms, which keeps only the largest piece (the others' viewpoints "
            "are dropped)"
        )


def ithor_findings(home: SourceHome) -> list[Finding]:
    """Lost grid points and empty rooms of an iTHOR home (:func:`split_rooms` is checked first)."""
    found: list[Finding] = []
    for r in home.rooms:
        lost = lost_grid_points(
            home.name,
            r.name,
            r.source_scene,
            len(r.viewpoints),
            (label.split("/", 1)[1].split("|")[0] for _, label in r.removed_inside_furniture),
            r.removed_disconnected,
            LOST_SHARE_ITHOR,
        )
        empty = empty_room(home.name, r.name, r.source_scene, len(r.statics))
        found += [f for f in (lost, empty) if f is not None]
    return found


class FindingsError(BuildError):
    """Findings the build was not told to accept; nothing was written."""

    def __init__(self, findings: Collection[Finding]) -> None:
        self.findings = tuple(findings)
        kinds = sorted({f.kind for f in self.findings})
        lines = "\n".join(f"  {f.text()}" for f in self.findings)
        super().__init__(
            f"the build found {len(self.findings)} problem(s) and wrote nothing:\n{lines}\n"
            f"pick other FloorPlans or houses, or accept them with --accept {','.join(kinds)} "
            "(accepted findings are recorded in PROVENANCE.md)"
        )


def unaccepted(
    findings: Iterable[Finding],
    accept: Collection[str],
    known: Mapping[tuple[str, str, str], str],
) -> list[Finding]:
    """Findings neither of an accepted kind nor in ``known`` (key -> the reason it is accepted)."""
    return [f for f in findings if f.kind not in accept and f.key not in known]
