"""Public entry point of the data converter: ``build_data`` derives every file of ``data/``.

Everything is computed in memory first and written only when all of it succeeded, each file
atomically, so a failed build leaves the previous files untouched.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from objsearch.events import _fs

from . import jsonio
from .accepted import COMMITTED_FINDINGS
from .errors import BuildError, HomeSpecError, SourceDataError
from .findings import (
    FINDING_KINDS,
    SPLIT_ROOMS,
    Finding,
    FindingsError,
    SplitRoomError,
    counts_text,
    ithor_findings,
    split_rooms,
    unaccepted,
)
from .home import SourceHome, build_home, check_home_name, check_home_spec, normalise_floorplan
from .homer import HOMER, homer_routines_json
from .homer import source_files as homer_files
from .more_homes import HELDOUT_HOMES, HELDOUT_SEED, PROCTHOR_FILES, heldout_ithor_homes
from .placement_stats import placement_stats_json
from .procthor import build_procthor_home
from .provenance import build_command, merge_provenance, provenance_md, sha256
from .rearrangement import REARRANGEMENT, SUPPORT_TOLERANCE_M, load_episodes, rearrangement_json
from .room_objects import SUPPORT_RADIUS_M
from .scenario import table1
from .sourceinfo import HOMER as HOMER_SOURCE
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
    #: Every finding of the build (all accepted, else the build raised ``FindingsError``), with
    #: the reason it was accepted.
    findings: tuple[tuple[Finding, str], ...] = ()


def parse_home_arg(text: str) -> tuple[str, tuple[str, ...]]:
    """``"name=FloorPlan2,FloorPlan201,FloorPlan303,FloorPlan401"`` (or bare numbers) -> parts."""
    name, sep, scenes = text.partition("=")
    if not sep or not name.strip():
        raise HomeSpecError(f"--ithor expects NAME=KITCHEN,LIVING,BEDROOM,BATHROOM, got {text!r}")
    return name.strip(), tuple(normalise_floorplan(s) for s in scenes.split(","))


def parse_procthor_arg(text: str) -> tuple[str, Path]:
    """``"name=procthor_houses/houses_20/house_3.json"`` -> (name, path); a relative path is
    relative to the source folder."""
    name, sep, path = text.partition("=")
    if not sep or not name.strip() or not path.strip():
        raise HomeSpecError(
            f"--procthor expects NAME=HOUSE.json (a ProcTHOR house file, relative to --source or "
            f"absolute), got {text!r}"
        )
    return name.strip(), Path(path.strip())


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
            + (f" [{counts_text(obstacles)}]" if obstacles else "")
            + f", {r.removed_disconnected} disconnected); "
            f"statics: {counts_text(statics) or 'none'}; "
            f"objects: {counts_text(objects) or 'none'}; "
            f"ALFRED poses {len(r.alfred_poses)} ({matched} matched to a static, {off} off the "
            f"viewpoints); merged fixtures {len(r.merged_statics)}"
        )
    return notes


@dataclass(frozen=True)
class _Wanted:
    """The homes one build derives."""

    ithor: Mapping[str, tuple[str, ...]]  # asked for by name: four FloorPlans each
    heldout: tuple[int, ...]  # held-out iTHOR homes by number (pipeline/more_homes.py)
    procthor: Mapping[str, Path]  # house file, relative to the source or absolute
    default: bool  # the build of the committed data/

    def names(self) -> list[str]:
        return [*self.ithor, *(f"ithor-{i:02d}" for i in self.heldout), *self.procthor]


def _wanted(
    homes: Mapping[str, Sequence[str]] | None,
    procthor: Mapping[str, Path] | None,
    heldout_ithor: Sequence[int],
) -> _Wanted:
    if homes is None and procthor is None and not heldout_ithor:
        return _Wanted(
            {PAPER_HOME_NAME: PAPER_HOME},
            tuple(range(1, HELDOUT_HOMES + 1)),
            {name: Path(rel) for name, rel in PROCTHOR_FILES},
            default=True,
        )
    wanted = _Wanted(
        {name: check_home_spec(name, scenes) for name, scenes in (homes or {}).items()},
        tuple(sorted(set(heldout_ithor))),
        dict(procthor or {}),
        default=False,
    )
    names = wanted.names()
    if not names:
        raise HomeSpecError("no home to build")
    for name in wanted.procthor:
        check_home_name(name)
    twice = sorted(n for n, k in Counter(names).items() if k > 1)
    if twice:
        raise HomeSpecError(
            f"home name(s) {', '.join(twice)} asked for twice (--home, --procthor and "
            "--heldout-ithor name the files they write); give each home its own name"
        )
    return wanted


def build_data(
    source: Path,
    out: Path,
    *,
    homes: Mapping[str, Sequence[str]] | None = None,
    procthor: Mapping[str, Path] | None = None,
    heldout_ithor: Sequence[int] = (),
    accept: Collection[str] = (),
    progress: Callable[[str], None] | None = None,
) -> BuildReport:
    """Derive ``vocabulary.json``, ``priors/``, ``homes/``, ``scenarios/``, ``schedules/``,
    ``rearrangement/`` and ``PROVENANCE.md`` under ``out`` from the raw public data under
    ``source``: a data folder ``search`` and ``bench homes`` run on (``demo`` and ``bench paper``
    too when a home is named ``paper``).

    Without ``homes``, ``procthor`` and ``heldout_ithor`` it builds the committed ``data/``: the
    paper's home, the held-out iTHOR homes ``ithor-01`` … ``ithor-10`` and the ProcTHOR houses of
    ``pipeline/more_homes.py``. Otherwise exactly the homes asked for: ``homes`` maps a name to four
    iTHOR scenes (kitchen, living room, bedroom, bathroom), ``procthor`` a name to a ProcTHOR house
    file, ``heldout_ithor`` numbers held-out iTHOR homes by the seeded rule. The Table I scenario
    and Table II schedule are derived for the home named ``paper`` when there is one.

    A room in pieces raises ``SplitRoomError`` unless ``accept`` holds ``split-rooms`` (then the
    room keeps its largest piece); other findings (``pipeline/findings.py``) of a kind not in
    ``accept`` (nor, for the default build, in ``pipeline/accepted.py``) raise ``FindingsError``.
    Either way nothing is written. When ``out`` already holds a ``PROVENANCE.md`` and this is not
    the default build, its lines are kept and this build's are appended.
    """
    say = progress or (lambda _msg: None)
    source, out = Path(source), Path(out)
    wanted = _wanted(homes, procthor, heldout_ithor)
    if not source.is_dir():
        raise SourceDataError(source, "every derived file", "source folder not found")
    bad = sorted(set(accept) - set(FINDING_KINDS))
    if bad:
        raise BuildError(f"cannot accept {', '.join(bad)}: findings are {', '.join(FINDING_KINDS)}")

    outputs: dict[str, str] = {}
    notes: list[str] = []
    findings: list[Finding] = []

    _vocabulary_and_priors(source, outputs, say)

    built: dict[str, SourceHome] = {}
    for name, scenes in wanted.ithor.items():
        home = build_home(source, name, scenes, say)
        split = split_rooms(home)
        if split:
            if SPLIT_ROOMS not in accept:
                raise SplitRoomError(name, split)
            home = build_home(source, name, scenes, say, largest_walkable_piece=True)
        findings += [*split, *ithor_findings(home)]
        built[name] = home
        outputs[f"homes/{name}.json"] = jsonio.dumps(home.to_json())
        notes += _room_notes(home)

    _own_table1_scenarios(built, outputs, notes)

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

    extra, extra_files = _more_homes(source, outputs, notes, findings, wanted, say, built)
    accepted = _accepted(findings, accept, wanted.default)
    extra += _accepted_lines(accepted)
    command = build_command(
        {} if wanted.default else wanted.ithor,
        {} if wanted.default else wanted.procthor,
        () if wanted.default else wanted.heldout,
        sorted(accept),
    )
    provenance = provenance_md(
        source,
        wanted.ithor,
        command,
        sorted(outputs),
        extra=extra,
        extra_files=extra_files,
        paper_tables=paper is not None,
    )
    existing = out / "PROVENANCE.md"
    if not wanted.default and existing.is_file():
        provenance = merge_provenance(existing.read_text(encoding="utf-8"), provenance, command)
    outputs["PROVENANCE.md"] = provenance

    written = _write_outputs(out, outputs, say)
    return BuildReport(files=tuple(written), notes=tuple(notes), findings=tuple(accepted))


def _write_outputs(out: Path, outputs: Mapping[str, str], say: Callable[[str], None]) -> list[Path]:
    """Each derived file written atomically under ``out`` (its folders made durably)."""
    written = []
    for rel, text in outputs.items():
        path = out / rel
        say(f"write {path}")
        _fs.make_dirs(path.parent)
        _fs.write_atomic(path, text.encode("utf-8"))
        written.append(path)
    return written


def _vocabulary_and_priors(
    source: Path, outputs: dict[str, str], say: Callable[[str], None]
) -> None:
    """``vocabulary.json`` and the Visual Genome priors (plain, single-name, HOZ-masked)."""
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


def _own_table1_scenarios(
    built: Mapping[str, SourceHome], outputs: dict[str, str], notes: list[str]
) -> None:
    """A Table I scenario of each iTHOR home but the paper's, where the removal rule finds one."""
    for name, home in built.items():
        if name == PAPER_HOME_NAME:
            continue
        try:
            own = table1(home)
        except BuildError as exc:
            notes.append(f"{name}: no Table I scenario ({exc})")
            continue
        outputs[f"scenarios/table1-{name}.json"] = jsonio.dumps(own.to_json())


def _accepted(
    findings: Sequence[Finding], accept: Collection[str], default: bool
) -> list[tuple[Finding, str]]:
    """Each finding with the reason it is accepted; ``FindingsError`` if one is not."""
    known = COMMITTED_FINDINGS if default else {}
    refused = unaccepted(findings, accept, known)
    if refused:
        raise FindingsError(refused)
    return [(f, known.get(f.key, f"by --accept {f.kind}")) for f in findings]


def _accepted_lines(accepted: Sequence[tuple[Finding, str]]) -> list[str]:
    if not accepted:
        return []
    return [
        "- Findings the build went ahead with (thresholds and kinds: `docs/pipeline.md`; the "
        "committed homes' in `pipeline/accepted.py`):",
        *(f"  - {f.text()}; accepted: {why}" for f, why in accepted),
    ]


def _procthor_path(source: Path, path: Path) -> Path:
    """The house file as the home records it: relative to ``source`` when it lies under it."""
    if not path.is_absolute():
        return path
    try:
        return path.resolve().relative_to(source.resolve())
    except ValueError:
        return path


def _more_homes(
    source: Path,
    outputs: dict[str, str],
    notes: list[str],
    findings: list[Finding],
    wanted: _Wanted,
    say: Callable[[str], None],
    built: Mapping[str, SourceHome],
) -> tuple[list[str], dict[str, list[Path]]]:
    """Held-out iTHOR homes, ProcTHOR houses, placement statistics and rearrangement placements
    (for ``built`` and the held-out iTHOR homes); provenance lines."""
    from .placement_stats import ASSETS, RECEPTACLES

    lines: list[str] = []
    heldout: list[SourceHome] = []
    if wanted.heldout:
        say("held-out iTHOR homes")
        paper = tuple(wanted.ithor.get(PAPER_HOME_NAME, PAPER_HOME))
        heldout, skipped = heldout_ithor_homes(source, paper, say, wanted.heldout)
        notes += skipped
        lines.append(
            "- held-out iTHOR homes (`pipeline/more_homes.py`, seed "
            f"{HELDOUT_SEED}: per room type, scenes 1-25 minus the paper's, shuffled; home i takes "
            "the i-th of each list; scenes whose walking graph is in pieces are skipped):"
        )
        for home in heldout:
            findings.extend(ithor_findings(home))
            outputs[f"homes/{home.name}.json"] = jsonio.dumps(home.to_json())
            notes.extend(_room_notes(home))
            scenes = [r.source_scene for r in home.rooms]
            lines.append(f"  - `homes/{home.name}.json`: {', '.join(scenes)}")
    houses = {name: _procthor_path(source, path) for name, path in wanted.procthor.items()}
    if houses:
        lines.append(
            "- ProcTHOR homes (`pipeline/procthor.py`): navigation grid from the floor polygons "
            "minus furniture footprints, rooms joined by doorways and open walls and walked (no "
            "teleport):"
        )
    for name, rel in houses.items():
        house = build_procthor_home(source, name, rel, say)
        findings.extend(house.findings)
        outputs[f"homes/{name}.json"] = jsonio.dumps(house.doc)
        lines.append(
            f"  - `homes/{name}.json`: `{rel.as_posix()}` ({len(house.doc['rooms'])} rooms, "
            f"{len(house.doc['links'])} door/open-wall steps)"
            # A house from outside the source folder has no source section to give its hash.
            + (f", sha256 `{sha256(rel)}`" if rel.is_absolute() else "")
        )
    say("AI2-THOR placement statistics")
    outputs["priors/ai2thor_placements.json"] = jsonio.dumps(placement_stats_json(source))
    lines.append(
        f"- `priors/ai2thor_placements.json`: counts from `{RECEPTACLES.as_posix()}` for our "
        f"targets on our static types, median sizes from `{ASSETS.as_posix()}`, move rate from "
        "Table II (`pipeline/placement_stats.py`)."
    )
    say("HOMER routines")
    outputs["priors/homer_routines.json"] = jsonio.dumps(
        homer_routines_json(HOMER_SOURCE.root(source))
    )
    lines.append(
        "- `priors/homer_routines.json`: per HOMER household, search object and time of day "
        "(07:30, 13:00, 18:30, 22:30), the days the object's place was each HOMER place, from "
        f"`sources/{HOMER.as_posix()}/` (`pipeline/homer.py`; its PLACE_TYPES and TARGET_OBJECTS map "
        "HOMER places and objects onto ours)."
    )
    files = {
        "homer": homer_files(),
        "ithor": sorted(
            {Path(f"ai2thor/ithor_scenes/{r.source_scene}.json") for h in heldout for r in h.rooms}
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
        "procthor_houses": sorted(p for p in houses.values() if not p.is_absolute()),
        "procthor_db": [ASSETS, RECEPTACLES],
    }
    ithor = [*built.values(), *heldout]
    if ithor:
        rearr_lines, files["rearrangement"] = _rearrangement(source, ithor, outputs, notes, say)
        lines += rearr_lines
    return lines, files


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
        uncovered = [r.source_scene for r in home.rooms if r.source_scene not in episodes.by_scene]
        if uncovered:
            # The schedules that need this file name the home's FloorPlans when it is missing.
            notes.append(
                f"rearrangement/{home.name}: not derived, no episodes for {', '.join(uncovered)}"
            )
            continue
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
