"""Object categories (static / semi-dynamic / dynamic) and the names users and datasets give them."""

from __future__ import annotations

import enum
import json
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from objsearch.agent.datapaths import data_dir
from objsearch.agent.errors import DataFileError, NotATargetError, UnknownObjectClassError


class Category(enum.Enum):
    STATIC = "static"
    SEMI_DYNAMIC = "semi_dynamic"
    DYNAMIC = "dynamic"


@dataclass(frozen=True, slots=True)
class ObjectClass:
    name: str
    category: Category
    thor_types: tuple[str, ...]
    aliases: tuple[str, ...]
    min_mask_area_px: float


def _norm(name: str) -> str:
    return "".join(ch for ch in name.lower() if ch.isalnum())


@dataclass(frozen=True)
class Vocabulary:
    """Every class the agent knows, with lookup by class name, alias or AI2-THOR type."""

    classes: Mapping[str, ObjectClass]

    @classmethod
    def from_dict(cls, doc: Mapping[str, Any]) -> Vocabulary:
        classes: dict[str, ObjectClass] = {}
        for category in Category:
            for name, spec in doc.get(category.value, {}).items():
                classes[name] = ObjectClass(
                    name=name,
                    category=category,
                    thor_types=tuple(spec.get("thor_types", ())),
                    aliases=tuple(spec.get("aliases", ())),
                    min_mask_area_px=float(spec.get("min_mask_area_px", 0.0)),
                )
        return cls(classes)

    @classmethod
    def load(cls, path: Path | None = None, data: Path | None = None) -> Vocabulary:
        """The vocabulary at ``path``, else that of the data folder ``data`` (None:
        ``datapaths.data_dir()``)."""
        path = path or data_dir(data) / "vocabulary.json"
        return cls.from_dict(read_json(path, "the object vocabulary"))

    def _lookup(self) -> dict[str, str]:
        table: dict[str, str] = {}
        for oc in self.classes.values():
            for key in (oc.name, *oc.aliases, *oc.thor_types):
                table.setdefault(_norm(key), oc.name)
        return table

    def resolve(self, name: str) -> ObjectClass:
        """The class a user-typed or dataset name refers to (case, spaces and '_' ignored)."""
        found = self._lookup().get(_norm(name))
        if found is None:
            raise UnknownObjectClassError(
                f"unknown object class {name!r}; known search targets: "
                f"{', '.join(self.names(Category.SEMI_DYNAMIC))}"
            )
        return self.classes[found]

    def resolve_target(self, name: str) -> ObjectClass:
        oc = self.resolve(name)
        if oc.category is not Category.SEMI_DYNAMIC:
            raise NotATargetError(
                f"{oc.name!r} is a {oc.category.value.replace('_', '-')} object and cannot be a "
                f"search target; targets are semi-dynamic: "
                f"{', '.join(self.names(Category.SEMI_DYNAMIC))}"
            )
        return oc

    def names(self, category: Category) -> tuple[str, ...]:
        return tuple(n for n, oc in self.classes.items() if oc.category is category)

    def class_of_thor_type(self, thor_type: str) -> ObjectClass | None:
        for oc in self.classes.values():
            if thor_type in oc.thor_types:
                return oc
        return None


def read_json(path: Path, what: str) -> Any:
    """Read a derived-data JSON file, with a clear error when it is missing or broken."""
    try:
        with path.open(encoding="utf-8") as fh:
            return json.load(fh)
    except FileNotFoundError:
        raise DataFileError(
            f"missing data file {path} ({what}); run `objsearch data build --source ../shared/data`"
        ) from None
    except json.JSONDecodeError as exc:
        raise DataFileError(f"data file {path} ({what}) is not valid JSON: {exc}") from None
