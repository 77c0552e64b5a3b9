"""Placement schedules from real AI2-THOR rearrangement episodes, with a seed.

``data/rearrangement/<home>.json`` (derived by ``objsearch data build``, ``pipeline/rearrangement.py``)
holds, for each room of an iTHOR-based home, where the 50 rearrangement episodes of its FloorPlan put
our targets, each pose attributed to the static it rests on or in. A schedule ``rearr-<seed>`` of
``scenes`` scenes is built from one ``random.Random`` seeded by (home, seed):

- per class, one object of the home with rearrangement data is followed through the schedule (the
  stats schedules also place one object per class); it is drawn among the objects that rest on a
  static in both poses of at least one episode that the room's other followed objects can share;
- per room, the usable episodes (every followed object of the room rests on a static in both poses)
  are shuffled; scenes 2j-1 and 2j use the j-th: first its *target* poses (the room as it should be),
  then its *starting* poses (after the episode moved some objects). So an object moves between scenes
  2j-1 and 2j exactly when the real episode moved it, and to wherever the next episode has it after
  that. Objects stay in their room: the episodes never move anything between rooms;
- classes the home has no rearrangement data for (Apple and Pillow are in no episode; some rooms'
  vases rest on no static of ours) are placed as the ``stats-<seed>`` schedule of
  ``sim/stats_schedule.py`` places them, and listed in ``Schedule.fallback``.

Homes built from ProcTHOR houses have no rearrangement data (the episodes are iTHOR FloorPlans):
asking for ``rearr-<seed>`` there is an error that says to use ``stats-<seed>``; for an iTHOR home
without the file it names the home's FloorPlans (:func:`why_no_rearrangement`).
"""

from __future__ import annotations

import random
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

from objsearch.agent.categories import read_json
from objsearch.agent.datapaths import data_dir, data_key
from objsearch.agent.errors import DataFileError
from objsearch.agent.geometry import Vec3
from objsearch.agent.home import Box, Home, load_home
from objsearch.sim.placements import Placement, Placements, Schedule
from objsearch.sim.stats_schedule import SCENES, stats_schedule

REARRANGEMENT_DIR = "rearrangement"
FORMAT = "objsearch.rearrangement/1"


@dataclass(frozen=True)
class RestingPlace:
    """Where one object rests in one episode: its centre, the static it rests on, how far from it."""

    center: Vec3
    support: str  # static id
    distance: float  # from the object's bottom centre to the static's box (m)


@dataclass(frozen=True)
class Episode:
    index: int
    target: tuple[RestingPlace | None, ...]  # per object of the room; None: on no static, or absent
    start: tuple[RestingPlace | None, ...]


@dataclass(frozen=True)
class TrackedObject:
    id: str
    cls: str
    size: Vec3


@dataclass(frozen=True)
class RoomEpisodes:
    name: str
    source_scene: str
    objects: tuple[TrackedObject, ...]
    episodes: tuple[Episode, ...]

    def usable(self, k: int) -> frozenset[int]:
        """Episodes in which object ``k`` rests on a static in both poses."""
        return frozenset(
            e.index for e in self.episodes if e.target[k] is not None and e.start[k] is not None
        )


@dataclass(frozen=True)
class RearrangementData:
    home: str
    rooms: tuple[RoomEpisodes, ...]

    @classmethod
    def load(cls, home_name: str, data: Path | None = None) -> RearrangementData:
        """Home ``home_name``'s episodes in the data folder ``data`` (None:
        ``datapaths.data_dir()``), read once per (resolved folder, home)."""
        return _load(home_name, data_key(data))


def homes_with_rearrangement(data: Path | None = None) -> tuple[str, ...]:
    folder = data_dir(data) / REARRANGEMENT_DIR
    return tuple(sorted(p.stem for p in folder.glob("*.json")))


def why_no_rearrangement(home: Home) -> str:
    """Why ``home`` has no rearrangement data, naming what it was built from."""
    scenes = [r.source_scene for r in home.rooms]
    if not home.teleport:
        houses = sorted({s.partition("#")[0] for s in scenes})
        return (
            f"{home.name} is a ProcTHOR house ({', '.join(houses)}); the rearrangement episodes "
            "are of iTHOR FloorPlans only"
        )
    return (
        f"{home.name}: no rearrangement episodes were derived for its FloorPlans "
        f"{', '.join(scenes)} ({REARRANGEMENT_DIR}/{home.name}.json is missing; `objsearch data "
        "build` derives it for every iTHOR home whose FloorPlans the episodes cover and names "
        "the ones they do not)"
    )


@cache
def _load(home_name: str, folder: Path) -> RearrangementData:
    path = folder / REARRANGEMENT_DIR / f"{home_name}.json"
    if not path.is_file():
        have = ", ".join(homes_with_rearrangement(folder)) or "none"
        raise DataFileError(
            f"home {home_name!r} has no rearrangement data: "
            f"{why_no_rearrangement(load_home(home_name, folder))} (homes with data: {have}); "
            "use a stats-<seed> schedule for this home"
        )
    return read_rearrangement(path, home_name)


def read_rearrangement(path: Path, home_name: str) -> RearrangementData:
    """Parse one ``objsearch.rearrangement/1`` file, with a clear error if it is broken."""
    doc: Any = read_json(path, f"the rearrangement placements of home {home_name!r}")
    try:
        if doc["format"] != FORMAT or doc["home"] != home_name:
            raise ValueError(f"expected format {FORMAT} for home {home_name!r}")
        rooms = tuple(_room(r) for r in doc["rooms"])
    except (KeyError, TypeError, ValueError, IndexError, AttributeError) as exc:
        raise DataFileError(f"{path} is malformed: {exc!r}") from None
    return RearrangementData(home=home_name, rooms=rooms)


def _resting_place(row: Sequence[Any] | None, statics: Sequence[str]) -> RestingPlace | None:
    if row is None:
        return None
    x, y, z, s, d = row
    return RestingPlace((float(x), float(y), float(z)), statics[int(s)], float(d))


def _room(doc: Mapping[str, Any]) -> RoomEpisodes:
    statics = [str(s) for s in doc["statics"]]
    objects = tuple(
        TrackedObject(
            str(o["id"]),
            str(o["cls"]),
            (float(o["size"][0]), float(o["size"][1]), float(o["size"][2])),
        )
        for o in doc["objects"]
    )
    episodes = []
    for e in doc["episodes"]:
        target = tuple(_resting_place(r, statics) for r in e["target"])
        if len(target) != len(objects):
            raise ValueError(f"episode {e['index']} of {doc['name']} has {len(target)} rows")
        moved = {int(k): _resting_place(r, statics) for k, r in e["moved"].items()}
        start = tuple(moved[k] if k in moved else target[k] for k in range(len(objects)))
        episodes.append(Episode(int(e["index"]), target, start))
    return RoomEpisodes(str(doc["name"]), str(doc["source_scene"]), objects, tuple(episodes))


def _follow(
    rng: random.Random, data: RearrangementData
) -> tuple[dict[str, tuple[RoomEpisodes, int]], dict[str, frozenset[int]]]:
    """Class -> (room, object index) followed; room -> episodes every followed object can use."""
    shared: dict[str, frozenset[int]] = {}
    followed: dict[str, tuple[RoomEpisodes, int]] = {}
    classes = sorted({o.cls for r in data.rooms for o in r.objects})
    for cls in classes:
        options = []
        for room in data.rooms:
            for k, o in enumerate(room.objects):
                if o.cls != cls:
                    continue
                left = room.usable(k) & shared.get(room.name, room.usable(k))
                if left:
                    options.append((o.id, room, k, left))
        if not options:
            continue
        _, room, k, left = rng.choice(sorted(options, key=lambda t: t[0]))
        followed[cls] = (room, k)
        shared[room.name] = left
    return followed, shared


def rearr_schedule(
    home: Home, seed: int, *, scenes: int = SCENES, data: Path | None = None
) -> Schedule:
    """A schedule for ``home`` from its rearrangement episodes (see the module doc) in the data
    folder ``data`` (None: ``datapaths.data_dir()``), which ``home`` was read from."""
    rearrangement = RearrangementData.load(home.name, data)
    rng = random.Random(f"rearr-schedule:{home.name}:{seed}")
    followed, shared = _follow(rng, rearrangement)
    order = {}
    for name, episodes in sorted(shared.items()):
        ids = sorted(episodes)
        rng.shuffle(ids)
        order[name] = ids
    by_index = {r.name: {e.index: e for e in r.episodes} for r in rearrangement.rooms}
    stats = stats_schedule(home, seed, scenes=scenes, data=data)
    fallback = sorted({p.cls for s in stats.scenes.values() for p in s.values()} - set(followed))
    statics = home.statics
    out: dict[int, Placements] = {}
    for scene in range(1, scenes + 1):
        placed: dict[str, Placement] = {}
        pair = (scene - 1) // 2
        for cls, (room, k) in sorted(followed.items()):
            ids = order[room.name]
            episode = by_index[room.name][ids[pair % len(ids)]]
            pose = (episode.target if scene % 2 else episode.start)[k]
            assert pose is not None  # only usable episodes are in ``order``
            s = statics.get(pose.support)
            if s is None:
                raise DataFileError(
                    f"rearrangement data of home {home.name!r} names static {pose.support!r}, "
                    "which the home does not have; rebuild data/"
                )
            obj = room.objects[k]
            placed[obj.id] = Placement(
                obj.id, cls, Box(pose.center, obj.size), s.room, s.id, s.container
            )
        for p in stats.scenes[scene].values():
            if p.cls in fallback:
                placed[p.instance_id] = p
        out[scene] = placed
    return Schedule(name=f"rearr-{seed}", home=home.name, scenes=out, fallback=tuple(fallback))
