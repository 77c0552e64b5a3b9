"""`verify_log` and `repair_log`: the explicit way past corruption, which keeps what it removes."""

from __future__ import annotations

from pathlib import Path

import pytest

from objsearch.cli import main
from objsearch.events import CorruptLogError, EventLog, LogLockedError, read_log
from objsearch.events.repair import repair_log, verify_log

RUN = "00000000-0000-4000-8000-0000000000bb"


def _write(directory: Path, n: int) -> bytes:
    with EventLog.open(directory, "robot", run_id=RUN, wall_clock=lambda: 1) as log:
        for i in range(n):
            log.append("search_failed", {"reason": f"r{i}"}, time_ns=i)
    return (directory / "events.log").read_bytes()


def test_verify_reads_a_clean_log_and_names_the_first_problem(tmp_path: Path) -> None:
    data = _write(tmp_path, 5)
    result = verify_log(tmp_path)
    assert (result.events, result.last_seq, result.durable_seq, result.run_id) == (5, 5, 5, RUN)
    lines = data.splitlines(keepends=True)
    lines[3] = lines[3].replace(b'"r3"', b'"r7"')
    (tmp_path / "events.log").write_bytes(b"".join(lines))
    with pytest.raises(CorruptLogError, match="line 4"):
        verify_log(tmp_path)


def test_repair_converts_crlf_back_and_keeps_the_original(tmp_path: Path) -> None:
    data = _write(tmp_path, 4)
    (tmp_path / "events.log").write_bytes(data.replace(b"\n", b"\r\n"))
    with pytest.raises(CorruptLogError, match="CR LF"):
        list(read_log(tmp_path))
    result = repair_log(tmp_path)
    assert result.changed and result.kept_events == 4 and result.removed_bytes == 0
    assert (tmp_path / "events.log").read_bytes() == data
    assert result.quarantine is not None
    assert result.quarantine.read_bytes() == data.replace(b"\n", b"\r\n")
    assert [e.payload["reason"] for e in read_log(tmp_path)] == ["r0", "r1", "r2", "r3"]


def test_repair_keeps_the_clean_prefix_and_every_removed_byte(tmp_path: Path) -> None:
    data = _write(tmp_path, 6)
    lines = data.splitlines(keepends=True)
    lines[2] = lines[2].replace(b'"r2"', b'"rX"')
    damaged = b"".join(lines)
    (tmp_path / "events.log").write_bytes(damaged)
    result = repair_log(tmp_path)
    cut = sum(map(len, lines[:2]))
    assert (result.kept_events, result.removed_bytes, result.removed_lines) == (
        2,
        len(damaged) - cut,
        4,
    )
    assert result.quarantine == tmp_path / f"events.log.repair-{cut}"
    assert (tmp_path / "events.log").read_bytes() + result.quarantine.read_bytes() == damaged
    assert result.missing_seqs == (3, 6)  # acknowledged, now only in the quarantine file
    with EventLog.open(tmp_path, "robot") as log:  # writable again, from seq 3
        assert log.append("search_failed", {"reason": "after"}, time_ns=9).seq == 3
    assert repair_log(tmp_path).changed is False


def test_repair_refuses_while_a_writer_holds_the_log(tmp_path: Path) -> None:
    _write(tmp_path, 1)
    with EventLog.open(tmp_path, "robot"), pytest.raises(LogLockedError):
        repair_log(tmp_path)


def test_cli_refuses_a_damaged_log_then_repairs_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    data = _write(tmp_path, 3)
    (tmp_path / "events.log").write_bytes(data.replace(b"\n", b"\r\n"))
    assert main(["log", "verify", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("objsearch: error: corrupt event log") and "line 1 (byte offset 0)" in err
    assert main(["log", "repair", str(tmp_path)]) == 0
    assert "converted CR LF" in capsys.readouterr().out
    assert main(["log", "verify", str(tmp_path)]) == 0
    assert "ok: " in capsys.readouterr().out


def test_deleting_the_lock_file_does_not_let_a_second_writer_in(tmp_path: Path) -> None:
    _write(tmp_path, 1)
    with EventLog.open(tmp_path, "robot"):
        (tmp_path / "LOCK").unlink()
        with pytest.raises(LogLockedError):
            EventLog.open(tmp_path, "robot")


def test_a_writer_whose_log_is_deleted_stops_acknowledging(tmp_path: Path) -> None:
    from objsearch.events import LogClosedError

    _write(tmp_path, 1)
    with EventLog.open(tmp_path, "robot") as log:
        (tmp_path / "events.log").unlink()
        with pytest.raises(LogClosedError, match="deleted"):
            log.append("search_failed", {"reason": "lost"}, time_ns=5)


@pytest.mark.parametrize("damage", ["crlf", "flip-last", "cut-at-record"])
def test_a_search_on_a_damaged_log_is_refused_and_changes_nothing(
    tmp_path: Path, damage: str, capsys: pytest.CaptureFixture[str]
) -> None:
    log = tmp_path / "log"
    assert main(["search", "--target", "Apple", "--start", "kitchen-1", "--log", str(log)]) == 0
    data = (log / "events.log").read_bytes()
    lines = data.splitlines(keepends=True)
    if damage == "crlf":
        damaged = data.replace(b"\n", b"\r\n")
    elif damage == "flip-last":
        last = bytearray(lines[-1])
        last[10] ^= 0x04
        damaged = b"".join(lines[:-1]) + bytes(last)
    else:
        damaged = b"".join(lines[:-3])
    (log / "events.log").write_bytes(damaged)
    before = {p.name: p.read_bytes() for p in log.iterdir()}
    capsys.readouterr()
    assert main(["search", "--target", "Cup", "--start", "kitchen-1", "--log", str(log)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("objsearch: error: corrupt event log") and "byte offset" in err
    assert {p.name: p.read_bytes() for p in log.iterdir()} == before
