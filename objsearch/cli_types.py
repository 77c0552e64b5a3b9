"""argparse helpers: every option of every subcommand is checked before a command runs.

This module holds the parser (:class:`Parser`), the options several commands share (output
format, progress, camera, perception, localisation, inputs, renamed spellings, lists) and the
progress lines; the ``type=`` converters live by concern in :mod:`objsearch.cli_values` (numbers,
names, paths, times) and :mod:`objsearch.cli_endpoints` (hosts, ports, endpoints), re-exported
here, so every command reaches all of them as ``cli_types.<name>``.

Each converter raises :class:`argparse.ArgumentTypeError` with a message naming the valid range
or form; :class:`Parser` turns that into ``objsearch: error: …`` and exit status 2.
``tests/test_cli_types.py`` and the bad-input battery (``tests/test_cli_bad_inputs.py``) check
that every option uses one of these.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Callable, Iterable, Iterator, Sequence
from typing import Any, NoReturn, TypeVar

from objsearch.cli_endpoints import (
    host,
    host_port,
    optional_host_port,
    ray_address,
    split_host_port,
    zenoh_endpoint,
)
from objsearch.cli_values import (
    ALPHA,
    MAX_SCENE,
    MAX_SEEDED_SCENES,
    SCENE,
    SCENES,
    SEED,
    byte_size,
    date,
    day_time,
    dir_path,
    existing_dir,
    existing_file,
    existing_path,
    file_path,
    float_list,
    float_range,
    int_list,
    int_range,
    log_or_lake,
    name_list,
    new_path,
    number_spans,
    sql,
    strategy,
    subset_of,
    text,
)

#: The most processes a command starts, whatever ``--workers`` says; the job count caps it too.
MAX_WORKERS = 64

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
    from objsearch.agent.detector_model import (
        CONFIRMATIONS,
        DRAWS,
        OVERRIDES,
        PRESETS,
        RELOOKS,
        REPORTS,
        STOP_MISSES,
    )

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
        "fp_recurrence": "with --confirmation consistent: P(a false report recurs at its spot)",
    }
    for name, (low, high) in OVERRIDES.items():
        p.add_argument(
            "--" + name.replace("_", "-"),
            type=float_range(low, high),
            metavar="X",
            help=f"{helps[name]}, {low:g}-{high:g} (the preset's)",
        )
    p.add_argument(
        "--confirmation",
        type=text,
        choices=CONFIRMATIONS,
        default=None,
        help="how a confirming look counts: score (a report by its score alone, a miss by the "
        "miss probability) or consistent (both against the chance --fp-recurrence that a false "
        "report recurs at its spot) (the preset's: consistent for realistic, score for harsh)",
    )
    p.add_argument(
        "--draws",
        type=text,
        choices=DRAWS,
        default=None,
        help="how the simulated detector's random draws are keyed: place (by the search, the "
        "object and the viewpoint it is seen from: strategies on the same schedule and seed meet "
        "the same luck at the same place) or view (by the view's index in the run, as runs before "
        "2026-12-07 did) (place)",
    )
    p.add_argument(
        "--reports",
        type=text,
        choices=REPORTS,
        default=None,
        help="what a report that is no sighting (score or mask too low) tells the agent's memory "
        "of the day: evidence (its likelihood ratio: the class is likelier there) or misses (a "
        "miss, as runs before 2026-12-07's second amendment counted it) (evidence)",
    )
    p.add_argument(
        "--relook",
        type=text,
        choices=RELOOKS,
        default=None,
        help="after an inspection that missed the target: off (move on; come back in a revisit "
        "pass) or likeliest (look again from where the robot stands while that stop is still "
        "likelier than every stop left in the pass) (likeliest; off for perfect)",
    )
    p.add_argument(
        "--stop-misses",
        type=text,
        choices=STOP_MISSES,
        default=None,
        help="what is left of a stop's chance after n inspections of it that missed: pooled (the "
        "stop's miss averaged over its statics, to the n-th power) or per-static (each static's "
        "own miss to the n-th power, averaged: a static seen badly keeps its chance) (per-static; "
        "pooled for perfect)",
    )


def perception_params(args: argparse.Namespace) -> dict[str, Any] | None:
    """The run spec's ``params.perception`` the options name; None for a perfect detector (a run
    that records none, so its log is what it always was)."""
    from objsearch.agent.detector_model import OVERRIDES, preset

    overrides = {
        name: value for name in OVERRIDES if (value := getattr(args, name, None)) is not None
    }
    model = preset(
        getattr(args, "perception", "perfect"),
        getattr(args, "confirmation", None),
        getattr(args, "draws", None),
        getattr(args, "reports", None),
        getattr(args, "relook", None),
        getattr(args, "stop_misses", None),
        **overrides,
    )
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


#: The modules whose converters validate a value (:func:`is_validated`).
VALIDATING_MODULES = frozenset({__name__, "objsearch.cli_values", "objsearch.cli_endpoints"})


def is_validated(convert: object) -> bool:
    """Whether an argparse ``type`` comes from these helpers (the battery test checks every one)."""
    return getattr(convert, "__module__", None) in VALIDATING_MODULES


def workers(args: argparse.Namespace) -> int:
    """The processes ``--workers`` asks for: 0 means min(2, cores) (a runner also never starts
    more processes than there are jobs)."""
    return max(1, args.workers if args.workers else min(2, os.cpu_count() or 1))


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


#: The helpers every command reaches as ``cli_types.<name>``: this module's own and the
#: converters of :mod:`objsearch.cli_values` and :mod:`objsearch.cli_endpoints`.
__all__ = [
    "ALPHA",
    "LIST",
    "MAX_SCENE",
    "MAX_SEEDED_SCENES",
    "MAX_WORKERS",
    "OLD_SPACED_LIST",
    "OUTPUT_FORMATS",
    "SCENE",
    "SCENES",
    "SEED",
    "VALIDATING_MODULES",
    "Converter",
    "Deprecated",
    "ListAction",
    "Parser",
    "byte_size",
    "camera_option",
    "date",
    "day_time",
    "dir_path",
    "existing_dir",
    "existing_file",
    "existing_path",
    "file_path",
    "float_list",
    "float_range",
    "format_option",
    "host",
    "host_port",
    "input_argument",
    "int_list",
    "int_range",
    "is_validated",
    "localisation_option",
    "localisation_params",
    "log_line",
    "log_lines",
    "log_or_lake",
    "name_list",
    "new_path",
    "number_spans",
    "optional_host_port",
    "perception_option",
    "perception_params",
    "progress",
    "progress_bar",
    "progress_option",
    "ray_address",
    "renamed",
    "split_host_port",
    "sql",
    "strategy",
    "subset_of",
    "text",
    "workers",
    "zenoh_endpoint",
]
