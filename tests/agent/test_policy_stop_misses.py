"""How much of a stop's chance repeated misses leave (agent/policy.py, ``stop_miss_after``):
``pooled`` raises the stop's mean miss to the n-th power, ``per-static`` averages each static's
own miss to that power (the target at one of them, equally likely)."""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import pytest

from objsearch.agent.catalogue import Record
from objsearch.agent.detector_model import STOP_MISSES, PerceptionModel, preset
from objsearch.agent.errors import ObjsearchError
from objsearch.agent.policy import SearchAgent
from objsearch.agent.recorder import Recorder
from objsearch.agent.session import load_context
from objsearch.agent.stops import Stop
from objsearch.agent.strategies import RunSpec
from objsearch.sim.detector_model import with_perception

from .relation_stubs import NoRelations


class Discard:
    """An event sink that keeps nothing (the agent's arithmetic alone is under test)."""

    def append_record(self, record: Record, *, time_ns: int, task_id: str | None = None) -> Any:
        return record


def _agent(model: PerceptionModel) -> SearchAgent:
    ctx = load_context("paper")
    base = RunSpec.of("paper", ctx.home.digest, "global-belief", params={"camera": "occluding"})
    spec, _ = with_perception(base, model)
    return SearchAgent(
        ctx.navmap,
        ctx.semmap,
        ctx.vocabulary,
        NoRelations(),
        Recorder(Discard(), ()),
        spec.config(),
    )


def _near_and_far_stop() -> Stop:
    """A stop whose first static is seen from its own viewpoint and whose second lies across
    the home from there: the Apple shows a large mask at one and a small one at the other."""
    statics = load_context("paper").semmap.statics
    near = statics[0]
    far = max(statics, key=lambda s: math.dist((s.loc.x, s.loc.y), near.viewpoint[:2]))
    return Stop((near, far), 1.0)


def test_per_static_misses_are_the_mean_of_each_statics_powers() -> None:
    stop = _near_and_far_stop()
    pooled = _agent(preset("realistic", stop_misses="pooled"))
    per_static = _agent(preset("realistic"))
    recalls = pooled._recalls("Apple", stop)
    assert recalls[0] != recalls[1]  # the case the two readings differ on
    misses = [1.0 - 0.8 * r for r in recalls]
    for looks in range(0, 6):
        assert pooled.stop_miss_after("Apple", stop, looks) == pytest.approx(
            pooled.stop_miss("Apple", stop) ** looks
        )
        assert per_static.stop_miss_after("Apple", stop, looks) == pytest.approx(
            sum(m**looks for m in misses) / 2
        )
    # one look: the same; more: the mean of powers is above the power of the mean (Jensen), so
    # the static seen badly keeps its chance where the pooled miss drains it
    one = per_static.stop_miss_after("Apple", stop, 1)
    assert one == pytest.approx(pooled.stop_miss_after("Apple", stop, 1))
    for looks in (2, 4, 8):
        assert per_static.stop_miss_after("Apple", stop, looks) > pooled.stop_miss_after(
            "Apple", stop, looks
        )
    assert per_static.stop_miss_after("Apple", stop, 8) >= max(misses) ** 8 / 2


def test_stop_misses_are_recorded_only_when_not_pooled() -> None:
    # the modelled presets count per static (the amendment of 23:03 UTC); perfect pools
    assert preset("perfect").stop_misses == "pooled"
    pooled = preset("realistic", stop_misses="pooled")
    assert "stop_misses" not in pooled.params()
    on = preset("harsh")
    assert on.stop_misses == "per-static" and on.params()["stop_misses"] == "per-static"
    assert PerceptionModel.from_params(on.params()) == on
    # a run spec that names none replays as the runs before the option
    assert PerceptionModel.from_params(pooled.params()).stop_misses == "pooled"
    assert STOP_MISSES == ("pooled", "per-static")
    with pytest.raises(ObjsearchError, match="unknown stop misses"):
        replace(preset("realistic"), stop_misses="sometimes")
