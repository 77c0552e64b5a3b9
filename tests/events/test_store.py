"""The store is handed to every reader and writer of events: none falls back to a bare one."""

from __future__ import annotations

import importlib
import inspect
import pkgutil
from collections.abc import Iterator
from typing import Any

import pytest

import objsearch.events
from objsearch.agent.catalogue import STORE
from objsearch.events.log import EventLog
from objsearch.events.log_read import read_log

#: The lake's modules (and its SQL, which imports them) are being split by another change, which
#: makes their store required.
_LATER = ("lake", "sql")


def _functions_taking_a_store() -> Iterator[tuple[str, Any]]:
    for info in pkgutil.iter_modules(objsearch.events.__path__):
        if info.name.startswith(_LATER):
            continue
        module = importlib.import_module(f"objsearch.events.{info.name}")
        for name, value in vars(module).items():
            if getattr(value, "__module__", None) != module.__name__:
                continue
            members = [(name, value)]
            if inspect.isclass(value):
                members = [
                    (f"{name}.{attr}", getattr(value, attr))
                    for attr, member in vars(value).items()
                    if isinstance(member, classmethod | staticmethod) or inspect.isfunction(member)
                ]
            for qualified, function in members:
                if callable(function) and "store" in _parameters(function):
                    yield f"{module.__name__}.{qualified}", function


def _parameters(function: Any) -> dict[str, inspect.Parameter]:
    try:
        return dict(inspect.signature(function).parameters)
    except (TypeError, ValueError):
        return {}


def test_no_reader_or_writer_falls_back_to_a_bare_store() -> None:
    found = dict(_functions_taking_a_store())
    # The walk finds the functions it is about (a walk that found none would pass anything).
    assert {"objsearch.events.log_read.read_log", "objsearch.events.log.EventLog.open"} <= set(
        found
    )
    defaulted = sorted(
        name
        for name, function in found.items()
        if _parameters(function)["store"].default is not inspect.Parameter.empty
    )
    assert defaulted == []


def test_a_reader_without_a_store_is_refused(tmp_path: Any) -> None:
    with EventLog.open(tmp_path, "s", store=STORE) as log:
        log.append("search_failed", {"reason": "r"}, time_ns=1)
    with pytest.raises(TypeError, match="store"):
        read_log(tmp_path)  # type: ignore[call-arg]
