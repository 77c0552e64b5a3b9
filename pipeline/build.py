"""Public entry point of the data converter: ``build_data`` derives every file of ``data/``.

Everything is computed in memory first and written only when all of it succeeded, each file
atomically, so a failed build leaves the previous files untouched.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from objsearch.events import _fs

from . import jsonio
from .errors import BuildError, HomeSpecError, SourceDataError
from .home import SourceHome, build_home, normalise_floorplan
from .more_homes import HELDOUT_SEED, PROCTHOR_FILES, heldout_ithor_homes
from .placement_stats import placement_stats_json
from .procthor import build_procthor_home
from .provenance import provenance_md, sha256
from .rearrangement import REARRANGEMENT, SUPPORT_TOLERANCE_M, load_episodes, rearrangement_json
from .room_objects import SUPPORT_RADIUS_M
from .scenario import table1
from .sources import HOZ_ADJACENCY, VG_MATRIX, load_cooccurrence, load_scene
from .table2 import table2
from .vg_prior import (
    PRIOR_FILES,
    hoz_masked_prior_json,
    load_adjacency,
    single_name_prior_json,
    vg_prior_json,
)
from .vocabulary import vocabulary_json

PAPER_HOME: tuple[str, str, str, str] = (
    "FloorPlan2",
    "FloorPlan201",
    "FloorPlan303",
    "FloorPlan401",
)
"""The paper's home: kitchen, living room, bedroom, bathroom."""

PAPER_HOME_NAME = "paper"


@dataclass(frozen=True)
class BuildReport:
    files: tuple[Path, ...]
    notes: tuple[str, ...]


def parse_home_arg(text: str) -> tuple[str, tuple[str, ...]]:
    """``"name=FloorPlan2,FloorPlan201,FloorPlan303,FloorPlan401"`` (or bare numbers) -> parts."""
    name, sep, scenes = text.partition("=")
    if not sep or not name.strip():
        raise HomeSpecError(f"--home expects NAME=KITCHEN,LIVING,BEDROOM,BATHROOM, got {text!r}")
    return name.strip(), tuple(normalise_floorplan(s) for s in scenes.split(","))


def _room_notes(home: SourceHome) -> list[str]:
    notes = []
    for r in home.rooms:
        grid_points = len(r.viewpoints) + r.removed_viewpoints
        obstacles = Counter(
            label.split("/", 1)[1].split("|")[0] for _, label in r.removed_inside_furniture
        )
        statics = Counter(s.cls for s in r.statics)
        objects = Counter(o.cls for o in r.objects)
        matched = sum(p.static_id is not None for p in r.alfred_poses)
        off = sum(not p.on_viewpoint for p in r.alfred_poses)
        notes.append(
            f"{home.name}/{r.name} ({r.source_scene}): {grid_points} ALFRED grid points -> "
            f"{len(r.viewpoints)} viewpoints ({len(r.removed_inside_furniture)} inside furniture"
            + (
                f" [{', '.join(f'{k} {v}' for k, v in sorted(obstacles.items()))}]"
                if obstacles
                else ""
            )
            + f", {r.removed_disconnected} disconnected); "
            f"statics: {', '.join(f'{k} {v}' for k, v in sorted(statics.items())) or 'none'}; "
            f"objects: {', '.join(f'{k} {v}' for k, v in sorted(objects.items())) or 'none'}; "
            f"ALFRED poses {len(r.alfred_poses)} ({matched} matched to a static, {off} off the "
            f"viewpoints); merged fixtures {len(r.merged_statics)}"
        )
        if r.walkable_components != 1:
            notes.append(
                f"{home.name}/{r.name}: warning: the viewpoints are 8-connected but fall into "
                f"{r.walkable_components} pieces when diagonal steps must not cut corners"
            )
    return notes


def build_data(
    source: Path,
    out: Path,
    *,
    homes: Mapping[str, Sequence[str]] | None = None,
    progress: Callable[[str], None] | None = None,
    more_homes: bool | None = None,
) -> BuildReport:
    """Derive ``vocabulary.json``, ``priors/``, ``homes/``, ``scenarios/``, ``schedules/`` and
    ``PROVENANCE.md`` under ``out`` from the raw public data under ``source``.

    ``homes`` maps a home name to four iTHOR scenes (kitchen, living room, bedroom, bathroom);
    default ``{"paper": PAPER_HOME}``. The Table I scenario and Table II schedule are derived for
    the home named ``paper`` when there is one.

    ``more_homes`` (default: when ``homes`` is not given) also derives the held-out homes
    (``pipeline/more_homes.py``: ten iTHOR combinations by a seeded rule and the ProcTHOR houses)
    and the AI2-THOR placement statistics their schedules are drawn from.
    """
    say = progress or (lambda _msg: None)
    source, out = Path(source), Path(out)
    default = {PAPER_HOME_NAME: PAPER_HOME}
    wanted = dict(homes) if homes is not None else default
    if not wanted:
        raise HomeSpecError("no home to build")
    if not source.is_dir():
        raise SourceDataError(source, "every derived file", "source folder not found")

    outputs: dict[str, str] = {}
    notes: list[str] = []

    say("vocabulary")
    outputs["vocabulary.json"] = jsonio.dumps(vocabulary_json())

    say("Visual Genome prior")
    matrix = load_cooccurrence(source, "the Visual Genome prior (priors/visual_genome.json)")
    vg_sha = sha256(source / VG_MATRIX)
    outputs[PRIOR_FILES["vg-cooccurrence"]] = jsonio.dumps(vg_prior_json(matrix, vg_sha))
    outputs[PRIOR_FILES["vg-single-name"]] = jsonio.dumps(single_name_prior_json(matrix, vg_sha))
    say("Visual Genome prior masked by the HOZ adjacency")
    graph = load_adjacency(source, f"the {PRIOR_FILES['vg-hoz-masked']} prior")
    outputs[PRIOR_FILES["vg-hoz-masked"]] = jsonio.dumps(
        hoz_masked_prior_json(matrix, graph, vg_sha, sha256(source / HOZ_ADJACENCY))
    )

    built: dict[str, SourceHome] = {}
    for name, scenes in wanted.items():
        home = build_home(source, name, scenes, say)
        built[name] = home
        outputs[f"homes/{name}.json"] = jsonio.dumps(home.to_json())
        notes += _room_notes(home)

    for name, home in built.items():
        if name == PAPER_HOME_NAME:
            continue
        try:
            own = table1(home)
        except BuildError as exc:
            notes.append(f"{name}: no Table I scenario ({exc})")
            continue
        outputs[f"scenarios/table1-{name}.json"] = jsonio.dumps(own.to_json())

    paper = built.get(PAPER_HOME_NAME)
    if paper is None:
        notes.append(f"no home named {PAPER_HOME_NAME!r}: Table I / Table II files not derived")
    else:
        say("Table I scenario and Table II schedule")
        scenario = table1(paper)
        outputs["scenarios/table1.json"] = jsonio.dumps(scenario.to_json())
        outputs["schedules/table2.json"] = jsonio.dumps(table2(paper, scenario))
        notes.append(
            f"table1: removed {len(scenario.removed)} instances; targets: "
            + ", ".join(f"{c} {i}" for c, i in scenario.targets.items())
        )

    normalised = {n: tuple(normalise_floorplan(s) for s in v) for n, v in wanted.items()}
    extra: list[str] = []
    extra_files: dict[str, list[Path]] = {}
    if more_homes if more_homes is not None else homes is None:
        extra, extra_files = _more_homes(source, outputs, notes, normalised, say, built)
    outputs["PROVENANCE.md"] = provenance_md(
        source, normalised, default, sorted(outputs), extra=extra, extra_files=extra_files
    )

    written = []
    for rel, text in outputs.items():
        path = out / rel
        say(f"write {path}")
        _fs.make_dirs(path.parent)
        _fs.write_atomic(path, text.encode("utf-8"))
        written.append(path)
    return BuildReport(files=tuple(written), notes=tuple(notes))


def _more_homes(
    source: Path,
    outputs: dict[str, str],
    notes: list[str],
    homes: Mapping[str, Sequence[str]],
    say: Callable[[str], None],
    built: Mapping[str, SourceHome],
) -> tuple[list[str], dict[str, list[Path]]]:
    """Held-out iTHOR homes, ProcTHOR houses, placement statistics and rearrangement placements
    (for ``built`` and the held-out iTHOR homes); provenance lines."""
    from .placement_stats import ASSETS, RECEPTACLES

    say("held-out iTHOR homes")
    paper = tuple(homes.get(PAPER_HOME_NAME, PAPER_HOME))
    heldout, skipped = heldout_ithor_homes(source, paper, say)
    notes += skipped
    lines = [
        "- held-out iTHOR homes (`pipeline/more_homes.py`, seed "
        f"{HELDOUT_SEED}: per room type, scenes 1-25 minus the paper's, shuffled; home i takes "
        "the i-th of each list; scenes whose walking graph is in pieces are skipped):"
    ]
    for home in heldout:
        outputs[f"homes/{home.name}.json"] = jsonio.dumps(home.to_json())
        notes.extend(_room_notes(home))
        scenes = [r.source_scene for r in home.rooms]
        lines.append(f"  - `homes/{home.name}.json`: {', '.join(scenes)}")
    lines.append(
        "- ProcTHOR homes (`pipeline/procthor.py`): navigation grid from the floor polygons minus "
        "furniture footprints, rooms joined by doorways and open walls and walked (no teleport):"
    )
    for name, rel in PROCTHOR_FILES:
        doc = build_procthor_home(source, name, Path(rel), say)
        outputs[f"homes/{name}.json"] = jsonio.dumps(doc)
        lines.append(
            f"  - `homes/{name}.json`: `{rel}` ({len(doc['rooms'])} rooms, "
            f"{len(doc['links'])} door/open-wall steps)"
        )
    say("AI2-THOR placement statistics")
    outputs["priors/ai2thor_placements.json"] = jsonio.dumps(placement_stats_json(source))
    lines.append(
        f"- `priors/ai2thor_placements.json`: counts from `{RECEPTACLES.as_posix()}` for our "
        f"targets on our static types, median sizes from `{ASSETS.as_posix()}`, move rate from "
        "Table II (`pipeline/placement_stats.py`)."
    )
    files = {
        "ithor": sorted(
            {
                p
                for h in heldout
                for r in h.rooms
                for p in (Path(f"ai2thor/ithor_scenes/{r.source_scene}.json"),)
            }
        ),
        "alfred": sorted(
            {
                p
                for h in heldout
                for r in h.rooms
                for p in (
                    Path(f"ai2thor/alfred_layouts/{r.source_scene}-layout.npy"),
                    Path(f"ai2thor/alfred_layouts/{r.source_scene}-openable.json"),
                )
            }
        ),
        "procthor_houses": sorted(Path(rel) for _, rel in PROCTHOR_FILES),
        "procthor_db": [ASSETS, RECEPTACLES],
    }
    rearr_lines, files["rearrangement"] = _rearrangement(
        source, [*built.values(), *heldout], outputs, notes, say
    )
    return [*lines, *rearr_lines], files


def _rearrangement(
    source: Path,
    homes: Sequence[SourceHome],
    outputs: dict[str, str],
    notes: list[str],
    say: Callable[[str], None],
) -> tuple[list[str], list[Path]]:
    """``rearrangement/<home>.json`` for every iTHOR home; provenance lines and files read."""
    say("rearrangement placements")
    episodes = load_episodes(source)
    lines = [
        f"- `rearrangement/<home>.json`: per room, the poses of our targets in the 50 "
        f"episodes of its FloorPlan (`{REARRANGEMENT.as_posix()}`, target and starting poses), "
        "converted like the homes (Unity -> REP-103, the room's offset) and attributed to the "
        f"static whose box is within {SUPPORT_TOLERANCE_M} m of the object's bottom centre (top "
        f"nearest that height, then centre nearest), else the nearest static box within "
        f"{SUPPORT_RADIUS_M} m; poses near no static are dropped (`pipeline/rearrangement.py`):",
    ]
    for home in homes:
        scenes = {
            r.source_scene: load_scene(source, r.source_scene, f"the rearrangement of {home.name}")
            for r in home.rooms
        }
        doc, counts = rearrangement_json(home, scenes, episodes, source)
        outputs[f"rearrangement/{home.name}.json"] = jsonio.dumps(doc, inline_rows=True)
        lines.append(
            f"  - `rearrangement/{home.name}.json`: {counts.kept} poses kept, "
            f"{counts.dropped} dropped (no static within {SUPPORT_RADIUS_M} m), {counts.absent} "
            "absent from their episode"
        )
        notes.append(
            f"rearrangement/{home.name}: {counts.kept} kept, {counts.dropped} dropped, "
            f"{counts.absent} absent"
        )
    return lines, list(episodes.files)
