"""Why a memory that knows the hour gains so little on the routine protocol's metric: a measured
decomposition (docs/results-routine.md, "Why even the time-aware oracle reaches only 0.94×").

- :func:`slot_effect`: how much knowing the hour tells, exactly, from the schedule's generator
  (``sim/routine_schedule.py``, ``sim/homer_schedule.py``; where its scenes land, redraws
  included, as the references read it, ``sim/distribution_oracle.py``): for each target class,
  slot and day type of the evaluation week, the chance that the most likely place (room) of the time-blind distribution holds the object,
  against that of the slot's own distribution, weighted by the days of the week.
- :func:`path_split`: where the references' paths go, from a ``bench homes`` run: the oracle path
  no memory can shorten, searches that went straight to the target's room against those that
  walked a wrong room first, and the first search of each scene (nothing seen yet that day)
  against the later ones (the robot has passed most objects while looking for earlier targets).

``objsearch bench routine-ceiling RUN_DIR... [--kind homer]`` prints both for the run's homes and
seeds (``homer``: the HOMER-derived schedules, ``sim/homer_schedule.py``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path

from objsearch.agent.home import load_home
from objsearch.experiments.learning import first_of_scene
from objsearch.experiments.runner import Row, read_output
from objsearch.sim.distribution_oracle import time_blind_distribution, time_of_day_distribution
from objsearch.sim.longterm import TARGET_ORDER
from objsearch.sim.routine_schedule import SCENES_PER_DAY, WEEKEND

#: The evaluation week of the routine protocol (days 15-21).
EVALUATED_WEEK = 2
#: First searches after this scene are evaluated (day 14; experiments/report_belief.py).
AFTER_SCENE = 14 * SCENES_PER_DAY


def _mode(dist: Mapping[str, float]) -> str:
    return min(dist, key=lambda p: (-dist[p], p))


def _rooms(dist: Mapping[str, float], room_of: Mapping[str, str]) -> dict[str, float]:
    out: dict[str, float] = {}
    for place, p in dist.items():
        out[room_of[place]] = out.get(room_of[place], 0.0) + p
    return out


def slot_effect(
    homes: Sequence[str], seeds: int, week: int = EVALUATED_WEEK, kind: str = "routine"
) -> dict[str, float]:
    """Means over (home, seed, target, slot, day type), weighted by days: P(object at the
    time-blind mode) and P(at the slot's mode), the same for rooms, and how often the slot's
    mode room differs from the time-blind one. ``kind``: ``routine`` or ``homer`` (whose days
    are all alike)."""
    sums: dict[str, float] = {}
    weight = 0.0
    for name in homes:
        home = load_home(name)
        room_of = {s.id: s.room for s in home.statics.values()}
        for seed in range(seeds):
            blind = time_blind_distribution(home, kind, seed, week)
            for weekend, days in ((False, 7 - len(WEEKEND)), (True, len(WEEKEND))):
                for slot in range(SCENES_PER_DAY):
                    exact = time_of_day_distribution(home, kind, seed, week, weekend, slot)
                    for cls in sorted(set(exact) & set(TARGET_ORDER)):
                        now, week_avg = exact[cls], blind[cls]
                        rooms_now = _rooms(now, room_of)
                        rooms_week = _rooms(week_avg, room_of)
                        values = {
                            "place_blind_mode": now.get(_mode(week_avg), 0.0),
                            "place_slot_mode": now[_mode(now)],
                            "room_blind_mode": rooms_now.get(_mode(rooms_week), 0.0),
                            "room_slot_mode": rooms_now[_mode(rooms_now)],
                            "room_mode_differs": float(_mode(rooms_now) != _mode(rooms_week)),
                        }
                        for key, v in values.items():
                            sums[key] = sums.get(key, 0.0) + days * v
                        weight += days
    return {key: v / weight for key, v in sums.items()}


def path_split(rows: Sequence[Row], after: int = AFTER_SCENE) -> dict[str, dict[str, float]]:
    """Per strategy, over its searches after ``after`` (one start per target and scene): the
    path and the oracle path (m per search), the share that walked no wrong room and the excess
    of those and of the rest, and Σ path ÷ Σ oracle path of the first search of each scene and
    of the later ones."""
    late = [r for r in rows if r.scene > after]
    firsts = {(r.strategy, r.home, r.placements, r.scene, r.target) for r in first_of_scene(late)}
    out: dict[str, dict[str, float]] = {}
    for name in sorted({r.strategy for r in late}):
        mine = [r for r in late if r.strategy == name and r.success]
        straight = [r for r in mine if (r.wrong_rooms_m or 0.0) < 1e-6]
        detour = [r for r in mine if (r.wrong_rooms_m or 0.0) >= 1e-6]
        first = [r for r in mine if (r.strategy, r.home, r.placements, r.scene, r.target) in firsts]
        later = [
            r for r in mine if (r.strategy, r.home, r.placements, r.scene, r.target) not in firsts
        ]

        def excess(part: Sequence[Row]) -> float:
            if not part:
                return math.nan
            return math.fsum(r.path_length - r.oracle_length for r in part) / len(part)

        def ratio(part: Sequence[Row]) -> float:
            oracle = math.fsum(r.oracle_length for r in part)
            return math.fsum(r.path_length for r in part) / oracle if oracle > 0 else math.nan

        out[name] = {
            "searches": len(mine),
            "path_m": math.fsum(r.path_length for r in mine) / len(mine),
            "oracle_m": math.fsum(r.oracle_length for r in mine) / len(mine),
            "straight_share": len(straight) / len(mine),
            "excess_straight_m": excess(straight),
            "excess_detour_m": excess(detour),
            "first_of_scene_ratio": ratio(first),
            "later_ratio": ratio(later),
        }
    return out


def ceiling_text(runs: Sequence[Path], kind: str) -> str | None:
    """Both decompositions for the ``kind``-<seed> searches of ``runs`` (bench homes outputs),
    as ``objsearch bench routine-ceiling`` prints them; None if the runs hold none."""
    rows = [r for run in runs for r in read_output(run) if r.placements.startswith(f"{kind}-")]
    if not rows:
        return None
    homes = sorted({r.home for r in rows})
    seeds = 1 + max(r.seed for r in rows)
    lines = [f"slot effect, week {EVALUATED_WEEK} ({len(homes)} homes, seeds 0-{seeds - 1}):"]
    lines += [f"  {key:20s} {v:.3f}" for key, v in slot_effect(homes, seeds, kind=kind).items()]
    lines.append(f"paths after scene {AFTER_SCENE}:")
    lines += [
        f"  {name:14s} " + " ".join(f"{k} {v:.3f}" for k, v in parts.items())
        for name, parts in path_split(rows).items()
    ]
    return "\n".join(lines)
