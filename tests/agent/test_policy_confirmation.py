"""Confirmation and revisits under a modelled detector (agent/policy.py): a confirming look at a
sighting made inside a container opens it again; a sighting's prior odds come from where the
memory says the target is; a revisit's per-look miss follows the target's size at each stop."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest

from objsearch.agent.catalogue import STORE, Detected, Moved, Record, ViewTaken
from objsearch.agent.detector_model import PerceptionModel, preset
from objsearch.agent.errors import ObjsearchError
from objsearch.agent.geometry import Pose
from objsearch.agent.home import Home
from objsearch.agent.policy import SearchAgent
from objsearch.agent.recorder import Recorder
from objsearch.agent.session import Session, load_context
from objsearch.agent.strategies import RunSpec
from objsearch.agent.world import Detection
from objsearch.events.log_read import read_log
from objsearch.sim.detector_model import NoisyDetector, with_perception
from objsearch.sim.placements import Placement, base_placements
from objsearch.sim.world import SimWorld

from .relation_stubs import NoRelations

FIXED_WALL_CLOCK_NS = 1_767_225_600_000_000_000
FRIDGE = "kitchen/Fridge|-01.76|+00.00|00.00"


def _spec(model: PerceptionModel, strategy: str = "wpl") -> RunSpec:
    ctx = load_context("paper")
    base = RunSpec.of(
        "paper", ctx.home.digest, strategy, schedule="table2", params={"camera": "occluding"}
    )
    spec, _ = with_perception(base, model)
    return spec


def _search_paper_apple(
    tmp_path: Path, model: PerceptionModel, detector: NoisyDetector
) -> tuple[Any, SimWorld, list[Any]]:
    """Search the paper home for its Apple from kitchen-1 with ``detector``: the result, the
    world and the events of the run's log."""
    ctx = load_context("paper")
    placements = base_placements(ctx.home, frozenset())
    session = Session.start(ctx, tmp_path, _spec(model), wall_clock=lambda: FIXED_WALL_CLOCK_NS)
    try:
        world = SimWorld(
            ctx.home, ctx.navmap, placements, ctx.home.start("kitchen-1"), detector=detector
        )
        result = session.search(world, "Apple", "kitchen-1")
    finally:
        session.close()
    return result, world, list(read_log(tmp_path, store=STORE))


class UnsureAtFirst(NoisyDetector):
    """Reports what the camera shows at score 0.99, but the Apple at 0.6 the first time (a score
    that says little) and at 0.95 after: a sighting that needs one confirming look."""

    def __init__(self, model: PerceptionModel) -> None:
        super().__init__(model, 0, ())
        self.apples = 0

    def observe(
        self,
        home: Home,
        room: str,
        pose: Pose,
        placed: Sequence[Placement],
        seen: Sequence[Detection],
    ) -> tuple[Detection, ...]:
        self.views += 1
        out: list[Detection] = []
        for d in seen:
            score = 0.99
            if d.object_class == "Apple":
                score = 0.6 if self.apples == 0 else 0.95
                self.apples += 1
            out.append(Detection(d.object_class, d.instance_id, d.mask_area, d.position, score))
        return tuple(out)


def test_a_confirming_look_at_a_sighting_inside_a_container_opens_it(tmp_path: Path) -> None:
    # The paper home's Apple lies in the fridge (seen only with its door open). Before, the
    # confirming looks did not open it, so each was a miss and the true sighting was rejected
    # (ithor-05 habit-0 scene 8 under realistic: 8 passes, 532 m).
    ctx = load_context("paper")
    model = preset("realistic", "score")
    placements = base_placements(ctx.home, frozenset())
    (apple,) = [p for p in placements.values() if p.cls == "Apple"]
    assert apple.inside and apple.support == FRIDGE
    result, _, events = _search_paper_apple(tmp_path, model, UnsureAtFirst(model))
    assert result.success and result.found_instance == apple.instance_id
    assert not [e for e in events if e.type == "sighting_rejected"]
    kinds = [e.type for e in events]
    first = next(
        i for i, e in enumerate(events) if e.type == "detection" and e.payload["score"] == 0.6
    )
    # The confirming look: the fridge opened again, a view inside, the Apple seen at 0.95.
    assert kinds[first + 1 : first + 3] == ["container_opened", "view_taken"]
    assert events[first + 1].payload["static_id"] == FRIDGE
    assert events[first + 2].payload["reason"] == "inside"
    assert events[first + 3].payload["score"] == 0.95


class FalseBesideFirst(UnsureAtFirst):
    """As :class:`UnsureAtFirst`, and in the view that sees the Apple again a false Apple
    0.3 m from it at a higher score, reported first."""

    def observe(
        self,
        home: Home,
        room: str,
        pose: Pose,
        placed: Sequence[Placement],
        seen: Sequence[Detection],
    ) -> tuple[Detection, ...]:
        out = super().observe(home, room, pose, placed, seen)
        apples = [d for d in out if d.object_class == "Apple" and d.score == 0.95]
        if not apples:
            return out
        x, y, z = apples[0].position
        beside = Detection("Apple", "false:beside", 900.0, (x + 0.3, y, z), 0.99)
        return (beside, *out)


def test_a_confirming_look_takes_the_report_nearest_the_sighting(tmp_path: Path) -> None:
    # Two reports of the target within 0.5 m of a sighting in one confirming view: the object
    # seen again is the nearer one. The first in the view's order was taken before, so a false
    # one beside the real object ended the search as "found" (harsh procthor-00 habit-0 scene 1,
    # a Pillow: a false Pillow 0.35 m off, while the Pillow itself was seen in the same view).
    ctx = load_context("paper")
    model = preset("realistic", "score")
    placements = base_placements(ctx.home, frozenset())
    (apple,) = [p for p in placements.values() if p.cls == "Apple"]
    result, _, events = _search_paper_apple(tmp_path, model, FalseBesideFirst(model))
    assert result.success and result.found_instance == apple.instance_id
    assert any(e.type == "detection" and e.payload["instance_id"] == "false:beside" for e in events)


class AnotherObjectBeside(NoisyDetector):
    """Reports what the camera shows at score 0.99, and the Apple at 0.8 the first time; the
    second time the Apple is missed, and 0.2 m from it an "Apple" with 1/25 of its mask is
    reported at 0.99 (a false positive beside it); after that, the Apple at 0.95."""

    def __init__(self, model: PerceptionModel) -> None:
        super().__init__(model, 0, ())
        self.apples = 0

    def observe(
        self,
        home: Home,
        room: str,
        pose: Pose,
        placed: Sequence[Placement],
        seen: Sequence[Detection],
    ) -> tuple[Detection, ...]:
        self.views += 1
        out: list[Detection] = []
        for d in seen:
            if d.object_class != "Apple":
                out.append(Detection(d.object_class, d.instance_id, d.mask_area, d.position, 0.99))
                continue
            self.apples += 1
            if self.apples == 2:
                x, y, z = d.position
                small = d.mask_area / 25
                out.append(Detection("Apple", "false:beside", small, (x, y + 0.2, z), 0.99))
            else:
                score = 0.8 if self.apples == 1 else 0.95
                out.append(Detection("Apple", d.instance_id, d.mask_area, d.position, score))
        return tuple(out)


def test_a_report_beside_a_sighting_with_a_very_different_mask_is_another_object(
    tmp_path: Path,
) -> None:
    # A confirming look counted any report of the target's class within 0.5 m as the object seen
    # again, so a neighbour's confusion or a false positive beside it confirmed the sighting and
    # was "found" (harsh paper habit-0 scene 11: a Laptop 0.46 m from the Phone, reported as a
    # Phone with 22 times the Phone's mask; realistic ithor-02 habit-3 scene 3: a false Bowl
    # 0.18 m from the Bowl with 1/26 of its mask). Such a report is another object now.
    ctx = load_context("paper")
    model = preset("realistic", "score")
    placements = base_placements(ctx.home, frozenset())
    (apple,) = [p for p in placements.values() if p.cls == "Apple"]
    result, _, events = _search_paper_apple(tmp_path, model, AnotherObjectBeside(model))
    assert result.success and result.found_instance == apple.instance_id
    assert any(e.type == "detection" and e.payload["instance_id"] == "false:beside" for e in events)


class PlantedOnTheStove(NoisyDetector):
    """Reports what the camera shows (score 1), and on the first view an Apple that is not
    there, on a stove burner (where no model expects an Apple), at a high score."""

    SPOT = (2.3846, 0.735, 0.94)

    def observe(
        self,
        home: Home,
        room: str,
        pose: Pose,
        placed: Sequence[Placement],
        seen: Sequence[Detection],
    ) -> tuple[Detection, ...]:
        self.views += 1
        if self.views > 1:
            return tuple(seen)
        planted = Detection("Apple", "false:stove", 900.0, self.SPOT, 0.96, (("Apple", 0.96),))
        return (*seen, planted)


def test_a_high_scoring_sighting_where_the_target_is_unlikely_is_looked_at_again(
    tmp_path: Path,
) -> None:
    # Score 0.96 has a likelihood ratio of about 380: from even prior odds P(real) 0.997, so it
    # ended the search at once (procthor-00 habit-0 scene 2 Cup: a false found at 0.959). The
    # prior is now the model's P(Apple on a stove burner), a floor of 0.05/45, times recall over
    # the false reports of the class per view: P(real) about 0.85, so it is looked at again and,
    # not seen again, rejected; the real Apple (in the fridge) is found.
    model = preset("realistic", "score")
    result, world, events = _search_paper_apple(tmp_path, model, PlantedOnTheStove(model, 0, ()))
    assert result.success and result.found_instance != "false:stove"
    assert world.is_instance_of(result.found_instance, "Apple")
    rejected = [e.payload for e in events if e.type == "sighting_rejected"]
    assert [r["instance_id"] for r in rejected] == ["false:stove"]
    assert rejected[0]["looks"] >= 1


def _give_up(tmp_path: Path, target: str, model: PerceptionModel) -> str:
    """Search the paper home for ``target`` with none placed; the search_failed reason."""
    ctx = load_context("paper")
    placements = {
        k: v for k, v in base_placements(ctx.home, frozenset()).items() if v.cls != target
    }
    spec, detector = with_perception(_spec(model), model)
    session = Session.start(ctx, tmp_path, spec, wall_clock=lambda: FIXED_WALL_CLOCK_NS)
    try:
        world = SimWorld(
            ctx.home, ctx.navmap, placements, ctx.home.start("kitchen-1"), detector=detector
        )
        result = session.search(world, target, "kitchen-1")
    finally:
        session.close()
    assert not result.success
    (reason,) = [
        e.payload["reason"] for e in read_log(tmp_path, store=STORE) if e.type == "search_failed"
    ]
    return str(reason)


def test_a_revisit_counts_a_small_targets_looks_as_weaker_evidence_than_a_large_ones(
    tmp_path: Path,
) -> None:
    # A detector that sees medium and large masks always and small ones at 10 %, nothing
    # false. From its stops a Phone (15 x 8 x 1 cm) shows a small mask, a Pillow (35 x 43 x
    # 14 cm) a large one: each pass that misses the Pillow leaves little of its mass, one that
    # misses the Phone most of it. Before, every target's per-look miss was the recall at a
    # 48 x 48 px mask (medium: 0.2 here), so the Phone's search stopped by ε as early.
    model = PerceptionModel(
        preset="realistic", recall_small=0.1, recall_medium=1.0, recall_large=1.0
    )
    pillow = _give_up(tmp_path / "pillow", "Pillow", model)
    phone = _give_up(tmp_path / "phone", "Phone", model)
    assert "< ε 0.5%" in pillow
    assert "budget of 8 passes spent" in phone


class SureOfTheFridge(NoRelations):
    """A relation model that is all but certain the Apple is in the fridge."""

    def instance_rel(self, dynamic: str, static_id: str, static_class: str) -> float:
        return 0.99 if (dynamic, static_id) == ("Apple", FRIDGE) else 0.0


class Records:
    """An event sink that keeps the records (no log: the agent alone is under test)."""

    def __init__(self) -> None:
        self.records: list[Record] = []

    def append_record(self, record: Record, *, time_ns: int, task_id: str | None = None) -> Any:
        self.records.append(record)
        return record


class PlantedInTheFridge(NoisyDetector):
    """Reports what the camera shows (score 1), and with the first view into the fridge a
    false Apple beside the real one, at a low score."""

    def observe(
        self,
        home: Home,
        room: str,
        pose: Pose,
        placed: Sequence[Placement],
        seen: Sequence[Detection],
    ) -> tuple[Detection, ...]:
        self.views += 1
        if not any(d.object_class == "Apple" for d in seen) or self.scored:
            return tuple(seen)
        self.scored.append((0.6, False))
        planted = Detection("Apple", "false:fridge", 4000.0, (2.2, 4.3, 0.9), 0.6)
        # Listed first: the search confirms the sightings of a view in order.
        return (
            planted,
            *(Detection(d.object_class, d.instance_id, d.mask_area, d.position, 1.0) for d in seen),
        )


def test_a_false_report_at_the_place_the_target_surely_is_is_no_find() -> None:
    # A false positive can land where the target is: the chance of a false report there does
    # not shrink as P(target there) grows. The prior was π r / ((1 − π) f): at π = 0.99 odds
    # of about 2,000, so a false Apple at score 0.6 (likelihood ratio 0.18) beside the real one
    # ended the search as found (procthor-00 habit-0 scene 4, Laptop: a false positive on the
    # bed the Laptop was on). Now π r / f, about 20: it is looked at again, and the look sees
    # the real Apple.
    ctx = load_context("paper")
    model = preset("realistic", "score")
    spec = _spec(model)
    sink = Records()
    agent = SearchAgent(
        ctx.navmap,
        ctx.semmap,
        ctx.vocabulary,
        SureOfTheFridge(),
        Recorder(sink, ()),
        spec.config(),
        next_task_id=lambda: "task-1",
    )
    placements = base_placements(ctx.home, frozenset())
    world = SimWorld(
        ctx.home,
        ctx.navmap,
        placements,
        ctx.home.start("kitchen-1"),
        detector=PlantedInTheFridge(model, 0, ()),
    )
    result = agent.search(world, "Apple", "kitchen-1")
    (apple,) = [p for p in placements.values() if p.cls == "Apple"]
    assert result.success and result.found_instance == apple.instance_id
    planted = [
        r for r in sink.records if isinstance(r, Detected) and r.instance_id == "false:fridge"
    ]
    assert planted and not any(r.accepted for r in planted)


def _rejected_on_the_stove(tmp_path: Path, model: PerceptionModel) -> dict[str, Any]:
    result, world, events = _search_paper_apple(tmp_path, model, PlantedOnTheStove(model, 0, ()))
    assert result.success and world.is_instance_of(result.found_instance, "Apple")
    (rejected,) = [e.payload for e in events if e.type == "sighting_rejected"]
    started = next(e for e in events if e.type == "run_started")
    assert started.payload["params"]["perception"] == model.params()
    return dict(rejected)


def test_the_consistent_confirmation_counts_each_miss_against_a_recurring_false_report(
    tmp_path: Path,
) -> None:
    # The false Apple on the stove (900 px, seen once) is missed at every confirming look from
    # where it was seen. The score rule multiplies its odds by 1 - r at each; the consistent
    # one by (1 - r) / (1 - q): the same looks leave odds (1 - q)^-looks times higher, and the
    # run spec records the rule (so a replay runs it).
    score = _rejected_on_the_stove(tmp_path / "score", preset("realistic", "score"))
    q = 0.1
    model = preset("realistic", "consistent", fp_recurrence=q)
    consistent = _rejected_on_the_stove(tmp_path / "consistent", model)
    assert score["looks"] == consistent["looks"] >= 1

    def odds(p: float) -> float:
        return p / (1 - p)

    expected = odds(score["posterior"]) / (1 - q) ** score["looks"]
    assert odds(consistent["posterior"]) == pytest.approx(expected, rel=1e-4)


class MissesTheAppleOnce(UnsureAtFirst):
    """Reports what the camera shows at score 0.99, but misses the Apple the first time it is in
    view: an inspection of its place that finds nothing."""

    def observe(
        self,
        home: Home,
        room: str,
        pose: Pose,
        placed: Sequence[Placement],
        seen: Sequence[Detection],
    ) -> tuple[Detection, ...]:
        self.views += 1
        out: list[Detection] = []
        for d in seen:
            if d.object_class == "Apple":
                self.apples += 1
                if self.apples == 1:
                    continue
            out.append(Detection(d.object_class, d.instance_id, d.mask_area, d.position, 0.99))
        return tuple(out)


class LikeliestInTheFridge(SureOfTheFridge):
    """A relation model that gives the fridge half the Apple's mass and every other place 1 %."""

    def instance_rel(self, dynamic: str, static_id: str, static_class: str) -> float:
        if dynamic != "Apple":
            return 0.0
        return 0.5 if static_id == FRIDGE else 0.01


@pytest.mark.parametrize("strategy", ["wpl", "global-belief"])
def test_a_stop_that_missed_is_looked_at_again_while_it_is_the_likeliest(strategy: str) -> None:
    # The paper home's Apple lies in the fridge, the likeliest place, and the detector misses it
    # at the first inspection there. Off (the default), the search moves on to the other places
    # and finds it only when it comes back; with relook ``likeliest`` it opens the fridge again
    # from where it stands (0.5 x the miss 0.56 is still above every other stop's value) and
    # finds it there, no metre further.
    ctx = load_context("paper")
    placements = base_placements(ctx.home, frozenset())
    paths: dict[str, float] = {}
    records: dict[str, list[Record]] = {}
    for relook in ("off", "likeliest"):
        model = replace(preset("realistic", "score"), relook=relook)
        sink = Records()
        agent = SearchAgent(
            ctx.navmap,
            ctx.semmap,
            ctx.vocabulary,
            LikeliestInTheFridge(),
            Recorder(sink, ()),
            _spec(model, strategy).config(),
            next_task_id=lambda: "task-1",
        )
        world = SimWorld(
            ctx.home,
            ctx.navmap,
            placements,
            ctx.home.start("kitchen-1"),
            detector=MissesTheAppleOnce(model),
        )
        result = agent.search(world, "Apple", "kitchen-1")
        assert result.success and world.is_instance_of(result.found_instance, "Apple")
        paths[relook], records[relook] = result.path_length, sink.records
    on = records["likeliest"]
    fridge = [i for i, r in enumerate(on) if isinstance(r, ViewTaken) and r.static_id == FRIDGE]
    first, again = on[fridge[0]], on[fridge[1]]
    assert isinstance(first, ViewTaken) and isinstance(again, ViewTaken)
    assert (first.pose.x, first.pose.y) == (again.pose.x, again.pose.y)
    between = on[fridge[0] : fridge[1]]
    assert not [r for r in between if isinstance(r, Moved) and r.metres > 0]
    assert not [r for r in between if isinstance(r, ViewTaken) and r.static_id != FRIDGE]
    assert paths["likeliest"] < paths["off"]


def test_relook_off_is_left_out_of_the_run_spec() -> None:
    off = preset("realistic", relook="off")
    assert "relook" not in off.params()
    assert preset("perfect").relook == "off"
    on = preset("realistic")  # the modelled presets relook (amendment of 21:12 UTC)
    assert on.relook == "likeliest" and on.params()["relook"] == "likeliest"
    assert PerceptionModel.from_params(on.params()) == on
    # a run spec that names none replays as the runs before the option
    assert PerceptionModel.from_params(off.params()).relook == "off"
    with pytest.raises(ObjsearchError, match="unknown relook"):
        replace(preset("realistic"), relook="sometimes")
