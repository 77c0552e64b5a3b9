"""Where each raw source comes from: repository, revision, licence (per shared PROVENANCE.md)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from .sources import ALFRED_LAYOUTS, ITHOR_SCENES, VG_MATRIX


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

ALL_SOURCES: tuple[SourceInfo, ...] = (ITHOR, ALFRED, VSGM)
