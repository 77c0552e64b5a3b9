"""The homes we did not tune on: iTHOR combinations chosen by a seeded rule, and ProcTHOR houses.

iTHOR rule (fixed before any result was seen): for each room type, the scenes 1–25 of that type
(kitchens 1–25, living rooms 201–225, bedrooms 301–325, bathrooms 401–425) minus the paper home's
scene are shuffled with ``random.Random(HELDOUT_SEED)``; home *i* takes the *i*-th scene of each
list. A scene whose walking graph falls into several pieces (``walkable_components != 1``) is
skipped in favour of the next one of its list, so no scene is used twice.
"""

from __future__ import annotations

import random
from collections.abc import Callable, Collection
from pathlib import Path

from .errors import HomeSpecError
from .home import SourceHome, build_home

HELDOUT_SEED = 3
HELDOUT_HOMES = 10
SCENES_PER_TYPE = 25
TYPE_BASES = (0, 200, 300, 400)

#: ProcTHOR houses imported by the default build: the 4-room houses and the 10-room house
#: (others come in with ``objsearch data build --procthor NAME=PATH``).
PROCTHOR_FILES: tuple[tuple[str, str], ...] = (
    *((f"procthor-{i:02d}", f"procthor_houses/houses_20/house_{i}.json") for i in range(15)),
    ("procthor-train1", "procthor_houses/procthor_train_1.json"),
)


def heldout_candidates(paper: tuple[str, ...]) -> list[list[str]]:
    """Per room type, the shuffled candidate scenes (the paper's excluded)."""
    rng = random.Random(HELDOUT_SEED)
    lists = []
    for base in TYPE_BASES:
        names = [f"FloorPlan{base + k}" for k in range(1, SCENES_PER_TYPE + 1)]
        names = [n for n in names if n not in paper]
        rng.shuffle(names)
        lists.append(names)
    return lists


def heldout_ithor_homes(
    source: Path,
    paper: tuple[str, ...],
    progress: Callable[[str], None] | None = None,
    numbers: Collection[int] = range(1, HELDOUT_HOMES + 1),
) -> tuple[list[SourceHome], list[str]]:
    """Build the held-out iTHOR homes ``ithor-<i>`` for each ``i`` in ``numbers`` by the rule in the
    module doc (the rule walks from home 1, so ``ithor-11`` continues after ``ithor-10``)."""
    bad = sorted(i for i in numbers if i < 1)
    if bad:
        raise HomeSpecError(f"held-out iTHOR homes are numbered from 1, not {bad[0]}")
    lists = heldout_candidates(paper)
    cursor = [0, 0, 0, 0]
    homes: list[SourceHome] = []
    notes: list[str] = []
    for i in range(1, max(numbers, default=0) + 1):
        name = f"ithor-{i:02d}"
        while True:
            if any(cursor[t] >= len(lists[t]) for t in range(4)):
                raise HomeSpecError(
                    f"the held-out rule runs out of scenes at {name}: each room type has "
                    f"{SCENES_PER_TYPE} scenes; ask for fewer held-out homes"
                )
            scenes = tuple(lists[t][cursor[t]] for t in range(4))
            # Homes before the first one asked for are built only to find which scenes they skip.
            say = progress if i in numbers else None
            home = build_home(source, name, scenes, say)
            split = [t for t, r in enumerate(home.rooms) if r.walkable_components != 1]
            if not split:
                break
            for t in split:
                if i in numbers:
                    notes.append(f"{name}: skipped {scenes[t]} (walking graph in pieces)")
                cursor[t] += 1
        for t in range(4):
            cursor[t] += 1
        if i in numbers:
            homes.append(home)
    return homes, notes
