"""Values of the command line's options (argparse ``type=`` converters): numbers in a range,
names and lists of them, paths, dates and times of the week.

Each returns the value or raises :class:`argparse.ArgumentTypeError` with a message naming the
valid range or form; :class:`objsearch.cli_types.Parser` turns that into ``objsearch: error: …``
and exit status 2. Every command reaches them as ``cli_types.<name>`` (re-exported there).
"""

from __future__ import annotations

import argparse
import math
import os
import re
import stat
from collections.abc import Callable
from pathlib import Path

#: Every schedule (Table II, stats-<seed>, rearr-<seed>) has scenes 1-10.
MAX_SCENE = 10
#: Longest seeded schedule ``bench homes --scenes`` asks for (a routine schedule has 84 scenes:
#: 21 days of four).
MAX_SEEDED_SCENES = 84


def _typed(name: str, convert: Callable[[str], object]) -> Callable[[str], object]:
    # argparse names the type in "invalid <name> value" messages and the battery test reads
    # __module__ to check that every option is validated here.
    convert.__name__ = name
    convert.__qualname__ = name
    return convert


def _bounds(lo: float | None, hi: float | None) -> str:
    if lo is not None and hi is not None:
        return f"between {lo:g} and {hi:g}"
    if lo is not None:
        return f"at least {lo:g}"
    return f"at most {hi:g}"


def int_range(lo: int | None = None, hi: int | None = None) -> Callable[[str], int]:
    """An integer in ``[lo, hi]`` (either end may be open)."""

    def convert(text: str) -> int:
        try:
            value = int(text.strip())
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"expected a whole number {_bounds(lo, hi)}, not {text!r}"
            ) from None
        if (lo is not None and value < lo) or (hi is not None and value > hi):
            raise argparse.ArgumentTypeError(f"must be {_bounds(lo, hi)}, not {value}")
        return value

    return _typed("int_range", convert)  # type: ignore[return-value]


def float_range(
    lo: float | None = None, hi: float | None = None, *, lo_open: bool = False
) -> Callable[[str], float]:
    """A finite number in ``[lo, hi]`` (``(lo, hi]`` with ``lo_open``); never NaN or infinite."""

    def describe() -> str:
        if lo_open and lo is not None:
            return f"above {lo:g}" + (f" and at most {hi:g}" if hi is not None else "")
        return _bounds(lo, hi)

    def convert(text: str) -> float:
        try:
            value = float(text.strip())
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"expected a number {describe()}, not {text!r}"
            ) from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"must be a finite number {describe()}, not {text}")
        low_bad = lo is not None and (value <= lo if lo_open else value < lo)
        if low_bad or (hi is not None and value > hi):
            raise argparse.ArgumentTypeError(f"must be {describe()}, not {value:g}")
        return value

    return _typed("float_range", convert)  # type: ignore[return-value]


def byte_size(lo: int, hi: int) -> Callable[[str], int]:
    """A size in bytes such as ``1GB``, ``512MiB`` or ``2GiB``, in ``[lo, hi]``."""

    def convert(text: str) -> int:
        from objsearch.events.sql_limits import format_size, parse_size

        try:
            value = parse_size(text)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None
        if not lo <= value <= hi:
            raise argparse.ArgumentTypeError(
                f"must be between {format_size(lo)} and {format_size(hi)}, not {text.strip()}"
            )
        return value

    return _typed("byte_size", convert)  # type: ignore[return-value]


def text(value: str) -> str:
    """Non-empty text on one line (names, labels, SQL keeps its own newlines: see :func:`sql`)."""
    if not value.strip():
        raise argparse.ArgumentTypeError("must not be empty")
    if any(ord(c) < 32 or ord(c) == 127 for c in value):
        raise argparse.ArgumentTypeError(f"must not hold control characters: {value!r}")
    return value


def sql(value: str) -> str:
    """A non-empty SQL text (newlines and tabs allowed)."""
    if not value.strip():
        raise argparse.ArgumentTypeError("the query is empty")
    if "\0" in value:
        raise argparse.ArgumentTypeError("the query holds a NUL character")
    if any("\udc80" <= c <= "\udcff" for c in value):
        # An ASCII locale (LC_ALL=C) hands UTF-8 arguments over as surrogate escapes.
        try:
            value = os.fsencode(value).decode("utf-8")
        except UnicodeError:
            raise argparse.ArgumentTypeError("the query is not UTF-8 text") from None
    return value


def int_list(lo: int | None = None, hi: int | None = None) -> Callable[[str], list[int]]:
    """A comma-separated list of integers, each in ``[lo, hi]``."""
    one = int_range(lo, hi)

    def convert(value: str) -> list[int]:
        parts = [p for p in value.split(",") if p.strip()]
        if not parts:
            raise argparse.ArgumentTypeError(f"expected numbers {_bounds(lo, hi)}, got nothing")
        return [one(p) for p in parts]

    return _typed("int_list", convert)  # type: ignore[return-value]


def float_list(lo: float | None = None, hi: float | None = None) -> Callable[[str], list[float]]:
    """A comma-separated list of finite numbers, each in ``[lo, hi]``."""
    one = float_range(lo, hi)

    def convert(value: str) -> list[float]:
        parts = [p for p in value.split(",") if p.strip()]
        if not parts:
            raise argparse.ArgumentTypeError(f"expected numbers {_bounds(lo, hi)}, got nothing")
        return [one(p) for p in parts]

    return _typed("float_list", convert)  # type: ignore[return-value]


def name_list(value: str) -> list[str]:
    """A comma-separated list of non-empty names."""
    parts = [p.strip() for p in value.split(",")]
    if not any(parts):
        raise argparse.ArgumentTypeError("expected comma-separated names, got nothing")
    if not all(parts):
        raise argparse.ArgumentTypeError(f"an empty name in {value!r}")
    return [text(p) for p in parts]


def number_spans(lo: int, hi: int) -> Callable[[str], list[int]]:
    """Comma-separated numbers or ``A-B`` spans (``11-14``, ``2,5-6``), each in ``[lo, hi]``;
    sorted, without repeats."""
    one = int_range(lo, hi)

    def convert(value: str) -> list[int]:
        parts = [p.strip() for p in value.split(",")]
        if not all(parts):
            raise argparse.ArgumentTypeError(
                f"expected numbers or spans like 11-14 {_bounds(lo, hi)}, got {value!r}"
            )
        found: set[int] = set()
        for part in parts:
            first, sep, last = part.partition("-")
            a, b = one(first), one(last) if sep else one(first)
            if b < a:
                raise argparse.ArgumentTypeError(f"the span {part!r} runs backwards")
            found.update(range(a, b + 1))
        return sorted(found)

    return _typed("number_spans", convert)  # type: ignore[return-value]


def subset_of(choices: tuple[str, ...]) -> Callable[[str], list[str]]:
    """A comma-separated subset of ``choices``, in the order given, without repeats."""

    def convert(value: str) -> list[str]:
        names = name_list(value)
        bad = [n for n in names if n not in choices]
        if bad:
            raise argparse.ArgumentTypeError(
                f"unknown {', '.join(bad)}; expected a comma-separated subset of "
                f"{', '.join(choices)}"
            )
        return list(dict.fromkeys(names))

    return _typed("subset_of", convert)  # type: ignore[return-value]


def strategy(value: str) -> str:
    """A search strategy's name: a registered one, or one ending in ``+cover``."""
    from objsearch.agent.errors import ObjsearchError
    from objsearch.agent.strategies import split_strategy

    try:
        split_strategy(value)
    except ObjsearchError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return value


def _kind(value: str) -> str:
    """``missing``, ``dir`` or ``file`` for a path given on the command line."""
    if not value.strip():
        raise argparse.ArgumentTypeError("the path is empty")
    if "\0" in value:
        raise argparse.ArgumentTypeError("the path holds a NUL character")
    try:
        st = os.stat(value)
    except FileNotFoundError:
        return "missing"
    except NotADirectoryError:
        raise argparse.ArgumentTypeError(f"{value}: a part of it is a file, not a folder") from None
    except OSError as exc:  # a name too long, a loop of links, no permission to look
        raise argparse.ArgumentTypeError(f"{value[:200]}: {exc.strerror or exc}") from None
    return "dir" if stat.S_ISDIR(st.st_mode) else "file"


def _not_under_a_file(value: str) -> None:
    for parent in Path(value).absolute().parents:
        kind = _kind(str(parent))
        if kind == "file":
            raise argparse.ArgumentTypeError(f"{parent} is a file, not a folder")
        if kind == "dir":
            return


def existing_dir(value: str) -> str:
    """A folder that exists."""
    kind = _kind(value)
    if kind == "missing":
        raise argparse.ArgumentTypeError(f"no such folder: {value}")
    if kind != "dir":
        raise argparse.ArgumentTypeError(f"{value} is a file, not a folder")
    return value


def log_or_lake(value: str) -> str:
    """An event log or lake folder that exists, or a fleet lake on object storage
    (``s3://bucket/prefix``, whose existence the command itself finds out)."""
    if value.startswith("s3://"):
        if not value.removeprefix("s3://").split("/", 1)[0]:
            raise argparse.ArgumentTypeError(f"{value}: no bucket (s3://BUCKET/PREFIX)")
        return value
    if "://" in value:
        raise argparse.ArgumentTypeError(
            f"{value}: only s3:// addresses are supported (or a folder on this machine)"
        )
    return existing_dir(value)


def existing_file(value: str) -> str:
    """A file that exists (not a folder)."""
    kind = _kind(value)
    if kind == "missing":
        raise argparse.ArgumentTypeError(f"no such file: {value}")
    if kind == "dir":
        raise argparse.ArgumentTypeError(f"{value} is a folder, not a file")
    return value


def existing_path(value: str) -> str:
    """A file or folder that exists (a ROS 1 bag is a file, a ROS 2 bag a folder)."""
    if _kind(value) == "missing":
        raise argparse.ArgumentTypeError(f"no such file or folder: {value}")
    return value


def _output_path(value: str, wrong: str, what: str) -> str:
    """An output ``what`` (file or folder): it may not exist yet, but it is not of kind ``wrong``."""
    kind = _kind(value)
    if kind == wrong:
        raise argparse.ArgumentTypeError(
            f"{value} is a {'file' if wrong == 'file' else 'folder'}, not a {what}"
        )
    if kind == "missing":
        _not_under_a_file(value)
    return value


def dir_path(value: str) -> str:
    """A folder to write or append to: it may not exist yet, but it is not a file."""
    return _output_path(value, "file", "folder")


def file_path(value: str) -> str:
    """A file to write: it may not exist yet, but it is not a folder."""
    return _output_path(value, "dir", "file")


def new_path(value: str) -> str:
    """A file or folder that does not exist yet (outputs that are never overwritten)."""
    if _kind(value) != "missing":
        raise argparse.ArgumentTypeError(f"{value} already exists; choose a new name")
    _not_under_a_file(value)
    return value


_DATE = re.compile(r"\d{4}-\d{2}-\d{2}")


def date(value: str) -> str:
    """A calendar date, YYYY-MM-DD."""
    import datetime as dt

    try:
        if not _DATE.fullmatch(value):
            raise ValueError
        dt.date.fromisoformat(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a date YYYY-MM-DD, not {value!r}") from None
    return value


_WEEKDAYS = ("mon", "tue", "wed", "thu", "fri", "sat", "sun")
_DAY_TIME = re.compile(r"(?:(?P<day>[A-Za-z]{3})\s+)?(?P<h>\d{1,2}):(?P<m>\d{2})")


def day_time(value: str) -> tuple[int, int] | None:
    """A time of the week: ``now`` (the local clock), ``HH:MM`` (today), ``DAY HH:MM`` (DAY one of
    mon … sun), or ``last`` (None: the time of the log's latest search). Returns (weekday 0-6,
    minute after midnight)."""
    import datetime as dt

    text = value.strip().lower()
    now = dt.datetime.now()
    if text == "last":
        return None
    if text == "now":
        return now.weekday(), now.hour * 60 + now.minute
    m = _DAY_TIME.fullmatch(text)
    day = m["day"] if m else None
    if m is None or int(m["h"]) > 23 or int(m["m"]) > 59 or (day and day not in _WEEKDAYS):
        raise argparse.ArgumentTypeError(
            f"expected now, last, HH:MM or DAY HH:MM (DAY one of {', '.join(_WEEKDAYS)}), "
            f"not {value!r}"
        )
    weekday = _WEEKDAYS.index(day) if day else now.weekday()
    return weekday, int(m["h"]) * 60 + int(m["m"])


#: Options several subcommands share.
SEED = int_range(0, 2**32 - 1)
#: Eq. 3's weight of the relation term; beyond 1000 it only magnifies rounding.
ALPHA = float_range(0.0, 1000.0)
SCENE = int_range(1, MAX_SCENE)
SCENES = int_list(1, MAX_SCENE)
