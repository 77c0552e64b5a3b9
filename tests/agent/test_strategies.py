"""Strategy names (agent/strategies.py): ``NAME`` and ``NAME+cover``, and the product's default."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from objsearch.agent.catalogue import STORE
from objsearch.agent.errors import ObjsearchError
from objsearch.agent.strategies import (
    COVER_SUFFIX,
    DEFAULT_STRATEGY,
    STRATEGIES,
    RunSpec,
    full_strategy_name,
    split_strategy,
    strategy_names,
)
from objsearch.cli import main
from objsearch.events.log_read import read_log


def test_a_name_says_the_strategy_and_how_it_inspects() -> None:
    for name in STRATEGIES:
        assert split_strategy(name) == (STRATEGIES[name], "single")
        assert split_strategy(name + COVER_SUFFIX) == (STRATEGIES[name], "cover")
        for inspection in ("single", "cover"):
            assert split_strategy(full_strategy_name(name, inspection))[1] == inspection
    assert set(strategy_names()) == {*STRATEGIES, *(n + COVER_SUFFIX for n in STRATEGIES)}
    for bad in ("wpl+", "wpl+cover+cover", "+cover", "nope+cover", "wpl+single"):
        with pytest.raises(ObjsearchError, match="unknown strategy"):
            split_strategy(bad)


def test_a_cover_name_is_recorded_as_the_runs_inspection_and_read_back() -> None:
    spec = RunSpec.of("paper", "digest", "global-belief+cover", params={"camera": "geometric"})
    assert spec.strategy == "global-belief"
    assert dict(spec.params) == {"camera": "geometric", "inspection": "cover"}
    assert spec.config().inspection == "cover"
    assert spec.name == "global-belief+cover"
    assert RunSpec.from_payload(spec.payload()) == spec
    plain = RunSpec.of("paper", "digest", "global-belief")
    assert (plain.inspection, plain.name) == ("single", "global-belief")
    # The two ways of saying it agree, and contradicting them is an error.
    assert RunSpec.of("paper", "digest", "wpl", params={"inspection": "cover"}).name == "wpl+cover"
    with pytest.raises(ObjsearchError, match="inspects by cover"):
        RunSpec.of("paper", "digest", "wpl+cover", params={"inspection": "single"})


def test_the_default_is_the_one_protocol_v5_chose_and_a_robot_gets_it() -> None:
    """docs/results-belief.md, protocol v5's rule: the belief over the whole home with cover."""
    assert DEFAULT_STRATEGY == "global-belief+cover"
    assert not split_strategy(DEFAULT_STRATEGY)[0].reference
    from objsearch.runtime.config import RuntimeConfig

    assert RuntimeConfig().strategy is None  # the agent node resolves it to DEFAULT_STRATEGY


def test_search_runs_the_default_and_records_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    log = tmp_path / "log"
    args = ["search", "Cup", "--start", "kitchen-1", "--log", str(log)]
    assert main([*args, "--format", "json"]) == 0
    assert json.loads(capsys.readouterr().out)["strategy"] == DEFAULT_STRATEGY
    (started,) = (e for e in read_log(log, store=STORE) if e.type == "run_started")
    assert started.payload["strategy"] == "global-belief"
    assert started.payload["params"]["inspection"] == "cover"


def test_a_name_the_registry_does_not_know_is_a_usage_error(
    capsys: pytest.CaptureFixture[str],
) -> None:
    args = ["search", "Cup", "--start", "kitchen-1", "--strategy", "wpl+twice"]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert err.startswith("objsearch: error: ") and "each may end in +cover" in err
