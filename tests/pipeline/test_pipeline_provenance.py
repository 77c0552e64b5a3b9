"""PROVENANCE.md names a source only for files that came from it: a ProcTHOR house a user gives
with ``--procthor`` from outside the shared data's own houses is listed apart, with its sha256 and
no repository or licence claimed for it."""

from __future__ import annotations

import shutil
from pathlib import Path

from objsearch.pipeline.provenance import is_shared_house, provenance_md, sha256

SHARED_HOUSE = Path("procthor_houses/houses_20/house_3.json")
OTHER_HOUSE = Path("procthor_houses/elsewhere/temp.json")


def test_only_the_shared_datas_own_houses_are_attributed_to_its_sources() -> None:
    for own in ("houses_20/house_0.json", "klbr/house_4.json", "house_100.json",
                "procthor_train_1.json"):  # fmt: skip
        assert is_shared_house(Path("procthor_houses", own))
    for other in ("mq/temp.json", "houses_20/more/house_1.json", "houses_21/house_1.json"):
        assert not is_shared_house(Path("procthor_houses", other))
    assert not is_shared_house(Path("elsewhere/house_100.json"))


def test_a_house_from_elsewhere_is_listed_apart_with_no_source_claimed(
    shared_data: Path, tmp_path: Path
) -> None:
    source = tmp_path / "source"
    source.mkdir()
    for part in ("ai2thor", "vg"):
        (source / part).symlink_to(shared_data / part)
    (source / SHARED_HOUSE).parent.mkdir(parents=True)
    shutil.copyfile(shared_data / SHARED_HOUSE, source / SHARED_HOUSE)
    (source / OTHER_HOUSE).parent.mkdir(parents=True)
    shutil.copyfile(shared_data / SHARED_HOUSE, source / OTHER_HOUSE)
    text = provenance_md(
        source,
        {},
        "objsearch data build",
        [],
        extra_files={"procthor_houses": [SHARED_HOUSE, OTHER_HOUSE]},
        paper_tables=False,
    )
    section = text.split("### `procthor_houses`")[1].split("###")[0]
    attributed, apart = section.split("- Other house files given with `--procthor`")
    assert "zhiyuan-gao/procthor" in attributed and SHARED_HOUSE.as_posix() in attributed
    assert OTHER_HOUSE.as_posix() not in attributed
    assert OTHER_HOUSE.as_posix() in apart and "zhiyuan-gao" not in apart
    assert sha256(source / OTHER_HOUSE) in apart
    assert "not known to this build" in apart
