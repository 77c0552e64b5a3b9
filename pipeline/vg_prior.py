"""Visual Genome co-occurrence counts per vocabulary class (the inputs of the paper's Eq. 2), in
each reading the public data allows (``docs/paper-readings.md``, "Eq. 2: which prior"):

- ``vg-cooccurrence``: C(d) and C(d, s) summed over the Visual Genome names of each class (the
  paper merges aliases). Dense: almost every pair has a count.
- ``vg-single-name``: the same matrix without the alias merge — one Visual Genome name per class
  (the first of ``vg_names``: "sink", "dining table", "bathtub", "toilet paper").
- ``vg-hoz-masked``: ``vg-cooccurrence`` with C(d, s) set to 0 where a published object-adjacency
  graph (HOZ's 83×83 binary matrix over the AI2-THOR 1.0 vocabulary) knows both classes and links
  none of their AI2-THOR types; a pair with a class the graph does not know keeps its count.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .errors import SourceDataError
from .sourceinfo import HOZ, VSGM
from .sources import HOZ_ADJACENCY, VG_MATRIX, CooccurrenceMatrix, require
from .vocabulary import SEMI_DYNAMIC_CLASSES, STATIC_CLASSES, SemiDynamicClass, StaticClass

NOTES = (
    "C(d) and C(d, s) are sums over the Visual Genome names of each class (the paper merges "
    "aliases). A sum counts an image once per name it contains, so an image showing both 'sink' "
    "and 'sink basin' is counted twice; Rel = C(d, s) / C(d) can therefore exceed its true value "
    "and consumers must clip Rel to [0, 1]. The source matrix is symmetric; the diagonal is the "
    "number of images containing the name."
)
SINGLE_NAME_NOTES = (
    "C(d) and C(d, s) over one Visual Genome name per class (the first of the class's vg_names), "
    "without the alias merge: the reading of Eq. 2 that takes each class's plain name only."
)
HOZ_NOTES = (
    "vg-cooccurrence counts, masked by HOZ's binary object adjacency (symmetrised: a and b are "
    "adjacent if either row links them). C(d, s) is set to 0 when both classes have an AI2-THOR "
    "type in HOZ's vocabulary and no type of d is adjacent to a type of s; a pair with a class HOZ "
    "does not know (see hoz_unknown) keeps its count. Table includes the AI2-THOR 1.0 type "
    "TableTop. C(d) is unchanged."
)

#: Prior name → the file ``objsearch data build`` writes (``objsearch.agent.session.PRIOR_FILES``
#: reads the same table; a test checks they agree).
PRIOR_FILES = {
    "vg-cooccurrence": "priors/visual_genome.json",
    "vg-single-name": "priors/vg_single_name.json",
    "vg-hoz-masked": "priors/vg_hoz_masked.json",
}
#: AI2-THOR 1.0 names HOZ uses for a class beyond the class's current AI2-THOR types.
HOZ_EXTRA_TYPES = {"Table": ("TableTop",)}


def _check_names(matrix: CooccurrenceMatrix) -> None:
    classes: tuple[StaticClass | SemiDynamicClass, ...] = (*STATIC_CLASSES, *SEMI_DYNAMIC_CLASSES)
    for cls in classes:
        for name in cls.vg_names:
            if name not in matrix.names:
                raise SourceDataError(
                    matrix.path,
                    f"the Visual Genome prior of class {cls.name}",
                    f"name {name!r} is not a row of the co-occurrence matrix",
                )


def image_count(matrix: CooccurrenceMatrix, names: tuple[str, ...]) -> int:
    return sum(matrix.count(n, n) for n in names)


def pair_count(matrix: CooccurrenceMatrix, a: tuple[str, ...], b: tuple[str, ...]) -> int:
    return sum(matrix.count(x, y) for x in a for y in b if x != y)


def _provenance(name: str, notes: str, source_sha256: str) -> dict[str, Any]:
    return {
        "format": "objsearch.prior/1",
        "prior": name,
        "source": VG_MATRIX.as_posix(),
        "source_repo": VSGM.repo,
        "source_commit": VSGM.commit,
        "source_path_in_repo": VSGM.upstream_path,
        "source_sha256": source_sha256,
        "licence": VSGM.licence,
        "notes": notes,
    }


def vg_prior_json(matrix: CooccurrenceMatrix, source_sha256: str) -> dict[str, Any]:
    """``vg-cooccurrence``: alias-merged image co-occurrence."""
    _check_names(matrix)
    return {
        **_provenance("vg-cooccurrence", NOTES, source_sha256),
        "image_counts": {d.name: image_count(matrix, d.vg_names) for d in SEMI_DYNAMIC_CLASSES},
        "pair_counts": {
            d.name: {s.name: pair_count(matrix, d.vg_names, s.vg_names) for s in STATIC_CLASSES}
            for d in SEMI_DYNAMIC_CLASSES
        },
    }


def single_name_prior_json(matrix: CooccurrenceMatrix, source_sha256: str) -> dict[str, Any]:
    """``vg-single-name``: co-occurrence of each class's first Visual Genome name only."""
    _check_names(matrix)
    return {
        **_provenance("vg-single-name", SINGLE_NAME_NOTES, source_sha256),
        "image_counts": {d.name: image_count(matrix, d.vg_names[:1]) for d in SEMI_DYNAMIC_CLASSES},
        "pair_counts": {
            d.name: {
                s.name: pair_count(matrix, d.vg_names[:1], s.vg_names[:1]) for s in STATIC_CLASSES
            }
            for d in SEMI_DYNAMIC_CLASSES
        },
    }


@dataclass(frozen=True)
class Adjacency:
    """A binary object-adjacency graph over AI2-THOR types (symmetrised on load)."""

    names: frozenset[str]
    edges: frozenset[frozenset[str]]
    path: Path

    def linked(self, a: str, b: str) -> bool:
        return frozenset((a, b)) in self.edges


def load_adjacency(source: Path, needed_for: str) -> Adjacency:
    path = require(source / HOZ_ADJACENCY, needed_for)
    try:
        with path.open(encoding="utf-8", newline="") as handle:
            rows = list(csv.reader(handle))
        names = [n.strip() for n in rows[0]]
        cells = [[int(c) for c in row] for row in rows[1:]]
    except (IndexError, ValueError, UnicodeDecodeError) as exc:
        raise SourceDataError(path, needed_for, f"unexpected adjacency CSV ({exc})") from exc
    if len(cells) != len(names) or any(len(r) != len(names) for r in cells):
        raise SourceDataError(path, needed_for, "adjacency matrix is not square")
    if any(c not in (0, 1) for r in cells for c in r):
        raise SourceDataError(path, needed_for, "adjacency matrix is not binary")
    edges = frozenset(
        frozenset((names[i], names[j]))
        for i, row in enumerate(cells)
        for j, c in enumerate(row)
        if c and i != j
    )
    return Adjacency(frozenset(names), edges, path)


def _hoz_types(cls: StaticClass | SemiDynamicClass, graph: Adjacency) -> tuple[str, ...]:
    types = (*cls.thor_types, *HOZ_EXTRA_TYPES.get(cls.name, ()))
    return tuple(t for t in types if t in graph.names)


def hoz_masked_prior_json(
    matrix: CooccurrenceMatrix, graph: Adjacency, source_sha256: str, hoz_sha256: str
) -> dict[str, Any]:
    """``vg-hoz-masked``: ``vg-cooccurrence`` masked by the HOZ adjacency (see the module doc)."""
    base = vg_prior_json(matrix, source_sha256)
    classes: tuple[StaticClass | SemiDynamicClass, ...] = (*SEMI_DYNAMIC_CLASSES, *STATIC_CLASSES)
    unknown = sorted(c.name for c in classes if not _hoz_types(c, graph))
    masked: list[list[str]] = []
    pair_counts: dict[str, dict[str, int]] = {}
    for d in SEMI_DYNAMIC_CLASSES:
        row: dict[str, int] = {}
        for s in STATIC_CLASSES:
            count = int(base["pair_counts"][d.name][s.name])
            dt, st = _hoz_types(d, graph), _hoz_types(s, graph)
            if dt and st and not any(graph.linked(a, b) for a in dt for b in st):
                if count:
                    masked.append([d.name, s.name])
                count = 0
            row[s.name] = count
        pair_counts[d.name] = row
    return {
        **base,
        **_provenance("vg-hoz-masked", HOZ_NOTES, source_sha256),
        "mask_source": HOZ_ADJACENCY.as_posix(),
        "mask_repo": HOZ.repo,
        "mask_commit": HOZ.commit,
        "mask_sha256": hoz_sha256,
        "mask_licence": HOZ.licence,
        "hoz_unknown": unknown,
        "masked_pairs": masked,
        "pair_counts": pair_counts,
    }
