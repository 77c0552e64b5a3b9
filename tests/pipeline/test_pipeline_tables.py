"""Vocabulary, Visual Genome prior, and the paper's Table I / Table II."""

from __future__ import annotations

import csv
import json
from collections import Counter
from pathlib import Path
from typing import Any

from objsearch.pipeline.build import BuildReport
from objsearch.pipeline.table2 import TABLE2
from objsearch.pipeline.vocabulary import SEMI_DYNAMIC_NAMES, STATIC_NAMES

Built = tuple[Path, BuildReport]


def load(built: Built, rel: str) -> Any:
    return json.loads((built[0] / rel).read_text())


def _csv(shared: Path) -> dict[str, dict[str, int]]:
    with (shared / "vg/VSGM/relationship_matrics_with_word.csv").open() as f:
        rows = list(csv.reader(f))
    return {r[0]: {n: int(v) for n, v in zip(rows[0][1:], r[1:], strict=True)} for r in rows[1:]}


def test_vocabulary_aliases_are_unique_and_include_the_class(built: Built) -> None:
    vocab = load(built, "vocabulary.json")
    assert set(vocab["static"]) == set(STATIC_NAMES)
    assert set(vocab["semi_dynamic"]) == set(SEMI_DYNAMIC_NAMES) and len(SEMI_DYNAMIC_NAMES) == 8
    aliases = [
        a
        for group in ("semi_dynamic", "dynamic")
        for c in vocab[group].values()
        for a in c["aliases"]
    ]
    assert len(aliases) == len(set(aliases)) and all(a == a.lower() for a in aliases)
    for name, c in vocab["semi_dynamic"].items():
        assert name.lower() in c["aliases"] and c["min_mask_area_px"] > 0
    assert {"phone", "cellphone", "cell phone", "mobile phone"} <= set(
        vocab["semi_dynamic"]["Phone"]["aliases"]
    )
    assert vocab["semi_dynamic"]["Phone"]["thor_types"] == ["CellPhone"]


def test_vg_counts_match_the_csv_by_hand(built: Built, shared_data: Path) -> None:
    prior = load(built, "priors/visual_genome.json")
    m = _csv(shared_data)
    assert prior["image_counts"]["Apple"] == m["apple"]["apple"] == 824
    assert (
        prior["pair_counts"]["Apple"]["Sink"] == m["apple"]["sink"] + m["apple"]["sink basin"] == 20
    )
    assert prior["image_counts"]["ToiletPaper"] == 646 + 28
    table = sum(m["cup"][n] for n in ("dining table", "coffee table", "side table", "counter top"))
    assert prior["pair_counts"]["Cup"]["Table"] == table
    assert prior["source_commit"] == "15844232b8eebb5ec7301a9a48a3210925114da9"
    assert set(prior["pair_counts"]) == set(SEMI_DYNAMIC_NAMES)
    assert all(set(row) == set(STATIC_NAMES) for row in prior["pair_counts"].values())


def test_table1_leaves_exactly_one_instance_per_target(built: Built, home: dict[str, Any]) -> None:
    scenario = load(built, "scenarios/table1.json")
    objects = {o["id"]: o for r in home["rooms"] for o in r["objects"]}
    assert set(scenario["removed"]) <= set(objects)
    left = Counter(o["cls"] for oid, o in objects.items() if oid not in scenario["removed"])
    assert left == Counter(dict.fromkeys(SEMI_DYNAMIC_NAMES, 1))
    removed = {(oid.split("/")[0], objects[oid]["cls"]) for oid in scenario["removed"]}
    assert removed == {
        ("living", "Bowl"),
        ("living", "Laptop"),
        ("living", "Pillow"),
        ("bedroom", "Phone"),
        ("bedroom", "Vase"),
        ("bathroom", "ToiletPaper"),
    }
    for cls, oid in scenario["targets"].items():
        assert objects[oid]["cls"] == cls and oid not in scenario["removed"]


def test_table2_resolves_every_cell_to_a_static_of_its_class(
    built: Built, home: dict[str, Any]
) -> None:
    schedule = load(built, "schedules/table2.json")
    targets = load(built, "scenarios/table1.json")["targets"]
    statics = {s["id"]: s for r in home["rooms"] for s in r["statics"]}
    assert [s["scene"] for s in schedule["scenes"]] == list(range(1, 11))
    for k, scene in enumerate(schedule["scenes"]):
        assert set(scene["placements"]) == set(SEMI_DYNAMIC_NAMES)
        for cls, p in scene["placements"].items():
            support = statics[p["support"]]
            assert p["static_class"] == TABLE2[cls][k] == support["cls"]
            assert p["inside"] == support["container"]
            assert p["object"] == targets[cls]
            lo = [c - s / 2 for c, s in zip(support["center"], support["size"], strict=True)]
            hi = [c + s / 2 for c, s in zip(support["center"], support["size"], strict=True)]
            assert all(lo[i] - 0.05 <= p["center"][i] <= hi[i] + 0.05 for i in (0, 1))


def test_table2_transcription() -> None:
    # Spot checks against the paper, including a changed cell ("Bad" = Bed).
    assert TABLE2["Apple"][4] == "Fridge" and TABLE2["Laptop"][2] == "Bed"
    assert TABLE2["ToiletPaper"][4:7] == ("Shelf", "Shelf", "Shelf")
    assert Counter(TABLE2["Phone"]) == Counter({"Table": 6, "Desk": 4})
