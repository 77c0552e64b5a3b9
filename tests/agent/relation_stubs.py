"""A relation model with no opinion, for tests of the searcher's own arithmetic: subclasses
give the values they need (``instance_rel``)."""

from __future__ import annotations


class NoRelations:
    """Every place's value 0; folds nothing."""

    tasks_folded = 0
    last_seq = 0

    def apply(self, event: object) -> None:
        pass

    def rel(self, dynamic: str, static: str) -> float:
        return 0.0

    def instance_rel(self, dynamic: str, static_id: str, static_class: str) -> float:
        return 0.0

    @property
    def state(self) -> dict[tuple[str, str], float]:
        return {}

    def as_table(self) -> dict[str, dict[str, float]]:
        return {}
