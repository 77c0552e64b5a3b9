"""The object vocabulary: the paper's static classes, its eight targets, and dynamic agents.

This module is the single source; ``data/vocabulary.json`` is written from it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

# One threshold for every class. A 640x480 image with a 90 degree horizontal field of view has a
# focal length of 320 px, so an object presenting A m^2 to the camera at d metres covers about
# 320^2 * A / d^2 pixels. 100 px (a 10x10 px blob) then keeps the smallest targets (apple, phone,
# toilet paper, about 0.01 m^2) visible to ~3 m, i.e. across a typical iTHOR room, while a far
# glimpse through a door does not count. The paper gives no number; nothing in the data argues for
# per-class values, so one documented number beats eight invented ones.
MIN_MASK_AREA_PX = 100


@dataclass(frozen=True)
class StaticClass:
    name: str
    thor_types: tuple[str, ...]
    vg_names: tuple[str, ...]


@dataclass(frozen=True)
class SemiDynamicClass:
    name: str
    thor_types: tuple[str, ...]
    vg_names: tuple[str, ...]
    aliases: tuple[str, ...]
    min_mask_area_px: int = MIN_MASK_AREA_PX


@dataclass(frozen=True)
class DynamicClass:
    name: str
    aliases: tuple[str, ...]


STATIC_CLASSES: tuple[StaticClass, ...] = (
    StaticClass("Sink", ("Sink", "SinkBasin"), ("sink", "sink basin")),
    StaticClass(
        "Table",
        ("DiningTable", "CoffeeTable", "SideTable", "CounterTop"),
        ("dining table", "coffee table", "side table", "counter top"),
    ),
    StaticClass("Microwave", ("Microwave",), ("microwave",)),
    StaticClass("Fridge", ("Fridge",), ("fridge",)),
    StaticClass("Shelf", ("Shelf",), ("shelf",)),
    StaticClass("Sofa", ("Sofa",), ("sofa",)),
    StaticClass("Bed", ("Bed",), ("bed",)),
    StaticClass("Toilet", ("Toilet",), ("toilet",)),
    StaticClass("Bathtub", ("Bathtub", "BathtubBasin"), ("bathtub", "bathtub basin")),
    StaticClass("StoveBurner", ("StoveBurner",), ("stove burner",)),
    StaticClass("Desk", ("Desk",), ("desk",)),
)

SEMI_DYNAMIC_CLASSES: tuple[SemiDynamicClass, ...] = (
    SemiDynamicClass("Apple", ("Apple",), ("apple",), ("apple", "apples")),
    SemiDynamicClass("Cup", ("Cup",), ("cup",), ("cup", "cups")),
    SemiDynamicClass("Bowl", ("Bowl",), ("bowl",), ("bowl", "bowls")),
    SemiDynamicClass(
        "Phone",
        ("CellPhone",),
        ("cell phone",),
        ("phone", "cellphone", "cell phone", "mobile phone", "smartphone"),
    ),
    SemiDynamicClass("Laptop", ("Laptop",), ("laptop",), ("laptop", "laptop computer")),
    SemiDynamicClass("Vase", ("Vase",), ("vase",), ("vase",)),
    SemiDynamicClass("Pillow", ("Pillow",), ("pillow",), ("pillow", "cushion")),
    SemiDynamicClass(
        "ToiletPaper",
        ("ToiletPaper",),
        ("toilet paper", "toilet paper roll"),
        ("toiletpaper", "toilet paper", "toilet paper roll", "toilet roll"),
    ),
)

DYNAMIC_CLASSES: tuple[DynamicClass, ...] = (
    DynamicClass("Person", ("person", "human", "people", "man", "woman", "child")),
    DynamicClass("Dog", ("dog", "puppy")),
    DynamicClass("Cat", ("cat", "kitten")),
)

STATIC_BY_THOR_TYPE: dict[str, StaticClass] = {t: c for c in STATIC_CLASSES for t in c.thor_types}
SEMI_DYNAMIC_BY_THOR_TYPE: dict[str, SemiDynamicClass] = {
    t: c for c in SEMI_DYNAMIC_CLASSES for t in c.thor_types
}
STATIC_NAMES: tuple[str, ...] = tuple(c.name for c in STATIC_CLASSES)
SEMI_DYNAMIC_NAMES: tuple[str, ...] = tuple(c.name for c in SEMI_DYNAMIC_CLASSES)

NOTES = (
    "Aliases are lower-case; match them case-insensitively after collapsing whitespace. "
    f"min_mask_area_px = {MIN_MASK_AREA_PX} for every class, for a 640x480 camera with a 90 degree "
    "horizontal field of view (focal length 320 px): a target presenting ~0.01 m^2 (apple, phone, "
    "toilet paper) stays above it out to ~3 m. Table groups four AI2-THOR types because AI2-THOR "
    "and Visual Genome have no plain 'table'."
)


def vocabulary_json() -> dict[str, Any]:
    return {
        "format": "objsearch.vocabulary/1",
        "notes": NOTES,
        "static": {
            c.name: {"thor_types": list(c.thor_types), "vg_names": list(c.vg_names)}
            for c in STATIC_CLASSES
        },
        "semi_dynamic": {
            c.name: {
                "thor_types": list(c.thor_types),
                "vg_names": list(c.vg_names),
                "aliases": list(c.aliases),
                "min_mask_area_px": c.min_mask_area_px,
            }
            for c in SEMI_DYNAMIC_CLASSES
        },
        "dynamic": {c.name: {"aliases": list(c.aliases)} for c in DYNAMIC_CLASSES},
    }
