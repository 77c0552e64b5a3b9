"""Where each raw source comes from: repository, revision, licence (per shared PROVENANCE.md)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from .sources import ALFRED_LAYOUTS, HOZ_ADJACENCY, ITHOR_SCENES, VG_MATRIX


@dataclass(frozen=True)
class SourceInfo:
    key: str
    local: Path  # relative to the source root
    repo: str
    revision: str  # a commit, or a release where no commit is known
    commit: str | None
    upstream_path: str
    licence: str
    licence_file: Path  # relative to the source root; the full licence text
    copyright: str
    #: The source travels with this repository (``sources/``, with its licence and how it was
    #: extracted) instead of coming from the shared data folder, which does not have it.
    vendored: bool = False

    @property
    def shown_root(self) -> str:
        """Where a reader finds the source's files, as PROVENANCE.md names it."""
        return "sources" if self.vendored else "shared/data"

    def root(self, source: Path) -> Path:
        """The folder this source's files are read from (``source``: the shared data folder)."""
        return VENDORED_SOURCES if self.vendored else source


#: The repository's own copy of sources the shared data folder lacks. The wheel ships it as
#: ``objsearch/sources`` (pyproject's package-data), which is the same path from this module.
VENDORED_SOURCES = Path(__file__).resolve().parents[1] / "sources"

ALFRED = SourceInfo(
    key="alfred",
    local=ALFRED_LAYOUTS,
    repo="askforalfred/alfred",
    revision="commit f91f4c0c96c7a29f33d0557f86b0a21035379b3b",
    commit="f91f4c0c96c7a29f33d0557f86b0a21035379b3b",
    upstream_path="gen/layouts/",
    licence="MIT",
    licence_file=ALFRED_LAYOUTS / "LICENSE.alfred",
    copyright="Copyright (c) 2019 ALFRED",
)

ITHOR = SourceInfo(
    key="ithor",
    local=ITHOR_SCENES,
    repo="allenai/procthor",
    revision="PyPI package procthor 0.0.1.dev2",
    commit=None,
    upstream_path=(
        "procthor/databases/ai2thor-object-metadata.json (compacted per scene, 4 decimals, "
        "by the shared-data curators)"
    ),
    licence="Apache-2.0",
    licence_file=ITHOR_SCENES / "LICENSE.procthor",
    copyright="Copyright 2022 Allen Institute for AI",
)

VSGM = SourceInfo(
    key="vsgm",
    local=VG_MATRIX,
    repo="roy402/VSGM",
    revision="commit 15844232b8eebb5ec7301a9a48a3210925114da9",
    commit="15844232b8eebb5ec7301a9a48a3210925114da9",
    upstream_path="graph_analysis/visual_genome/relationship_matrics_with_word.csv",
    licence="MIT",
    licence_file=VG_MATRIX.parent / "LICENSE.VSGM",
    copyright="Copyright (c) [2021] [Cheng-Yu Tsai and others]",
)

HOZ = SourceInfo(
    key="hoz",
    local=HOZ_ADJACENCY,
    repo="sx-zhang/HOZ",
    revision="commit 4add8e74fcfbcac3f009a51dddd40a6b6e17e2ac",
    commit="4add8e74fcfbcac3f009a51dddd40a6b6e17e2ac",
    upstream_path="adjmat_83x83.csv (binary object adjacency over the AI2-THOR 1.0 vocabulary)",
    licence="MIT",
    licence_file=HOZ_ADJACENCY.parent / "LICENSE.HOZ",
    copyright="Copyright (c) 2021 JJJJasper",
)

ALL_SOURCES: tuple[SourceInfo, ...] = (ITHOR, ALFRED, VSGM, HOZ)

PROCTHOR_HOUSES = SourceInfo(
    key="procthor_houses",
    local=Path("procthor_houses"),
    repo="zhiyuan-gao/procthor (houses_20); allenai/ai2thor (procthor_train_1.json)",
    revision=(
        "commit 7f073e665088a96b4b80c268d924d108cd127e0b; allenai/ai2thor commit "
        "0c2389e9d7a961834ef127608bf7e85323d51ce2"
    ),
    commit=None,
    upstream_path="houses_20/house_*.json; ai2thor/tests/data/arm/procthor_train_1.json",
    licence="Apache-2.0",
    licence_file=Path("procthor_houses/LICENSE.zhiyuan-gao-procthor"),
    copyright="Copyright 2022 Allen Institute for AI (ProcTHOR) and the repository's authors",
)

PROCTHOR_DB = SourceInfo(
    key="procthor_db",
    local=Path("ai2thor/procthor_db"),
    repo="allenai/procthor",
    revision="commit 53d5bd4c8c96a699e6a615dc390abb670cc9d353",
    commit="53d5bd4c8c96a699e6a615dc390abb670cc9d353",
    upstream_path="procthor/databases/",
    licence="Apache-2.0",
    licence_file=Path("ai2thor/procthor_db/LICENSE.procthor"),
    copyright="Copyright 2022 Allen Institute for AI",
)

REARRANGEMENT = SourceInfo(
    key="rearrangement",
    local=Path("ai2thor/rearrangement"),
    repo="allenai/ai2thor-rearrangement",
    revision="commit 7fcf881b09ddd88be37ee87bbeea319c01e62bc4",
    commit="7fcf881b09ddd88be37ee87bbeea319c01e62bc4",
    upstream_path="data/2022/{train,val}.pkl.gz (converted to JSON by the shared-data curators)",
    licence="Apache-2.0",
    licence_file=Path("ai2thor/rearrangement/LICENSE.ai2thor-rearrangement"),
    copyright="Copyright 2021 Allen Institute for AI",
)

HOMER = SourceInfo(
    key="homer",
    local=Path("homer"),
    repo="Maithili/SpatioTemporalObjectTracking (HOMER, Patel & Chernova, CoRL 2022)",
    revision="commit f4ce4141d3210ba2c18879c64450db6906e534ff",
    commit="f4ce4141d3210ba2c18879c64450db6906e534ff",
    upstream_path=(
        "data/householdsDifferent/household*/processed/ (common_data.json as upstream; the day "
        "files compacted to days.json, see sources/homer/README.md)"
    ),
    licence="MIT",
    licence_file=Path("homer/LICENSE.SpatioTemporalObjectTracking"),
    copyright="Copyright (c) 2022 Maithili Patel",
    vendored=True,
)

EXTRA_SOURCES: tuple[SourceInfo, ...] = (PROCTHOR_HOUSES, PROCTHOR_DB, REARRANGEMENT, HOMER)
