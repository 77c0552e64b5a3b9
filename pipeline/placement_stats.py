"""``data/priors/ai2thor_placements.json``: where AI2-THOR itself puts each target class.

Counts come from ProcTHOR's ``receptacles.json`` (receptacle type → child type → count over the
iTHOR/RoboTHOR scenes), kept for our eight targets and the receptacle types that are our static
classes (a ShelvingUnit's objects rest on its Shelf objects, so it counts as Shelf). Sizes are the
per-axis median of the class's AI2-THOR assets (``asset-database.json``), in the ROS frame. The move
rate is the share of Table II cells whose class differs from the previous scene's.
"""

from __future__ import annotations

import itertools
import json
import statistics
from pathlib import Path
from typing import Any

from .coordinate_frames import unity_size_to_ros
from .errors import SourceDataError
from .table2 import TABLE2
from .vocabulary import SEMI_DYNAMIC_BY_THOR_TYPE, STATIC_BY_THOR_TYPE

RECEPTACLES = Path("ai2thor/procthor_db/receptacles.json")
ASSETS = Path("ai2thor/procthor_db/asset-database.json")
RECEPTACLE_ALIASES = {"ShelvingUnit": "Shelf"}


def table2_move_rate() -> tuple[int, int]:
    moves = total = 0
    for row in TABLE2.values():
        for prev, cur in itertools.pairwise(row):
            moves += prev != cur
            total += 1
    return moves, total


def _load(path: Path, what: str) -> Any:
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise SourceDataError(path, what, str(exc)) from None


def placement_stats_json(source: Path) -> dict[str, Any]:
    what = "the AI2-THOR placement statistics (priors/ai2thor_placements.json)"
    receptacles = _load(source / RECEPTACLES, what)
    assets = _load(source / ASSETS, what)
    counts: dict[str, dict[str, int]] = {}
    for receptacle, children in receptacles.items():
        rtype = RECEPTACLE_ALIASES.get(receptacle, receptacle)
        if rtype not in STATIC_BY_THOR_TYPE:
            continue
        for child, stat in children.items():
            cls = SEMI_DYNAMIC_BY_THOR_TYPE.get(child)
            if cls is not None:
                row = counts.setdefault(cls.name, {})
                row[rtype] = row.get(rtype, 0) + int(stat["count"])
    sizes: dict[str, list[float]] = {}
    for thor_type, cls in SEMI_DYNAMIC_BY_THOR_TYPE.items():
        boxes = [
            unity_size_to_ros(
                (
                    float(a["boundingBox"]["x"]),
                    float(a["boundingBox"]["y"]),
                    float(a["boundingBox"]["z"]),
                )
            )
            for a in assets.get(thor_type, ())
        ]
        if not boxes:
            raise SourceDataError(source / ASSETS, what, f"no asset of type {thor_type}")
        sizes[cls.name] = [statistics.median(b[k] for b in boxes) for k in range(3)]
    moves, total = table2_move_rate()
    return {
        "format": "objsearch.placements/1",
        "source": RECEPTACLES.as_posix(),
        "size_source": ASSETS.as_posix(),
        "notes": (
            "counts: class -> receptacle type -> placements in AI2-THOR scenes (ProcTHOR "
            "receptacles.json), receptacle types limited to our static classes' AI2-THOR types "
            "(ShelvingUnit counted as Shelf); sizes: per-axis median asset bounding box (ROS x, y, "
            f"z); move_rate: {moves} of {total} Table II cells change class from one scene to the next."
        ),
        "counts": {c: dict(sorted(v.items())) for c, v in sorted(counts.items())},
        "sizes": dict(sorted(sizes.items())),
        "move_rate": moves / total,
    }
