"""`verify_log` and `repair_log`: the explicit way past corruption, which keeps what it removes."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import pytest

from devtools.repair_battery import LINE_DAMAGE, run_repair_battery
from objsearch.agent.catalogue import STORE
from objsearch.cli import main
from objsearch.events import CorruptLogError, EventLog, LogLockedError, read_log
from objsearch.events.envelope import deterministic_event_id
from objsearch.events.repair import repair_log, verify_log

RUN = "00000000-0000-4000-8000-0000000000bb"


def _write(directory: Path, n: int) -> bytes:
    with EventLog.open(directory, "robot", run_id=RUN, wall_clock=lambda: 1, store=STORE) as log:
        for i in range(n):
            log.append("search_failed", {"reason": f"r{i}"}, time_ns=i)
    return (directory / "events.log").read_bytes()


def test_verify_reads_a_clean_log_and_names_the_first_problem(tmp_path: Path) -> None:
    data = _write(tmp_path, 5)
    result = verify_log(tmp_path, store=STORE)
    assert (result.events, result.last_seq, result.durable_seq, result.run_id) == (5, 5, 5, RUN)
    lines = data.splitlines(keepends=True)
    lines[3] = lines[3].replace(b'"r3"', b'"r7"')
    (tmp_path / "events.log").write_bytes(b"".join(lines))
    with pytest.raises(CorruptLogError, match="line 4"):
        verify_log(tmp_path, store=STORE)


def test_repair_converts_crlf_back_and_keeps_the_original(tmp_path: Path) -> None:
    data = _write(tmp_path, 4)
    (tmp_path / "events.log").write_bytes(data.replace(b"\n", b"\r\n"))
    with pytest.raises(CorruptLogError, match="CR LF"):
        list(read_log(tmp_path, store=STORE))
    result = repair_log(tmp_path, store=STORE)
    assert result.changed and result.kept_events == 4 and result.removed_bytes == 0
    assert (tmp_path / "events.log").read_bytes() == data
    assert result.quarantine is not None
    assert result.quarantine.read_bytes() == data.replace(b"\n", b"\r\n")
    assert [e.payload["reason"] for e in read_log(tmp_path, store=STORE)] == [
        "r0",
        "r1",
        "r2",
        "r3",
    ]


def _damage(directory: Path, line: int, edit: Callable[[bytearray], None]) -> bytes:
    lines = (directory / "events.log").read_bytes().splitlines(keepends=True)
    changed = bytearray(lines[line - 1])
    edit(changed)
    lines[line - 1] = bytes(changed)
    damaged = b"".join(lines)
    (directory / "events.log").write_bytes(damaged)
    return damaged


def _reasons(directory: Path) -> list[tuple[int, str]]:
    return [
        (e.seq, e.payload["reason"] if e.type == "search_failed" else e.type)
        for e in read_log(directory, store=STORE)
    ]


def test_a_record_damaged_in_place_is_the_only_one_moved_out(tmp_path: Path) -> None:
    data = _write(tmp_path, 6)
    line3 = data.splitlines(keepends=True)[2]
    damaged = _damage(
        tmp_path, 3, lambda b: b.__setitem__(slice(None), b.replace(b'"r2"', b'"rX"'))
    )
    with pytest.raises(CorruptLogError, match="record at seq 3 is damaged: its bytes were damaged"):
        verify_log(tmp_path, store=STORE)
    result = repair_log(tmp_path, store=STORE)
    assert (result.kept_events, result.kept_last_seq, result.removed_lines) == (5, 6, 1)
    assert [(a.kind, a.first_seq, a.line) for a in result.actions] == [("quarantined", 3, 3)]
    assert result.quarantine is not None
    assert result.quarantine.read_bytes() == damaged.splitlines(keepends=True)[2] != line3
    assert _reasons(tmp_path) == [
        (1, "r0"),
        (2, "r1"),
        (3, "record_quarantined"),
        (4, "r3"),
        (5, "r4"),
        (6, "r5"),
    ]
    marker = list(read_log(tmp_path, store=STORE))[2]
    assert marker.payload["quarantine"] == result.quarantine.name
    assert verify_log(tmp_path, store=STORE).last_seq == 6
    with EventLog.open(
        tmp_path, "robot", store=STORE
    ) as log:  # the next writer continues after seq 6
        after = log.append("search_failed", {"reason": "after"}, time_ns=9)
    assert after.seq == 7
    ids = [e.event_id for e in read_log(tmp_path, store=STORE)]
    assert len(set(ids)) == 7 and deterministic_event_id(RUN, 3) not in ids  # never reused
    assert repair_log(tmp_path, store=STORE).changed is False


def test_a_flipped_bit_is_corrected_and_damaged_checksum_digits_are_rewritten(
    tmp_path: Path,
) -> None:
    data = _write(tmp_path, 6)

    def flip(b: bytearray) -> None:
        b[40] ^= 0x02

    def digit(b: bytearray) -> None:
        b[-3] = ord("g")  # a checksum digit that is not even hex

    for line, edit, kind in ((2, flip, "bit-restored"), (5, digit, "checksum-rewritten")):
        damaged = _damage(tmp_path, line, edit)
        with pytest.raises(CorruptLogError, match=f"record at seq {line} is damaged"):
            verify_log(tmp_path, store=STORE)
        result = repair_log(tmp_path, store=STORE)
        assert [(a.kind, a.first_seq) for a in result.actions] == [(kind, line)]
        assert (tmp_path / "events.log").read_bytes() == data  # exactly as written
        assert result.quarantine is not None
        assert result.quarantine.read_bytes() == damaged.splitlines(keepends=True)[line - 1]
        assert (result.kept_events, result.kept_last_seq) == (6, 6)


def test_records_out_of_order_are_put_back_in_their_order(tmp_path: Path) -> None:
    data = _write(tmp_path, 6)
    lines = data.splitlines(keepends=True)
    lines[2], lines[3] = lines[3], lines[2]  # seq 4 where seq 3 belongs, then seq 3
    (tmp_path / "events.log").write_bytes(b"".join(lines))
    result = repair_log(tmp_path, store=STORE)
    # seq 3's checksum chains from seq 2's and seq 4's from seq 3's, wherever they stand
    assert [(a.kind, a.first_seq, a.line) for a in result.actions] == [("reordered", 4, 3)]
    assert (tmp_path / "events.log").read_bytes() == data
    assert (result.kept_events, result.removed_bytes, result.quarantine) == (6, 0, None)
    assert _reasons(tmp_path) == [(i + 1, f"r{i}") for i in range(6)]


def test_records_that_do_not_belong_are_moved_out_and_their_seqs_stay_taken(
    tmp_path: Path,
) -> None:
    data = _write(tmp_path, 6)
    with EventLog.open(tmp_path / "other", "robot", wall_clock=lambda: 1, store=STORE) as other:
        for i in range(6):
            other.append("search_failed", {"reason": f"r{i}"}, time_ns=i)
    donor = (tmp_path / "other" / "events.log").read_bytes().splitlines(keepends=True)
    lines = data.splitlines(keepends=True)
    lines[2:] = donor[2:]  # spliced: nothing after line 3 belongs to this log
    damaged = b"".join(lines)
    (tmp_path / "events.log").write_bytes(damaged)
    result = repair_log(tmp_path, store=STORE)
    cut = sum(map(len, lines[:2]))
    assert [(a.kind, a.first_seq, a.last_seq) for a in result.actions] == [("cut", 3, 6)]
    assert result.quarantine == tmp_path / f"events.log.repair-{cut}"
    assert result.quarantine.read_bytes() == damaged[cut:]
    assert (result.kept_events, result.kept_last_seq) == (2, 6)
    assert [seq for seq, what in _reasons(tmp_path) if what == "record_quarantined"] == [3, 4, 5, 6]
    with EventLog.open(tmp_path, "robot", store=STORE) as log:
        assert log.append("search_failed", {"reason": "after"}, time_ns=9).seq == 7


def test_acknowledged_records_the_file_lost_are_reported_and_their_seqs_kept(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    data = _write(tmp_path, 6)
    lines = data.splitlines(keepends=True)
    (tmp_path / "events.log").write_bytes(b"".join(lines[:4]))  # cut at a record boundary
    assert main(["log", "repair", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "seqs 5..6 (line 5, byte" in out and "already missing from the file" in out
    assert [seq for seq, what in _reasons(tmp_path) if what == "record_quarantined"] == [5, 6]
    with EventLog.open(tmp_path, "robot", store=STORE) as log:
        assert log.append("search_failed", {"reason": "after"}, time_ns=9).seq == 7


def test_repair_refuses_while_a_writer_holds_the_log(tmp_path: Path) -> None:
    _write(tmp_path, 1)
    with EventLog.open(tmp_path, "robot", store=STORE), pytest.raises(LogLockedError):
        repair_log(tmp_path, store=STORE)


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
    with EventLog.open(tmp_path, "robot", store=STORE):
        (tmp_path / "LOCK").unlink()
        with pytest.raises(LogLockedError):
            EventLog.open(tmp_path, "robot", store=STORE)


def test_a_writer_whose_log_is_deleted_stops_acknowledging(tmp_path: Path) -> None:
    from objsearch.events import LogClosedError

    _write(tmp_path, 1)
    with EventLog.open(tmp_path, "robot", store=STORE) as log:
        (tmp_path / "events.log").unlink()
        with pytest.raises(LogClosedError, match="deleted"):
            log.append("search_failed", {"reason": "lost"}, time_ns=5)


@pytest.mark.parametrize("damage", ["crlf", "flip-last", "cut-at-record"])
def test_a_search_on_a_damaged_log_is_refused_and_changes_nothing(
    tmp_path: Path, damage: str, capsys: pytest.CaptureFixture[str]
) -> None:
    log = tmp_path / "log"
    assert main(["search", "Apple", "--start", "kitchen-1", "--log", str(log)]) == 0
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
    assert main(["search", "Cup", "--start", "kitchen-1", "--log", str(log)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("objsearch: error: corrupt event log") and "byte offset" in err
    assert {p.name: p.read_bytes() for p in log.iterdir()} == before


def _intact_moved_out(written: bytes, directory: Path) -> int:
    kept = set((directory / "events.log").read_bytes().splitlines())
    return sum(1 for line in written.splitlines() if line not in kept)


def test_a_blank_line_or_lines_duplicated_in_place_cost_no_record(tmp_path: Path) -> None:
    """Issue 43: an empty line inserted after line 143 moved 143 records out; three lines
    duplicated in place, 234. The next record is the line chained from the last one kept."""
    damages: list[tuple[str, Callable[[list[bytes]], list[bytes]]]] = [
        ("blank", lambda ls: [*ls[:143], b"\n", *ls[143:]]),
        ("dup3", lambda ls: [*ls[:103], *ls[100:103], *ls[103:]]),
    ]
    for name, damage in damages:
        directory = tmp_path / name
        data = _write(directory, 200)
        lines = data.splitlines(keepends=True)
        damaged = b"".join(damage(lines))
        (directory / "events.log").write_bytes(damaged)
        result = repair_log(directory, store=STORE)
        assert _intact_moved_out(data, directory) == 0
        assert (directory / "events.log").read_bytes() == data
        assert [a.kind for a in result.actions] == ["extra"]
        assert (result.kept_events, result.kept_last_seq) == (200, 200)
        assert result.quarantine is not None
        assert len(result.quarantine.read_bytes()) == len(damaged) - len(data)
        assert verify_log(directory, store=STORE).events == 200


def test_a_damaged_record_after_a_deleted_one_costs_only_itself(tmp_path: Path) -> None:
    data = _write(tmp_path, 12)
    lines = data.splitlines(keepends=True)
    damaged = bytearray(lines[6])
    damaged[damaged.index(b'"r6"') + 2] = ord("X")  # an edit, its checksum not recomputed
    lines[6] = bytes(damaged)
    del lines[3]  # seq 4 lost
    (tmp_path / "events.log").write_bytes(b"".join(lines))
    result = repair_log(tmp_path, store=STORE)
    assert [(a.kind, a.first_seq, a.last_seq) for a in result.actions] == [
        ("lost", 4, 4),
        ("quarantined", 7, 7),
    ]
    assert [seq for seq, what in _reasons(tmp_path) if what == "record_quarantined"] == [4, 7]
    assert _intact_moved_out(data, tmp_path) == 2  # seq 4 (deleted) and seq 7 (damaged)


def test_two_records_damaged_in_a_row_are_both_moved_out_never_kept_changed(
    tmp_path: Path,
) -> None:
    """The second keeps its id, seq and checksum (proven by the record after it), but its bytes
    do not chain from the checksum the first carries: neither is proven, so neither is kept."""
    data = _write(tmp_path, 10)
    lines = data.splitlines(keepends=True)
    for i in (4, 5):
        lines[i] = lines[i].replace(f'"r{i}"'.encode(), f'"X{i}"'.encode())
    (tmp_path / "events.log").write_bytes(b"".join(lines))
    result = repair_log(tmp_path, store=STORE)
    assert [(a.kind, a.first_seq, a.last_seq) for a in result.actions] == [("quarantined", 5, 6)]
    assert _reasons(tmp_path) == [
        *((i + 1, f"r{i}") for i in range(4)),
        (5, "record_quarantined"),
        (6, "record_quarantined"),
        *((i + 1, f"r{i}") for i in range(6, 10)),
    ]
    assert result.quarantine is not None
    assert result.quarantine.read_bytes() == lines[4] + lines[5]


def test_a_record_cut_short_or_split_in_two_costs_no_other(tmp_path: Path) -> None:
    data = _write(tmp_path, 8)
    lines = data.splitlines(keepends=True)
    cut = [*lines[:2], lines[2][:30] + b"\n", *lines[3:]]  # seq 3 cut short
    (tmp_path / "events.log").write_bytes(b"".join(cut))
    result = repair_log(tmp_path, store=STORE)
    assert [(a.kind, a.first_seq) for a in result.actions] == [("quarantined", 3)]
    assert _intact_moved_out(data, tmp_path) == 1
    split = tmp_path / "split"
    data = _write(split, 8)
    lines = data.splitlines(keepends=True)
    half = len(lines[4]) // 2
    (split / "events.log").write_bytes(
        b"".join([*lines[:4], lines[4][:half], b"\n", lines[4][half:], *lines[5:]])
    )
    result = repair_log(split, store=STORE)
    assert [(a.kind, a.first_seq) for a in result.actions] == [("line-ending-restored", 5)]
    assert (split / "events.log").read_bytes() == data


@pytest.mark.parametrize(
    "edit",
    [
        {"format": "objsearch.events/1", "run_id": None},  # the issue's: "keeps 0 events"
        {"run_id": "00000000-0000-4000-8000-00000000beef"},
        {"stream": "robot2"},
    ],
)
def test_an_edited_meta_json_is_refused_with_a_clear_error(
    tmp_path: Path, edit: dict[str, str | None], capsys: pytest.CaptureFixture[str]
) -> None:
    """Issue 43: meta.json edited to format /1 without its run id made every record "damaged"
    and the repair kept 0 events; the refusal meant for it never triggered."""
    _write(tmp_path, 20)
    meta = json.loads((tmp_path / "meta.json").read_text())
    for key, value in edit.items():
        if value is None:
            del meta[key]
        else:
            meta[key] = value
    (tmp_path / "meta.json").write_text(json.dumps(meta))
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    capsys.readouterr()
    assert main(["log", "verify", str(tmp_path)]) == 2
    assert main(["log", "repair", str(tmp_path)]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 2 and all(e.startswith("objsearch: error: ") for e in err)
    assert all("meta.json was edited" in e for e in err), err
    assert "nothing was changed" in err[1]
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before


def test_a_damaged_first_record_is_not_taken_for_an_edited_meta_json(tmp_path: Path) -> None:
    data = _write(tmp_path, 10)
    lines = data.splitlines(keepends=True)
    first = bytearray(lines[0])
    first[first.index(b'"version":') + 10] ^= 0x06  # its version digit edited: 1 -> 7
    lines[0] = bytes(first)
    (tmp_path / "events.log").write_bytes(b"".join(lines))
    with pytest.raises(CorruptLogError, match="record at seq 1 is damaged"):
        verify_log(tmp_path, store=STORE)
    result = repair_log(tmp_path, store=STORE)
    assert [(a.kind, a.first_seq) for a in result.actions] == [("quarantined", 1)]
    assert result.kept_events == 9 and _intact_moved_out(data, tmp_path) == 1


def test_the_battery_moves_no_intact_record_out_loses_nothing_and_changes_nothing_silently() -> (
    None
):
    """Every kind of line damage at every fourth line of a small closed and a small crashed log,
    and every meta.json edit, through `objsearch log repair` (the large run:
    benchmarks/log_fuzz.py --battery-events)."""
    report = run_repair_battery(12, stride=4)
    assert report.failures == [], report.failures[:5]
    assert (report.traceback, report.silent_change, report.loss) == (0, 0, 0)
    assert report.intact_moved_out == 0, report.summary()
    assert set(report.by_kind) == {d.__name__ for d in LINE_DAMAGE} | {"meta_or_durable_edit"}
    # not vacuous: nearly every case changed the log, and every meta.json edit was refused
    assert report.repaired > 0.8 * report.tried
    refused = report.outcomes["meta_or_durable_edit: clear error"]
    assert refused == 2 * 9, report.outcomes
