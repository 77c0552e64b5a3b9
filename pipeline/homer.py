"""``data/priors/homer_routines.json``: household routines measured in the HOMER dataset.

HOMER (Patel & Chernova, CoRL 2022) simulates five households' days, 06:00–24:00 in 10-minute
steps, as scene graphs: every movable object has a parent (a piece of furniture, an appliance, a
room, or another object). The shared data folder has none of it, so the repository keeps those
days compacted in ``sources/`` (``homer/householdsDifferent/householdN/days.json``: each node's
parent at the day's start and every later change; ``common_data.json`` as upstream;
``sources/homer/README.md`` says how they were made, ``extract_days.py`` made them).

For each household, each of its search objects and each of the seeded schedules' four times of
day (``SLOT_MINUTES``, the same as ``sim/routine_schedule.SLOT_MINUTES``) this counts, over the
household's days, where the object is: its *place*, the first ancestor that is not itself a
movable object (a pencil on a note pad is at the desk the note pad is on). The counts are the
routine: a usual place per slot (the most counted), how often it is elsewhere (the exception
rate), and where. Nothing is fitted or smoothed.

What maps onto our homes is written down here, not chosen per home:

- ``PLACE_TYPES``: HOMER furniture class → our static class's AI2-THOR type, where one means the
  same thing; every other HOMER place (cupboards, cabinets, the dresser, the TV stand, rooms,
  "outside", …) maps to none, and the schedule stands in a fixed place drawn from the AI2-THOR
  placement statistics for it (``sim/homer_schedule.py``);
- ``TARGET_OBJECTS``: our target class → the HOMER objects that are that thing. Five of our eight
  targets (Laptop, Phone, Pillow, ToiletPaper, Vase) are in no HOMER household; their schedules
  draw from all HOMER routines.

Drift: HOMER's days carry no calendar (each day file is an independent draw of the household's
routine generator; files are numbered, not dated), so no drift can be measured from them. The
file reports, as ``summary.half_mode_change``, how often a (routine, slot)'s usual place differs
between the first and the second half of the household's days — what sampling alone gives.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .errors import SourceDataError

HOMER = Path("homer/householdsDifferent")
HOUSEHOLDS = tuple(f"household{i}" for i in range(5))
#: The seeded schedules' times of day (minutes after midnight): morning, afternoon, evening,
#: night (``sim/routine_schedule.SLOT_MINUTES``; a test keeps the two equal).
SLOT_MINUTES = (7 * 60 + 30, 13 * 60, 18 * 60 + 30, 22 * 60 + 30)
#: HOMER's category of movable objects: a place is the first ancestor of another category.
MOVABLE = "placable_objects"
#: HOMER place class → our static class's AI2-THOR type (None: no static of ours is that place).
PLACE_TYPES: Mapping[str, str | None] = {
    "bathroom_counter": "CounterTop",
    "bookshelf": "Shelf",
    "desk": "Desk",
    "fridge": "Fridge",
    "kitchen_counter": "CounterTop",
    "sink": "Sink",
    "sofa": "Sofa",
    "stove": "StoveBurner",
    "table": "DiningTable",
    # No static class of ours: cupboards, cabinets and drawers, appliances we do not map, rooms.
    "bathroom_cabinet": None,
    "bench": None,
    "coffe_maker": None,
    "cupboard": None,
    "dishwasher": None,
    "dresser": None,
    "kitchen_cabinet": None,
    "knifeblock": None,
    "mat": None,
    "shoe_rack": None,
    "shower": None,
    "trashcan": None,
    "tvstand": None,
    "washing_machine": None,
    "bathroom": None,
    "bedroom": None,
    "dining_room": None,
    "home_office": None,
    "outside": None,
}
#: Our target class → the HOMER objects that are one.
TARGET_OBJECTS: Mapping[str, tuple[str, ...]] = {
    "Apple": ("food_apple",),
    "Bowl": ("bowl",),
    "Cup": ("coffee_cup", "drinking_glass", "mug"),
}
WHAT = "the HOMER routines (priors/homer_routines.json)"


def _load(path: Path) -> Any:
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise SourceDataError(path, WHAT, str(exc)) from None


def source_files() -> list[Path]:
    """The files this step reads, relative to the source's folder (vendored: sources/homer/)."""
    return [HOMER / h / name for h in HOUSEHOLDS for name in ("common_data.json", "days.json")]


def parents_at(day: Mapping[str, Any], minute: int) -> list[int]:
    """Every node's parent index at ``minute`` of ``day`` (the last change at or before it)."""
    parents = list(day["start"])
    for when, node, parent in sorted(day["changes"], key=lambda c: int(c[0])):
        if when > minute:
            break
        parents[node] = parent
    return parents


def place_of(node: int, parents: Sequence[int], categories: Sequence[str]) -> int:
    """The first ancestor of ``node`` that is not a movable object (-1: none)."""
    seen = set()
    at = parents[node]
    while at >= 0 and categories[at] == MOVABLE and at not in seen:
        seen.add(at)
        at = parents[at]
    return at if at >= 0 and categories[at] != MOVABLE else -1


@dataclass(frozen=True)
class _Household:
    ids: list[int]
    classes: list[str]
    categories: list[str]
    objects: list[str]
    days: list[Mapping[str, Any]]


def _read(source: Path, household: str) -> _Household:
    folder = source / HOMER / household
    common = _load(folder / "common_data.json")
    doc = _load(folder / "days.json")
    try:
        ids = [int(i) for i in common["node_ids"]]
        h = _Household(
            ids=ids,
            classes=[str(c) for c in common["node_classes"][: len(ids)]],
            categories=[str(c) for c in common["node_categories"][: len(ids)]],
            objects=[str(o) for o in common["info"]["search_object_names"]],
            days=sorted(doc["days"], key=lambda d: str(d["file"])),
        )
    except (KeyError, TypeError, ValueError) as exc:
        raise SourceDataError(folder, WHAT, f"unexpected format: {exc!r}") from None
    if not h.days:
        raise SourceDataError(folder / "days.json", WHAT, "no days")
    unknown = sorted(
        {c for c, k in zip(h.classes, h.categories, strict=True) if k != MOVABLE} - set(PLACE_TYPES)
    )
    if unknown:
        raise SourceDataError(folder, WHAT, f"HOMER places with no mapping: {', '.join(unknown)}")
    return h


def _count(h: _Household, days: Sequence[Mapping[str, Any]]) -> dict[str, list[dict[str, int]]]:
    """Per search object the household holds, per slot: place node id → days there."""
    index = {c: i for i, c in enumerate(h.classes) if h.categories[i] == MOVABLE}
    out: dict[str, list[dict[str, int]]] = {}
    for obj in h.objects:
        node = index.get(obj)
        if node is None:  # a search object this household's graph does not hold
            continue
        per_slot = []
        for minute in SLOT_MINUTES:
            counts: dict[str, int] = {}
            for day in days:
                place = place_of(node, parents_at(day, minute), h.categories)
                if place < 0:
                    raise SourceDataError(HOMER, WHAT, f"{obj} has no place in {day['file']}")
                counts[str(h.ids[place])] = counts.get(str(h.ids[place]), 0) + 1
            per_slot.append(dict(sorted(counts.items())))
        out[obj] = per_slot
    return dict(sorted(out.items()))


def household_routines(source: Path, household: str) -> dict[str, Any]:
    """One household's routines (per search object, per slot: place node id → days there) and
    the same counted over the first and the second half of its days."""
    h = _read(source, household)
    routines = _count(h, h.days)
    cut = len(h.days) // 2
    first, second = _count(h, h.days[:cut]), _count(h, h.days[cut:])
    used = {int(k) for per_slot in routines.values() for counts in per_slot for k in counts}
    return {
        "household": household,
        "days": [str(d["file"]) for d in h.days],
        "places": {str(i): h.classes[h.ids.index(i)] for i in sorted(used)},
        "routines": routines,
        "halves": {o: [first[o], second[o]] for o in routines},
    }


def _mode(counts: Mapping[str, int]) -> str:
    return min(counts, key=lambda k: (-counts[k], k))


def summary(households: Sequence[Mapping[str, Any]]) -> dict[str, float]:
    """Pooled over every (household, object, slot): the share of days at the slot's usual place
    (1 − the exception rate), how often the slot's usual place differs from the object's usual
    place over the whole day, and how often it differs between the first and the second half of
    the days (``half_mode_change``; what sampling gives: HOMER has no calendar)."""
    usual = differs = changed = cells = 0.0
    for h in households:
        for obj, per_slot in h["routines"].items():
            whole: dict[str, int] = {}
            for counts in per_slot:
                for k, v in counts.items():
                    whole[k] = whole.get(k, 0) + v
            first, second = h["halves"][obj]
            for counts, a, b in zip(per_slot, first, second, strict=True):
                cells += 1
                usual += counts[_mode(counts)] / sum(counts.values())
                differs += _mode(counts) != _mode(whole)
                changed += _mode(a) != _mode(b)
    return {
        "cells": cells,
        "usual_share": usual / cells,
        "slot_mode_differs_from_day_mode": differs / cells,
        "half_mode_change": changed / cells,
    }


def homer_routines_json(source: Path) -> dict[str, Any]:
    households = [household_routines(source, h) for h in HOUSEHOLDS]
    stats = summary(households)
    return {
        "format": "objsearch.homer-routines/1",
        "source": (
            "HOMER (Patel & Chernova, CoRL 2022), processed days of "
            "Maithili/SpatioTemporalObjectTracking data/householdsDifferent, compacted in "
            f"the repository's sources/{HOMER.as_posix()}"
        ),
        "notes": (
            "households[].routines: HOMER search object -> per slot (slot_minutes) -> place "
            "node id -> days there; places: node id -> HOMER class; place_types: HOMER place "
            "class -> our static AI2-THOR type (null: none of ours); target_objects: our target "
            "-> the HOMER objects that are one (pipeline/homer.py)"
        ),
        "slot_minutes": list(SLOT_MINUTES),
        "place_types": dict(sorted(PLACE_TYPES.items())),
        "target_objects": {k: list(v) for k, v in sorted(TARGET_OBJECTS.items())},
        "summary": {k: round(v, 6) for k, v in stats.items()},
        "households": [{k: v for k, v in h.items() if k != "halves"} for h in households],
    }
