"""The homes we did not tune on: iTHOR combinations chosen by a seeded rule, and ProcTHOR houses.

iTHOR rule (fixed before any result was seen): for each room type, the scenes 1–25 of that type
(kitchens 1–25, living rooms 201–225, bedrooms 301–325, bathrooms 401–425) minus the paper home's
scene are shuffled with ``random.Random(HELDOUT_SEED)``; home *i* takes the *i*-th scene of each
list. A scene whose walking graph falls into several pieces (``walkable_components != 1``) is
skipped in favour of the next one of its list, so no scene is used twice.
"""

from __future__ import annotations

import random
from collections.abc import Callable
from pathlib import Path

from .home import SourceHome, build_home

HELDOUT_SEED = 3
HELDOUT_HOMES = 10
SCENES_PER_TYPE = 25
TYPE_BASES = (0, 200, 300, 400)

#: ProcTHOR houses imported by default: the 4-room houses and the 10-room house.
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
    source: Path, paper: tuple[str, ...], progress: Callable[[str], None] | None = None
) -> tuple[list[SourceHome], list[str]]:
    """Build the held-out iTHOR homes ``ithor-01`` … by the rule in the module doc."""
    lists = heldout_candidates(paper)
    cursor = [0, 0, 0, 0]
    homes: list[SourceHome] = []
    notes: list[str] = []
    for i in range(1, HELDOUT_HOMES + 1):
        name = f"ithor-{i:02d}"
        while True:
            scenes = tuple(lists[t][cursor[t]] for t in range(4))
            home = build_home(source, name, scenes, progress)
            split = [t for t, r in enumerate(home.rooms) if r.walkable_components != 1]
            if not split:
                break
            for t in split:
                notes.append(f"{name}: skipped {scenes[t]} (walking graph in pieces)")
                cursor[t] += 1
        for t in range(4):
            cursor[t] += 1
        homes.append(home)
    return homes, notes
