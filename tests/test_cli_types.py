"""The shared option types: what each accepts and how it says no."""

from __future__ import annotations

import argparse
import io
import sys
from pathlib import Path

import pytest

from objsearch import cli_types as t
from objsearch.cli import expected_errors


def _rejects(convert: object, value: str, match: str) -> None:
    assert callable(convert)
    with pytest.raises(argparse.ArgumentTypeError, match=match):
        convert(value)


def test_int_range() -> None:
    workers = t.int_range(1, 64)
    assert workers("1") == 1 and workers(" 64 ") == 64
    _rejects(workers, "0", "between 1 and 64, not 0")
    _rejects(workers, "300", "between 1 and 64, not 300")
    _rejects(workers, "1.5", "whole number between 1 and 64")
    _rejects(t.int_range(0), "-1", "at least 0")


@pytest.mark.parametrize("bad", ["nan", "inf", "-inf", "1e400", "NaN", "Infinity"])
def test_float_range_refuses_what_is_not_finite(bad: str) -> None:
    _rejects(t.float_range(0, 10), bad, "finite")


def test_float_range_bounds() -> None:
    hz = t.float_range(0.0, 200.0, lo_open=True)
    assert hz("0.5") == 0.5 and hz("200") == 200.0
    _rejects(hz, "0", "above 0 and at most 200")
    _rejects(hz, "1e9", r"not 1e\+09")
    _rejects(hz, "fast", "expected a number")


def test_text_and_lists() -> None:
    assert t.text("Apple") == "Apple"
    _rejects(t.text, "", "empty")
    _rejects(t.text, "x\n", "control characters")
    assert t.name_list(" Apple, Vase ") == ["Apple", "Vase"]
    _rejects(t.name_list, ",", "nothing")
    _rejects(t.name_list, "a,,b", "empty name")
    assert t.int_list(1, 10)("1,3") == [1, 3]
    _rejects(t.int_list(1, 10), "1,99", "not 99")
    assert t.float_list(0, 1)("1, 0.85,0.5") == [1.0, 0.85, 0.5]
    _rejects(t.float_list(0, 1), "1,1.5", "between 0 and 1, not 1.5")
    _rejects(t.float_list(0, 1), "0.5,nan", "finite")
    _rejects(t.float_list(0, 1), ",", "expected numbers between 0 and 1, got nothing")
    _rejects(t.sql, " \n", "empty")


def test_number_spans_and_subsets() -> None:
    spans = t.number_spans(1, 24)
    assert spans("11-14") == [11, 12, 13, 14] and spans("5,2,4-5") == [2, 4, 5]
    _rejects(spans, "14-11", "runs backwards")
    _rejects(spans, "20-25", "not 25")
    _rejects(spans, "1,,2", "spans like 11-14")
    kinds = t.subset_of(("lost-grid-points", "dropped-rooms"))
    assert kinds("dropped-rooms,lost-grid-points,dropped-rooms") == [
        "dropped-rooms",
        "lost-grid-points",
    ]
    _rejects(kinds, "everything", "unknown everything; expected a comma-separated subset of")


def test_paths(tmp_path: Path) -> None:
    (tmp_path / "f").write_text("x")
    folder, file, missing = str(tmp_path), str(tmp_path / "f"), str(tmp_path / "none")
    assert t.existing_dir(folder) == folder
    _rejects(t.existing_dir, file, "is a file, not a folder")
    _rejects(t.existing_dir, missing, "no such folder")
    assert t.existing_file(file) == file
    _rejects(t.existing_file, folder, "is a folder, not a file")
    _rejects(t.existing_path, missing, "no such file or folder")
    assert t.dir_path(missing) == missing
    _rejects(t.dir_path, file, "is a file")
    _rejects(t.dir_path, str(tmp_path / "f" / "sub"), "is a file, not a folder")
    _rejects(t.file_path, folder, "is a folder")
    _rejects(t.new_path, file, "already exists")
    for convert in (t.existing_dir, t.existing_file, t.dir_path, t.file_path, t.new_path):
        _rejects(convert, "", "empty")


def test_host_port_and_endpoints() -> None:
    assert t.split_host_port("8765", host_optional=True) == (None, 8765)
    assert t.split_host_port("[::1]:9000") == ("::1", 9000)
    assert t.split_host_port("robot-1.local:7447") == ("robot-1.local", 7447)
    _rejects(t.optional_host_port, "garbage", "port must be a number")
    _rejects(t.optional_host_port, "70000", "0-65535")
    _rejects(t.optional_host_port, "::1:9000", "IPv6")
    _rejects(t.host_port, "7447", "HOST:PORT")
    _rejects(t.host, "not a host", "not a host name")
    assert t.zenoh_endpoint("tcp/127.0.0.1:7447") == "tcp/127.0.0.1:7447"
    assert t.zenoh_endpoint("tcp/[::1]:0") == "tcp/[::1]:0"
    assert t.zenoh_endpoint("unixsock-stream//tmp/z.sock") == "unixsock-stream//tmp/z.sock"
    _rejects(t.zenoh_endpoint, "garbage", "PROTO/ADDRESS")
    _rejects(t.zenoh_endpoint, "tcp/host", "HOST:PORT")
    _rejects(t.zenoh_endpoint, "carrier-pigeon/1:2", "unknown protocol")
    assert t.ray_address("auto") == "auto" and t.ray_address("ray://head:10001")
    _rejects(t.ray_address, "ray://", "HOST:PORT")


def test_dates() -> None:
    assert t.date("2026-01-31") == "2026-01-31"
    for bad in ("2026-02-30", "26-1-1", "today", "2026-01-31\n"):
        _rejects(t.date, bad, "YYYY-MM-DD")


def test_scenes_match_the_schedules() -> None:
    from objsearch.sim.stats_schedule import SCENES

    assert t.MAX_SCENE == SCENES


def test_one_error_root_is_expected() -> None:
    from objsearch.agent.errors import ObjsearchError
    from objsearch.events import EventStoreError
    from objsearch.pipeline.errors import BuildError

    assert expected_errors() == (ObjsearchError,)
    assert issubclass(EventStoreError, ObjsearchError) and issubclass(BuildError, ObjsearchError)
    assert not issubclass(RuntimeError, expected_errors())  # bugs keep their traceback


def test_progress_stays_off_a_pipe(monkeypatch: pytest.MonkeyPatch) -> None:
    # Not a terminal (a pipe, a log file): no progress line.
    piped = io.StringIO()
    monkeypatch.setattr(sys, "stderr", piped)
    assert list(t.progress(range(3), "count", " items")) == [0, 1, 2]
    assert piped.getvalue() == ""


@pytest.mark.parametrize("command", [["audit", "LOG"], ["replay", "LOG"], ["map", "build"]])
def test_long_commands_take_no_progress(command: list[str], tmp_path: Path) -> None:
    from objsearch.cli import build_parser

    argv = [c.replace("LOG", str(tmp_path)) for c in command]
    args = build_parser().parse_args([*argv, "--no-progress"])
    assert args.no_progress is True


@pytest.mark.parametrize(
    "command", [["bench", "homes"], ["search", "Apple", "--start", "kitchen-1"]]
)
def test_the_confirmation_model_is_an_option_recorded_in_the_run_spec(command: list[str]) -> None:
    from objsearch.cli import build_parser

    parse = build_parser().parse_args
    # Each preset's own model by default: realistic consistent (q 0.1), harsh score (not recorded).
    default = t.perception_params(parse([*command, "--perception", "realistic"]))
    assert default is not None
    assert (default["confirmation"], default["fp_recurrence"]) == ("consistent", 0.1)
    harsh = t.perception_params(parse([*command, "--perception", "harsh"]))
    assert harsh is not None and "confirmation" not in harsh
    score = t.perception_params(
        parse([*command, "--perception", "realistic", "--confirmation", "score"])
    )
    assert score is not None and "confirmation" not in score
    args = parse(
        [
            *command,
            "--perception",
            "harsh",
            "--confirmation",
            "consistent",
            "--fp-recurrence",
            "0.3",
        ]
    )
    chosen = t.perception_params(args)
    assert chosen is not None
    assert (chosen["confirmation"], chosen["fp_recurrence"]) == ("consistent", 0.3)
    with pytest.raises(SystemExit):
        parse([*command, "--confirmation", "sometimes"])


@pytest.mark.parametrize(
    "command", [["bench", "homes"], ["search", "Apple", "--start", "kitchen-1"]]
)
def test_relook_is_an_option_recorded_in_the_run_spec_only_when_on(command: list[str]) -> None:
    """The modelled presets relook (the amendment of 21:12 UTC); ``off`` is left out of the run
    spec, so a spec that names none replays as the runs before the option."""
    from objsearch.cli import build_parser

    parse = build_parser().parse_args
    default = t.perception_params(parse([*command, "--perception", "realistic"]))
    assert default is not None and default["relook"] == "likeliest"
    off = t.perception_params(parse([*command, "--perception", "realistic", "--relook", "off"]))
    assert off is not None and "relook" not in off
    harsh = t.perception_params(parse([*command, "--perception", "harsh"]))
    assert harsh is not None and harsh["relook"] == "likeliest"
    # a perfect detector records no perception model (its run spec is what it always was)
    assert t.perception_params(parse([*command, "--relook", "likeliest"])) is None
    with pytest.raises(SystemExit):
        parse([*command, "--relook", "sometimes"])


@pytest.mark.parametrize(
    "command", [["bench", "homes"], ["search", "Apple", "--start", "kitchen-1"]]
)
def test_stop_misses_is_an_option_recorded_in_the_run_spec_only_when_per_static(
    command: list[str],
) -> None:
    """The modelled presets count misses per static (the amendment of 23:03 UTC); ``pooled``
    (every run before the option) is left out of the run spec."""
    from objsearch.cli import build_parser

    parse = build_parser().parse_args
    default = t.perception_params(parse([*command, "--perception", "realistic"]))
    assert default is not None and default["stop_misses"] == "per-static"
    pooled = t.perception_params(
        parse([*command, "--perception", "harsh", "--stop-misses", "pooled"])
    )
    assert pooled is not None and "stop_misses" not in pooled
    with pytest.raises(SystemExit):
        parse([*command, "--stop-misses", "sometimes"])
