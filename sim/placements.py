"""Where semi-dynamic objects are: the home's own placements and placement schedules over time."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from objsearch.agent.categories import read_json
from objsearch.agent.datapaths import data_dir
from objsearch.agent.errors import DataFileError
from objsearch.agent.home import Box, Home


@dataclass(frozen=True, slots=True)
class Placement:
    """Where one semi-dynamic object is for one task."""

    instance_id: str
    cls: str
    box: Box
    room: str
    support: str | None
    inside: bool


Placements = Mapping[str, Placement]


def base_placements(home: Home, removed: frozenset[str] = frozenset()) -> dict[str, Placement]:
    """The objects as the source scenes place them, minus ``removed`` instances."""
    return {
        o.id: Placement(o.id, o.cls, o.box, o.room, o.support, o.inside)
        for o in home.objects.values()
        if o.id not in removed
    }


def table1_scenario_path(home_name: str, data: Path | None = None) -> Path:
    """``scenarios/table1-<home>.json`` when the build derived one for that home (any home that
    satisfies the paper's removal rule), else the paper home's ``scenarios/table1.json``; of the
    data folder ``data`` (None: ``datapaths.data_dir()``)."""
    own = data_dir(data) / "scenarios" / f"table1-{home_name}.json"
    return own if own.is_file() else data_dir(data) / "scenarios" / "table1.json"


def has_table1_scenario(home_name: str) -> bool:
    """Whether the paper's Table I removals are defined for the home: the paper home's own
    ``scenarios/table1.json``, or a ``table1-<home>.json`` the data build derived."""
    own = table1_scenario_path(home_name)
    return own.name != "table1.json" or home_name == "paper"


def table1_removals(
    home: Home, path: Path | None = None, data: Path | None = None
) -> frozenset[str]:
    """The paper's Table I removals (one instance per target), checked against the home; from
    ``path``, else the scenario of the data folder ``data`` (None: ``datapaths.data_dir()``)."""
    path = path or table1_scenario_path(home.name, data)
    doc = read_json(path, "the Table I scenario")
    removed = frozenset(doc["removed"])
    unknown = removed - set(home.objects)
    if unknown:
        raise DataFileError(f"{path}: removes objects not in home {home.name!r}: {sorted(unknown)}")
    return removed


@dataclass(frozen=True)
class Schedule:
    """Placements per scene (paper Table II): scene number → instance id → placement.

    ``fallback``: classes this schedule places by another source than its own (a ``rearr-<seed>``
    schedule places classes without rearrangement data as ``stats-<seed>`` does). ``redrawn``:
    placements a drawn schedule refused because no viewpoint could see them (sim/seeable.py)."""

    name: str
    home: str
    scenes: Mapping[int, Placements]
    fallback: tuple[str, ...] = ()
    redrawn: int = 0

    @classmethod
    def load(
        cls, home: Home, name: str = "table2", path: Path | None = None, data: Path | None = None
    ) -> Schedule:
        """The schedule at ``path``, else ``schedules/<name>.json`` of the data folder ``data``
        (None: ``datapaths.data_dir()``), for ``home``."""
        path = path or data_dir(data) / "schedules" / f"{name}.json"
        doc = read_json(path, f"the placement schedule {name!r}")
        if doc["home"] != home.name:
            raise DataFileError(f"{path} is a schedule for home {doc['home']!r}, not {home.name!r}")
        base = base_placements(home, table1_removals(home, data=data))
        instance_of = {p.cls: p for p in base.values()}
        statics = home.statics
        scenes: dict[int, Placements] = {}
        for scene in doc["scenes"]:
            placed: dict[str, Placement] = {}
            for cls_name, spec in scene["placements"].items():
                obj = instance_of.get(cls_name)
                support = statics.get(spec["support"])
                if obj is None or support is None:
                    raise DataFileError(
                        f"{path}: scene {scene['scene']} places {cls_name!r} on {spec['support']!r}, "
                        f"which home {home.name!r} does not have"
                    )
                center: Any = spec["center"]
                box = Box((float(center[0]), float(center[1]), float(center[2])), obj.box.size)
                placed[obj.instance_id] = Placement(
                    obj.instance_id, cls_name, box, support.room, support.id, bool(spec["inside"])
                )
            scenes[int(scene["scene"])] = placed
        return cls(name=name, home=home.name, scenes=scenes)
