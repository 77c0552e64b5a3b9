"""Fold ≡ SQL as a property: for *any* run — tasks started twice, ended without a start, aborted,
re-seeded mid-task, update modes switched between tasks, detections rejected, away from any static,
of classes the prior does not know — the lake's closed form of Eq. 4 (``scene_graph`` and
``scene_graph_at_seq``) gives the graph the agent's fold gives, at every cut-off.

``test_analytics.py`` checks the same on two real simulated runs; those never hold most of the
orders drawn here, which is where two statements of one rule drift apart.
"""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from objsearch.agent.catalogue import STORE
from objsearch.agent.scene_graph import SceneGraphProjection
from objsearch.events import EventLog, fold, read_log
from objsearch.events.lake import TableLake, add_log
from objsearch.replay.analytics import open_analytics

DYNAMICS = ("Cup", "Phone", "Apple")
STATICS = ("Table", "Sink", "Shelf")
UNKNOWN_DYNAMIC = "Vase"  # in no seed: the fold and the closed form must both ignore it
UNKNOWN_STATIC = "Bed"

_REL = st.floats(0.0, 1.0, allow_nan=False)
_SEED = st.fixed_dictionaries({(d, s): _REL for d in DYNAMICS for s in STATICS})
_RESEED = st.tuples(st.just("seed"), _SEED)
_MODE = st.tuples(st.just("mode"), st.sampled_from(["none", "targets", "all"]))
_DETECT = st.tuples(
    st.just("detect"),
    st.sampled_from((*DYNAMICS, UNKNOWN_DYNAMIC)),
    st.sampled_from((*STATICS, UNKNOWN_STATIC, None)),
    st.booleans(),  # at the static
    st.booleans(),  # accepted
)
# How a task's steps close: most end or abort; some never close (the next start or the run's end
# cuts them), some end twice or end after an abort (stray ends a crash and a restart can leave).
_CLOSE = st.sampled_from(
    [(("end",),), (("end",),), (("abort",),), (), (("end",), ("end",)), (("abort",), ("end",))]
)


@st.composite
def _task(draw: st.DrawFn) -> list[Any]:
    """One task's events: a start (or none: detections after a task end), detections, a close;
    sometimes a re-seed or a mode switch in the middle."""
    target = draw(st.sampled_from((*DYNAMICS, UNKNOWN_DYNAMIC, None)))
    steps: list[Any] = [] if target is None else [("start", target)]
    steps += draw(st.lists(_DETECT, max_size=4))
    interjection = draw(st.none() | _RESEED | _MODE)
    if interjection is not None:
        steps.insert(draw(st.integers(0, len(steps))), interjection)
    return steps + list(draw(_CLOSE))


_STEPS = st.lists(_task(), min_size=1, max_size=8).map(lambda tasks: [s for t in tasks for s in t])

POSE = {"x": 0.0, "y": 0.0, "yaw": 0.0}


def _run_started(mode: str) -> dict[str, Any]:
    return {
        "home": "prop",
        "home_digest": "sha256:00",
        "strategy": "wpl",
        "method": "wpl",
        "planner": "wpl",
        "relations": {
            "model": "eq4",
            "prior_strength": None,
            "half_life_tasks": None,
            "recent_weight": None,
        },
        "alpha": 10.0,
        "update_mode": mode,
        "seed": 0,
        "support_radius": 0.5,
        "schedule": None,
        "params": {},
    }


def _seeded(values: dict[tuple[str, str], float]) -> dict[str, Any]:
    return {
        "source": "hypothesis",
        "values": [{"dynamic": d, "static": s, "rel": r} for (d, s), r in values.items()],
    }


def _write(log_dir: Path, mode: str, seed: dict[tuple[str, str], float], steps: list[Any]) -> None:
    with EventLog.open(log_dir, "prop", store=STORE, wall_clock=lambda: 0) as log:
        clock = iter(range(1_000, 10**9, 1_000))
        log.append("run_started", _run_started(mode), time_ns=next(clock))
        log.append("scene_graph_seeded", _seeded(seed), time_ns=next(clock))
        task = 0
        for step in steps:
            kind = step[0]
            if kind == "seed":
                log.append("scene_graph_seeded", _seeded(step[1]), time_ns=next(clock))
            elif kind == "mode":
                log.append("run_started", _run_started(step[1]), time_ns=next(clock))
            elif kind == "start":
                task += 1
                payload = {"target": step[1], "start": "r", "pose": POSE, "scene": 0, "clock": None}
                log.append("task_started", payload, time_ns=next(clock), task_id=f"t{task}")
            elif kind == "detect":
                _, dynamic, static, at, accepted = step
                support = (
                    None
                    if static is None
                    else {"static_id": f"{static}|1", "static_class": static, "at": at}
                )
                detection = {
                    "object_class": dynamic,
                    "instance_id": f"{dynamic}|1",
                    "mask_area": 900.0,
                    "position": [0.0, 0.0, 0.0],
                    "accepted": accepted,
                    "support": support,
                    "score": 1.0,
                    "classes": [],
                }
                log.append("detection", detection, time_ns=next(clock), task_id=f"t{task}")
            elif kind == "end":
                ended = {"target": "Cup", "success": True, "path_length": 1.0}
                log.append("task_ended", ended, time_ns=next(clock), task_id=f"t{task}")
            else:
                aborted = {"target": "Cup", "reason": "restart", "path_length": 0.0}
                log.append("task_aborted", aborted, time_ns=next(clock), task_id=f"t{task}")


@pytest.mark.slow
@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(mode=st.sampled_from(["none", "targets", "all"]), seed=_SEED, steps=_STEPS)
def test_the_closed_form_is_the_fold_for_any_run(
    mode: str, seed: dict[tuple[str, str], float], steps: list[Any]
) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        log_dir = Path(tmp) / "log"
        _write(log_dir, mode, seed, steps)
        lake = TableLake(Path(tmp) / "lake", store=STORE)
        add_log(log_dir, lake, robot="r")
        con = open_analytics(lake.root)
        events = list(read_log(log_dir, store=STORE))
        final = fold(iter(events), SceneGraphProjection())
        rows = con.execute("SELECT dynamic, static, rel FROM scene_graph").fetchall()
        assert {(d, s) for d, s, _ in rows} == final.relations.keys()
        for d, s, rel in rows:
            assert rel == pytest.approx(final.relations[d, s], abs=1e-12), (d, s)
        for event in events:
            graph = fold(iter(events), SceneGraphProjection(), until_seq=event.seq)
            at_seq = con.execute(
                "SELECT dynamic, static, rel FROM scene_graph_at_seq(?)", [event.seq]
            ).fetchall()
            assert {(d, s) for d, s, _ in at_seq} == graph.relations.keys(), event.seq
            for d, s, rel in at_seq:
                assert rel == pytest.approx(graph.relations[d, s], abs=1e-12), (event.seq, d, s)
        con.close()
