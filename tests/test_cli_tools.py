"""The command line as a newcomer meets it: --version, --format json on the commands that write things,
record's size up front (its progress on a terminal only), and agent find telling that nobody can hear it."""

from __future__ import annotations

import json
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from objsearch import __version__
from objsearch.cli import demo_summary, main

REPO = Path(__file__).resolve().parents[1]
GOLDEN = REPO / "tests" / "replay" / "golden" / "sim-wpl-updates"


def test_version(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"objsearch {__version__}"


def test_record_says_what_it_will_write_and_prints_json(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "bag"
    args = ["record", "--out", str(out), "--bag-format", "ros2-mcap", "--scenes", "1"]
    args += ["--targets", "Apple", "--starts", "kitchen-1", "--format", "json"]
    assert main(args) == 0
    captured = capsys.readouterr()
    assert "1 searches into" in captured.err and "zstd" in captured.err
    assert "about 0.1 MB" in captured.err  # the expected size, before anything runs
    # Not a terminal: no progress bars (drawn on a terminal only, tests/test_cli_conventions.py).
    assert "searches:" not in captured.err and "messages:" not in captured.err
    doc = json.loads(captured.out)
    assert doc["searches"] == 1 and doc["compressed"] is True
    assert doc["bytes"] == (out / "bag.mcap").stat().st_size
    assert doc["messages"]["/objsearch/events"] == doc["events"]

    # ingest --format json: one JSON line per bag; lake add --format json: the committed run.
    lake = tmp_path / "lake"
    assert main(["ingest", str(out), "--lake", str(lake), "--no-progress", "--format", "json"]) == 0
    (line,) = capsys.readouterr().out.strip().splitlines()
    ingested = json.loads(line)
    assert ingested["ok"] and not ingested["already"] and ingested["committed"] > 0
    assert ingested["report"]["format"] == "ros2-mcap"
    assert (
        main(
            ["lake", "add", str(GOLDEN), "--robot", "sim", "--lake", str(lake), "--format", "json"]
        )
        == 0
    )
    added = json.loads(capsys.readouterr().out)
    assert added["robot"] == "sim" and added["events"] == sum(added["rows"].values())


def test_liveview_json(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    mcap = tmp_path / "view.mcap"
    assert main(["liveview", str(GOLDEN), "--mcap", str(mcap), "--format", "json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["bytes"] == mcap.stat().st_size and doc["compressed"] is True
    assert doc["messages"] == sum(c["messages"] for c in doc["channels"].values())


def test_demo_summary_reads_the_demos_table(tmp_path: Path) -> None:
    """``demo --format json`` summarises the table the demo writes (a small real run of it here; the
    full demo is 1280 searches)."""
    from objsearch.agent.home import load_home
    from objsearch.agent.scene_graph import UpdateMode
    from objsearch.agent.strategies import RunSpec
    from objsearch.sim.demo import discovery, write_csv
    from objsearch.sim.longterm import run_schedule

    spec = RunSpec.for_home(load_home("paper"), "wpl", schedule="table2")
    trials = run_schedule(
        tmp_path / "log-all", spec, targets=["Apple", "Cup"], scenes=[1], starts=["kitchen-1"]
    )
    write_csv(tmp_path / "path_lengths.csv", {UpdateMode.ALL: trials})
    doc = demo_summary(tmp_path)
    (mode,) = doc["modes"].values()
    assert mode["searches"] == 2
    assert mode["mean_path_length_m"] == pytest.approx(
        sum(t.path_length for t in trials) / 2, abs=1e-3
    )
    assert mode["mean_path_to_discovery_m"] == pytest.approx(
        sum(discovery(t) for t in trials) / 2, abs=1e-3
    )
    assert mode["mean_path_to_discovery_m"] < mode["mean_path_length_m"]
    assert doc["logs"] == {"all": str(tmp_path / "log-all")}


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_agent_find_without_a_router_says_so_within_seconds() -> None:
    pytest.importorskip("zenoh")
    endpoint = f"tcp/127.0.0.1:{_free_port()}"  # nobody listens there
    # The clock starts once the interpreter has started and imported the CLI (seconds on a
    # loaded machine): that is not what is measured. CLOCK_MONOTONIC is one clock for both.
    started_cli = (
        "import sys, time\nfrom objsearch.cli import main\n"
        "print(time.monotonic(), file=sys.stderr, flush=True)\nsys.exit(main(sys.argv[1:]))"
    )
    proc = subprocess.Popen(
        [sys.executable, "-c", started_cli, "agent", "find", "Apple", "--connect", endpoint,
         "--timeout", "600"],
        stderr=subprocess.PIPE,
        text=True,
    )  # fmt: skip
    try:
        assert proc.stderr is not None
        started = float(proc.stderr.readline())
        line = proc.stderr.readline()
        waited = time.monotonic() - started
    finally:
        proc.terminate()
        proc.wait(timeout=120)
    assert "nobody answers: no zenoh router or peer is reachable at " + endpoint in line
    assert "objsearch robot router" in line and "rmw_zenohd" in line
    assert waited < 60, waited  # told within seconds, not at the 600 s timeout


def test_lake_ls_of_a_missing_lake_is_an_error_like_query(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    missing = str(tmp_path / "no-lake")
    assert main(["lake", "ls", "--lake", missing]) == 2
    assert main(["query", "--lake", missing, "SELECT 1"]) == 2
    assert capsys.readouterr().err.count("objsearch: error: no lake at") == 2


def test_ingest_takes_its_lake_from_objsearch_lake(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from objsearch.cli import build_parser

    monkeypatch.setenv("OBJSEARCH_LAKE", str(tmp_path / "site-lake"))
    bag = tmp_path / "x.bag"
    bag.write_bytes(b"")
    args = build_parser().parse_args(["ingest", str(bag)])
    assert args.lake == str(tmp_path / "site-lake")
