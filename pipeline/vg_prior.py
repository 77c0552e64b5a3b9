"""Visual Genome co-occurrence counts per vocabulary class (the inputs of the paper's Eq. 2)."""

from __future__ import annotations

from typing import Any

from .errors import SourceDataError
from .sourceinfo import VSGM
from .sources import VG_MATRIX, CooccurrenceMatrix
from .vocabulary import SEMI_DYNAMIC_CLASSES, STATIC_CLASSES, SemiDynamicClass, StaticClass

NOTES = (
    "C(d) and C(d, s) are sums over the Visual Genome names of each class (the paper merges "
    "aliases). A sum counts an image once per name it contains, so an image showing both 'sink' "
    "and 'sink basin' is counted twice; Rel = C(d, s) / C(d) can therefore exceed its true value "
    "and consumers must clip Rel to [0, 1]. The source matrix is symmetric; the diagonal is the "
    "number of images containing the name."
)


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


def vg_prior_json(matrix: CooccurrenceMatrix, source_sha256: str) -> dict[str, Any]:
    _check_names(matrix)
    return {
        "format": "objsearch.prior/1",
        "source": VG_MATRIX.as_posix(),
        "source_repo": VSGM.repo,
        "source_commit": VSGM.commit,
        "source_path_in_repo": VSGM.upstream_path,
        "source_sha256": source_sha256,
        "licence": VSGM.licence,
        "notes": NOTES,
        "image_counts": {d.name: image_count(matrix, d.vg_names) for d in SEMI_DYNAMIC_CLASSES},
        "pair_counts": {
            d.name: {s.name: pair_count(matrix, d.vg_names, s.vg_names) for s in STATIC_CLASSES}
            for d in SEMI_DYNAMIC_CLASSES
        },
    }
