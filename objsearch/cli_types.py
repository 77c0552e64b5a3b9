"""argparse ``type=`` helpers: every option of every subcommand is checked before a command runs.

Each helper returns a converter that raises :class:`argparse.ArgumentTypeError` with a message
naming the valid range or form; :class:`Parser` turns that into ``objsearch: error: …`` and exit
status 2. ``tests/objsearch/test_cli_types.py`` and the bad-input battery
(``tests/objsearch/test_cli_bad_inputs.py``) check that every option uses one of these.
"""

from __future__ import annotations

import argparse
import ipaddress
import math
import os
import re
import stat
import sys
from collections.abc import Callable, Iterable, Iterator, Sequence
from pathlib import Path
from typing import Any, NoReturn, TypeVar

#: The most processes a command starts, whatever ``--workers`` says; the job count caps it too.
MAX_WORKERS = 64
#: Every schedule (Table II, stats-<seed>, rearr-<seed>) has scenes 1-10.
MAX_SCENE = 10
#: Longest seeded schedule ``bench homes --scenes`` asks for (a routine schedule has 84 scenes:
#: 21 days of four).
MAX_SEEDED_SCENES = 84

Converter = Callable[[str], object]
T = TypeVar("T")


class Parser(argparse.ArgumentParser):
    """An ArgumentParser whose errors read ``objsearch: error: …`` (exit 2) in every subcommand.

    Arguments whose choices or defaults need a heavy import (the strategies, the simulator's
    cameras) are added by :meth:`defer`: only when this parser parses or shows its help, so
    ``objsearch --help`` and every other command never pay for them.
    """

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        # An option is spelled out: argparse would take `--strat` for `--strategy` silently, and a
        # script so written breaks (or changes meaning) when another option shares the prefix.
        # Subparsers are built with this class too (add_subparsers' default parser_class).
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)

    def defer(self, add: Callable[[argparse.ArgumentParser], object]) -> None:
        """Call ``add(self)`` just before this parser is first used."""
        self.__dict__.setdefault("_deferred", []).append(add)

    def build_deferred(self) -> None:
        """Add the deferred arguments now (a walk over every parser's actions needs them)."""
        deferred = self.__dict__.get("_deferred", [])
        while deferred:
            deferred.pop(0)(self)

    def check(self, problem: Callable[[argparse.Namespace], str | None]) -> None:
        """After parsing, ``problem(args)`` names what is wrong with the command line as a whole
        (an input given neither way), reported as every other parse error."""
        self.__dict__.setdefault("_checks", []).append(problem)

    def parse_known_args(  # type: ignore[override]
        self, args: Sequence[str] | None = None, namespace: argparse.Namespace | None = None
    ) -> tuple[argparse.Namespace, list[str]]:
        self.build_deferred()
        parsed, extras = super().parse_known_args(args, namespace)
        for problem in self.__dict__.get("_checks", []):
            message = problem(parsed)
            if message:
                self.error(message)
        return parsed, extras

    def format_help(self) -> str:
        self.build_deferred()
        return super().format_help()

    def format_usage(self) -> str:
        self.build_deferred()
        return super().format_usage()

    def error(self, message: str) -> NoReturn:
        # The message first, as every other objsearch error; the full usage is one --help away.
        where = self.prog.removeprefix("objsearch").strip()
        self.exit(
            2,
            f"objsearch: error: {where + ': ' if where else ''}{message}\n"
            f"(`{self.prog} --help` lists the options)\n",
        )


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


def dir_path(value: str) -> str:
    """A folder to write or append to: it may not exist yet, but it is not a file."""
    kind = _kind(value)
    if kind == "file":
        raise argparse.ArgumentTypeError(f"{value} is a file, not a folder")
    if kind == "missing":
        _not_under_a_file(value)
    return value


def file_path(value: str) -> str:
    """A file to write: it may not exist yet, but it is not a folder."""
    kind = _kind(value)
    if kind == "dir":
        raise argparse.ArgumentTypeError(f"{value} is a folder, not a file")
    if kind == "missing":
        _not_under_a_file(value)
    return value


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


_HOSTNAME = re.compile(r"[A-Za-z0-9](?:[A-Za-z0-9-]{0,62})(?:\.[A-Za-z0-9](?:[A-Za-z0-9-]{0,62}))*")


def _host(value: str, whole: str) -> str:
    try:
        ipaddress.ip_address(value)
    except ValueError:
        if len(value) > 253 or not _HOSTNAME.fullmatch(value):
            raise argparse.ArgumentTypeError(
                f"{whole!r}: {value!r} is not a host name or IP address"
            ) from None
    return value


def _port(value: str, whole: str) -> int:
    if not value.isdigit() or not 0 <= int(value) <= 65535:
        raise argparse.ArgumentTypeError(f"{whole!r}: the port must be a number 0-65535")
    return int(value)


def split_host_port(value: str, *, host_optional: bool = False) -> tuple[str | None, int]:
    """``HOST:PORT``, ``[IPv6]:PORT`` (or ``PORT`` alone with ``host_optional``)."""
    host, sep, port = value.rpartition(":")
    if not sep:
        if not host_optional:
            raise argparse.ArgumentTypeError(f"expected HOST:PORT, not {value!r}")
        return None, _port(port, value)
    if host.startswith("[") and host.endswith("]"):
        host = host[1:-1]
        try:
            ipaddress.IPv6Address(host)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"{value!r}: {host!r} is not an IPv6 address"
            ) from None
        return host, _port(port, value)
    if not host or ":" in host:
        raise argparse.ArgumentTypeError(
            f"expected {'[HOST:]PORT' if host_optional else 'HOST:PORT'} "
            f"(IPv6 as [addr]:PORT), not {value!r}"
        )
    return _host(host, value), _port(port, value)


def host_port(value: str) -> str:
    """``HOST:PORT`` (IPv6 as ``[addr]:PORT``)."""
    split_host_port(value)
    return value


def optional_host_port(value: str) -> str:
    """``PORT`` or ``HOST:PORT`` (IPv6 as ``[addr]:PORT``)."""
    split_host_port(value, host_optional=True)
    return value


def host(value: str) -> str:
    """A host name or an IP address."""
    return _host(text(value), value)


#: Zenoh locator protocols whose address is HOST:PORT.
_IP_PROTOCOLS = frozenset({"tcp", "udp", "tls", "quic", "ws"})
_OTHER_PROTOCOLS = frozenset({"unixsock-stream", "unixpipe", "serial", "vsock"})


def zenoh_endpoint(value: str) -> str:
    """A zenoh endpoint ``PROTO/ADDRESS`` such as ``tcp/127.0.0.1:7447`` or ``tcp/[::1]:7447``."""
    proto, sep, rest = value.partition("/")
    address = rest.split("?", 1)[0].split("#", 1)[0]
    if not sep or not address:
        raise argparse.ArgumentTypeError(
            f"expected a zenoh endpoint PROTO/ADDRESS such as tcp/127.0.0.1:7447, not {value!r}"
        )
    if proto in _IP_PROTOCOLS:
        split_host_port(address)
    elif proto not in _OTHER_PROTOCOLS:
        known = ", ".join(sorted(_IP_PROTOCOLS | _OTHER_PROTOCOLS))
        raise argparse.ArgumentTypeError(f"{value!r}: unknown protocol {proto!r} (known: {known})")
    return value


def ray_address(value: str) -> str:
    """A Ray cluster address: ``auto``, ``local``, ``HOST:PORT`` or ``ray://HOST:PORT``."""
    if value in ("auto", "local"):
        return value
    rest = value.removeprefix("ray://")
    split_host_port(rest)
    return value


#: Options several subcommands share.
SEED = int_range(0, 2**32 - 1)
#: Eq. 3's weight of the relation term; beyond 1000 it only magnifies rounding.
ALPHA = float_range(0.0, 1000.0)
SCENE = int_range(1, MAX_SCENE)
SCENES = int_list(1, MAX_SCENE)


def camera_option(p: argparse.ArgumentParser) -> None:
    """``--camera``: the simulated search camera (docs/perception.md), recorded in the run
    (added when ``p`` is first used: the choices come from the simulator)."""
    if isinstance(p, Parser):
        p.defer(_add_camera_option)
    else:
        _add_camera_option(p)


def _add_camera_option(p: argparse.ArgumentParser) -> None:
    from objsearch.sim.world import CAMERAS, DEFAULT_CAMERA

    p.add_argument(
        "--camera",
        type=text,
        choices=CAMERAS,
        default=DEFAULT_CAMERA,
        help="simulated search camera: occluding (what a render shows; furniture hides what is "
        f"behind it) or geometric (field of view and box area, no occlusion) ({DEFAULT_CAMERA})",
    )


def perception_option(p: argparse.ArgumentParser) -> None:
    """``--perception PRESET`` and the options that override one of its parameters: the
    simulated detector (docs/perception.md), recorded in the run (added when ``p`` is first
    used, as ``--camera``). :func:`perception_params` reads them."""
    if isinstance(p, Parser):
        p.defer(_add_perception_options)
    else:
        _add_perception_options(p)


def _add_perception_options(p: argparse.ArgumentParser) -> None:
    from objsearch.agent.detector_model import OVERRIDES, PRESETS

    p.add_argument(
        "--perception",
        type=text,
        choices=PRESETS,
        default=PRESETS[0],
        help="simulated detector: perfect (every object in view, nothing false), realistic "
        "(Mask R-CNN's published recall by size, false positives, confusions, scores) or harsh "
        "(half its recall, twice its false positives) (perfect)",
    )
    helps = {
        "recall_scale": "multiply the preset's recall by this",
        "fp_per_image": "false positives of the movable classes per view (Poisson mean)",
        "confusion": "probability that a detection carries a similar class",
        "occluded_recall": "recall factor of an object less than half visible",
        "accept_posterior": "P(real) at which a sighting is confirmed",
    }
    for name, (low, high) in OVERRIDES.items():
        p.add_argument(
            "--" + name.replace("_", "-"),
            type=float_range(low, high),
            metavar="X",
            help=f"{helps[name]}, {low:g}-{high:g} (the preset's)",
        )


def perception_params(args: argparse.Namespace) -> dict[str, Any] | None:
    """The run spec's ``params.perception`` the options name; None for a perfect detector (a run
    that records none, so its log is what it always was)."""
    from objsearch.agent.detector_model import OVERRIDES, preset

    overrides = {
        name: value for name in OVERRIDES if (value := getattr(args, name, None)) is not None
    }
    model = preset(getattr(args, "perception", "perfect"), **overrides)
    return None if model.perfect else model.params()


def localisation_option(p: argparse.ArgumentParser) -> None:
    """``--localisation PRESET``: the simulated robot's pose error (docs/perception.md,
    Localisation), recorded in the run (added when ``p`` is first used, as ``--camera``).
    :func:`localisation_params` reads it."""
    if isinstance(p, Parser):
        p.defer(_add_localisation_option)
    else:
        _add_localisation_option(p)


def _add_localisation_option(p: argparse.ArgumentParser) -> None:
    from objsearch.sim.localisation import PRESETS

    p.add_argument(
        "--localisation",
        type=text,
        choices=PRESETS,
        default=PRESETS[0],
        help="simulated localisation: perfect (the robot knows its pose), realistic (wheel "
        "odometry drift corrected by an AMCL-like localiser with occasional jumps) or harsh "
        "(twice the drift and error, five times the jumps) (perfect)",
    )


def localisation_params(args: argparse.Namespace) -> dict[str, Any] | None:
    """The run spec's ``params.localisation`` the option names; None when perfect (a run that
    records none, so its log is what it always was)."""
    from objsearch.sim.localisation import preset

    model = preset(getattr(args, "localisation", "perfect"))
    return None if model.perfect else model.params()


#: ``--format`` values of a command whose output is a report (``query`` and ``lake ls``, whose
#: output is a table, take ``table``, ``csv`` or ``json``).
OUTPUT_FORMATS = ("text", "json")


class Deprecated(argparse.Action):
    """An old spelling that still works (scripts keep running): it stores into the new
    argument's ``dest`` — ``const`` for a flag such as ``--json``, else its value — and notes
    the new spelling on stderr. Hidden from ``--help``, which shows one way to say each thing.
    ``then``: the new argument's action, to store through (one that appends or extends)."""

    def __init__(
        self,
        option_strings: Sequence[str],
        dest: str,
        *,
        new: str,
        nargs: int | str | None = None,
        const: object = None,
        type: Converter | None = None,
        choices: Iterable[object] | None = None,
        metavar: str | None = None,
        then: argparse.Action | None = None,
    ) -> None:
        super().__init__(
            option_strings,
            dest,
            nargs=nargs,
            const=const,
            default=argparse.SUPPRESS,  # the new argument's default stands
            type=type,
            choices=choices,
            help=argparse.SUPPRESS,
            metavar=metavar,
        )
        self.new = new
        self.then = then

    def __call__(
        self,
        parser: argparse.ArgumentParser,
        namespace: argparse.Namespace,
        values: str | Sequence[Any] | None,
        option_string: str | None = None,
    ) -> None:
        print(f"objsearch: note: {option_string} is deprecated; use {self.new}", file=sys.stderr)
        if self.then is not None:
            self.then(parser, namespace, values, option_string)
        else:
            setattr(namespace, self.dest, self.const if self.nargs == 0 else values)


def renamed(p: argparse.ArgumentParser, old: str, new: argparse.Action) -> None:
    """``old`` as a deprecated spelling of the option ``new`` (same value, same checks)."""
    assert new.type is not None, "a renamed option keeps its validated type"
    p.add_argument(
        old,
        action=Deprecated,
        dest=new.dest,
        new=new.option_strings[0],
        type=new.type,
        choices=new.choices,
        nargs=new.nargs,
        metavar=new.metavar if isinstance(new.metavar, str) else None,
        then=new if isinstance(new, (argparse._AppendAction, ListAction)) else None,
    )


def format_option(
    p: argparse.ArgumentParser,
    json_help: str,
    *,
    choices: tuple[str, ...] = OUTPUT_FORMATS,
    action: type[argparse.Action] | None = None,
    also: tuple[str, ...] = (),
) -> None:
    """``--format text|json`` (``choices[0]`` the default, for a person), the one output-format
    option of every command (DEVELOPERS.md, "CLI conventions"); ``--json`` is its deprecated
    spelling of ``--format json``. ``action`` and ``also`` serve an option that took other,
    now deprecated, values (``record --format ros1``)."""
    p.add_argument(
        "--format",
        action=action or "store",
        type=text,
        choices=(*choices, *also),
        default=choices[0],
        metavar="{" + ",".join(choices) + "}",
        help=f"{', '.join(choices[:-1])} or {choices[-1]} ({choices[0]}); json: {json_help}",
    )
    p.add_argument(
        "--json", action=Deprecated, dest="format", nargs=0, const="json", new="--format json"
    )


def input_argument(
    p: argparse.ArgumentParser,
    dest: str,
    *,
    type: Converter,
    metavar: str,
    help: str,
    old: tuple[str, ...],
    purpose: str = "to read",
) -> None:
    """A command's main input — the log or lake it reads, the object it finds — positional as
    in every command (DEVELOPERS.md, "CLI conventions"); the options in ``old`` named it once and
    still do (deprecated). Either way it lands in ``args.<dest>``; giving neither is a usage
    error ("the METAVAR ``purpose`` is missing")."""
    p.add_argument(dest, nargs="?", type=type, metavar=metavar, help=help)
    for option in old:
        # Their own dest: a positional left empty would overwrite a value given before it.
        p.add_argument(
            option,
            action=Deprecated,
            dest=f"{dest}_option",
            new=f"the positional argument {metavar}",
            type=type,
            metavar=metavar,
        )

    def merged(args: argparse.Namespace) -> str | None:
        given = getattr(args, dest), getattr(args, f"{dest}_option", None)
        if None not in given and given[0] != given[1]:
            return f"{metavar} given twice ({given[0]} and {given[1]}); give one"
        setattr(args, dest, given[0] or given[1])
        if hasattr(args, f"{dest}_option"):
            delattr(args, f"{dest}_option")
        return None if getattr(args, dest) else f"the {metavar} {purpose} is missing"

    if isinstance(p, Parser):
        p.check(merged)


class ListAction(argparse.Action):
    """A list option: comma-separated (``--targets Apple,Cup``), repeatable (``--targets Apple
    --targets Cup`` is the same), each part checked by ``type`` (which returns a list)."""

    def __call__(
        self,
        parser: argparse.ArgumentParser,
        namespace: argparse.Namespace,
        values: object,
        option_string: str | None = None,
    ) -> None:
        parts = values if isinstance(values, list) and self.nargs == "+" else [values]
        if self.nargs == "+" and isinstance(values, list) and len(values) > 1:
            # The space-separated form some commands took once (record --scenes 1 2).
            print(
                f"objsearch: note: {option_string} takes a comma-separated list; the "
                "space-separated form is deprecated",
                file=sys.stderr,
            )
        earlier = getattr(namespace, self.dest, None)
        found = list(earlier) if isinstance(earlier, list) and earlier is not self.default else []
        for part in parts:
            found += part if isinstance(part, list) else [part]
        setattr(namespace, self.dest, found)


#: ``add_argument(..., type=name_list, **LIST)``: a list option, comma-separated and repeatable.
LIST: dict[str, Any] = {"action": ListAction}
#: As LIST, also taking the space-separated form (``record --scenes 1 2``) with a deprecation
#: note: for the options that once took only that form.
OLD_SPACED_LIST: dict[str, Any] = {"action": ListAction, "nargs": "+"}


def is_validated(convert: object) -> bool:
    """Whether an argparse ``type`` comes from this module (the battery test checks every one)."""
    return getattr(convert, "__module__", None) == __name__


def progress_option(p: argparse.ArgumentParser) -> None:
    """``--no-progress``: the progress line :func:`progress` draws on a terminal."""
    p.add_argument("--no-progress", action="store_true", help="no progress line on stderr")


def progress(
    items: Iterable[T], label: str, unit: str, *, total: int | None = None, enabled: bool = True
) -> Iterable[T]:
    """``items`` as they are consumed, counted on stderr (tqdm) — on a terminal only, so logs
    and pipes get no carriage-return lines; ``enabled=False`` (``--no-progress``) never."""
    bar: Iterable[T] = progress_bar(label, unit, total=total, enabled=enabled, items=items)
    return bar


def log_lines(
    items: Iterable[T],
    label: str,
    unit: str,
    *,
    counts: Callable[[T], bool],
    every: int,
    enabled: bool = True,
) -> Iterator[T]:
    """``items`` as they are consumed; where :func:`progress` draws nothing (stderr is not a
    terminal: a pipe, a log) a line on stderr every ``every`` items ``counts`` holds and one at the
    end, ``audit: 300 tasks read (41 s)``, so a long command is not silent there (DEVELOPERS.md,
    "Progress"); ``enabled=False`` (``--no-progress``) never."""
    import time

    if not enabled or sys.stderr.isatty():
        yield from items
        return
    started, seen = time.monotonic(), 0

    def line() -> None:
        elapsed = time.monotonic() - started
        print(f"{label}: {seen} {unit} read ({elapsed:.0f} s)", file=sys.stderr, flush=True)

    for item in items:
        yield item
        if counts(item):
            seen += 1
            if seen % every == 0:
                line()
    if seen % every:
        line()


def log_line(message: str, *, enabled: bool = True) -> None:
    """One line of a long command's progress on stderr where :func:`progress` draws nothing (not
    a terminal); ``enabled=False`` (``--no-progress``) never."""
    if enabled and not sys.stderr.isatty():
        print(message, file=sys.stderr, flush=True)


def progress_bar(
    label: str,
    unit: str,
    *,
    total: int | None = None,
    enabled: bool = True,
    items: Iterable[object] | None = None,
) -> Any:
    """As :func:`progress`, a bar to ``update()`` by hand (a context manager)."""
    from tqdm import tqdm

    return tqdm(
        items,
        desc=label,
        unit=unit,
        total=total,
        file=sys.stderr,
        disable=None if enabled else True,  # None: off when stderr is not a terminal
        leave=False,
        mininterval=0.5,
    )
