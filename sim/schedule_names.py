"""Every kind of placement schedule, by name: the one place that turns a name into a schedule.

- ``table2`` (and any other ``data/schedules/<name>.json``): a schedule written by the converter;
- ``stats-<seed>``: drawn from AI2-THOR placement statistics (``sim/stats_schedule.py``);
- ``rearr-<seed>``: taken from real AI2-THOR rearrangement episodes (``sim/rearr_schedule.py``);
- ``habit-<seed>``: objects with habits, 30 scenes (``sim/habit_schedule.py``);
- ``moved-<seed>``: the same habits until scene 11, new ones (another room) from then on;
- ``routine-<seed>``: where an object is depends on the time of day and the weekday, habits
  drift week by week, 84 scenes (``sim/routine_schedule.py``);
- ``homer-<seed>``: routines measured in the HOMER households (Patel & Chernova), laid onto the
  home, 84 scenes (``sim/homer_schedule.py``).

Every seeded schedule's scenes are times of day, four a day (``routine_schedule.scene_clock``),
and each search records its scene's (``task_started.clock``); a file schedule's scenes have none.
"""

from __future__ import annotations

from pathlib import Path

from objsearch.agent.catalogue import DayClock
from objsearch.agent.datapaths import data_dir
from objsearch.agent.errors import ObjsearchError
from objsearch.agent.home import Home
from objsearch.sim.habit_schedule import HABIT_SCENES, habit_schedule
from objsearch.sim.homer_schedule import homer_schedule
from objsearch.sim.placements import Schedule
from objsearch.sim.rearr_schedule import rearr_schedule
from objsearch.sim.routine_schedule import routine_schedule, scene_clock
from objsearch.sim.stats_schedule import SCENES, stats_schedule

#: Seeded schedule kinds: ``<kind>-<seed>``.
SEEDED_KINDS = ("stats", "rearr", "habit", "moved", "routine", "homer")
#: The kinds whose scenes' places depend on the time of day.
ROUTINE_KINDS = ("routine", "homer")


class UnknownScheduleError(ObjsearchError, ValueError):
    """A schedule name that is no file schedule and no ``<kind>-<seed>``."""


def file_schedules(data: Path | None = None) -> tuple[str, ...]:
    return tuple(sorted(p.stem for p in (data_dir(data) / "schedules").glob("*.json")))


def _expected(data: Path | None = None) -> str:
    return ", ".join([*file_schedules(data), *(f"{k}-<seed>" for k in SEEDED_KINDS)])


def parse_seeded(name: str) -> tuple[str, int] | None:
    """``"rearr-3"`` -> ``("rearr", 3)``; None for a file schedule's name; an error if malformed."""
    kind, sep, seed = name.partition("-")
    if not sep or kind not in SEEDED_KINDS:
        return None
    try:
        value = int(seed)
    except ValueError:
        raise UnknownScheduleError(
            f"schedule {name!r}: expected {kind}-<integer seed>, e.g. {kind}-0"
        ) from None
    if value < 0:
        raise UnknownScheduleError(f"schedule {name!r}: the seed must be >= 0")
    return kind, value


def load_schedule(
    home: Home, name: str, *, scenes: int | None = None, data: Path | None = None
) -> Schedule:
    """The schedule ``name`` for ``home`` (``scenes`` applies to the seeded kinds only; default:
    the kind's own length, 10 scenes, 30 for ``habit``, 84 for ``routine`` and ``homer``), from
    the data folder ``data`` ``home`` was read from (None: ``datapaths.data_dir()``)."""
    seeded = parse_seeded(name)
    if seeded is not None:
        kind, seed = seeded
        if kind in ("habit", "moved"):
            n, moved = scenes or HABIT_SCENES, kind == "moved"
            return habit_schedule(home, seed, scenes=n, moved=moved, data=data)
        if kind == "routine":
            return routine_schedule(home, seed, scenes=scenes, data=data)
        if kind == "homer":
            return homer_schedule(home, seed, scenes=scenes, data=data)
        scenes = scenes or SCENES
        if kind == "stats":
            return stats_schedule(home, seed, scenes=scenes, data=data)
        return rearr_schedule(home, seed, scenes=scenes, data=data)
    if name not in file_schedules(data):
        raise UnknownScheduleError(f"unknown schedule {name!r}; expected one of: {_expected(data)}")
    return Schedule.load(home, name, data=data)


def schedule_clock(name: str | None, scene: int | None) -> DayClock | None:
    """The time of day of ``scene`` of the schedule ``name``: a seeded schedule's (four scenes a
    day, scene 1 a Monday morning); None for a file schedule or no scene."""
    if name is None or scene is None or scene < 1 or parse_seeded(name) is None:
        return None
    return scene_clock(scene)
