"""What a search task believes of a sighting of its target (docs/perception.md): the odds of the
sequential confirmation test, from the place's prior, this task's earlier looks and the detector
model. :class:`SearchingAgent` is what a task needs of its agent (the seam: the agent,
``objsearch.agent.policy.SearchAgent``, builds tasks; nothing here imports it)."""

from __future__ import annotations

import math
from typing import Protocol

from objsearch.agent.belief import ELSEWHERE_PRIOR
from objsearch.agent.categories import Vocabulary
from objsearch.agent.detector_model import SIMILAR, PerceptionModel
from objsearch.agent.geometry import Pose, Vec3
from objsearch.agent.navmap import NavigationMap
from objsearch.agent.recorder import Recorder
from objsearch.agent.results import Found
from objsearch.agent.semmap import SemanticMap
from objsearch.agent.stops import Stop
from objsearch.agent.world import Detection, World

#: Confirmation (docs/perception.md), a sequential test: a sighting not sure by its score is
#: looked at again, in turn from the ``CONFIRM_VIEWPOINTS`` viewpoints it was seen from or nearest
#: it (1: only where it was seen from; 3, with the two nearest others, rejected more true
#: sightings on the development homes, misses from where it was hidden), until
#: P(real) reaches the model's ``accept_posterior`` or falls below ``REJECT_BELOW``, at most
#: ``CONFIRM_LOOKS`` looks; a detection of the target class this close to it (m) is the same
#: object seen again. A sighting the looks leave undecided keeps its odds for the rest of the task.
CONFIRM_LOOKS = 6
CONFIRM_VIEWPOINTS = 1
SAME_OBJECT_M = 0.5
#: ... and whose mask is within this factor of the mask the sighting predicts from where the
#: robot stands (its own, scaled by the squared ratio of the distances): the same object seen
#: from about the same place shows about the same mask, so a report beside it with a very
#: different one is another object (a false positive beside it, a neighbour's confusion). A
#: choice, not measured: occlusion and pitch change a mask between looks, by less than this.
SAME_MASK_FACTOR = 4.0
REJECT_BELOW = 0.05
#: Odds that stand for certainty (a detector that makes no false reports), kept finite so that a
#: score's likelihood ratio of 0 still says no.
SURE_ODDS = 1e12


class TaskConfig(Protocol):
    """The search settings a task reads (``SearchConfig``)."""

    @property
    def perception(self) -> PerceptionModel: ...

    @property
    def support_radius(self) -> float: ...


class SearchingAgent(Protocol):
    """What a search task needs of the agent that runs it (``SearchAgent``): its maps, vocabulary,
    recorder and settings, and the relation model's view of where the target may be."""

    @property
    def navmap(self) -> NavigationMap: ...

    @property
    def semmap(self) -> SemanticMap: ...

    @property
    def vocabulary(self) -> Vocabulary: ...

    @property
    def recorder(self) -> Recorder: ...

    @property
    def config(self) -> TaskConfig: ...

    @property
    def movable_classes(self) -> int:
        """How many movable (semi-dynamic) classes the vocabulary holds."""
        ...

    def stop_miss_after(self, target: str, stop: Stop, looks: int) -> float: ...

    def place_probabilities(self, d: str) -> tuple[dict[str, float], float]: ...


def same_object(sighting: Found, position: Vec3, mask_area: float, pose: Pose) -> bool:
    """Whether a report of the sighting's class at ``position`` with ``mask_area``, seen from
    ``pose``, is the sighted object again: within :data:`SAME_OBJECT_M` of it, with a mask
    within :data:`SAME_MASK_FACTOR` of the one the sighting predicts from ``pose``."""
    if math.dist(sighting.position, position) > SAME_OBJECT_M:
        return False
    if sighting.mask_area <= 0.0:
        return True
    seen_from = math.dist((sighting.pose.x, sighting.pose.y, 1.0), sighting.position)
    here = math.dist((pose.x, pose.y, 1.0), sighting.position)
    expected = sighting.mask_area * (seen_from / max(here, 0.1)) ** 2
    return expected / SAME_MASK_FACTOR <= mask_area <= expected * SAME_MASK_FACTOR


class TaskOdds:
    """One search task's state and what it believes of the target's sightings: the inspections
    made, the sightings left unconfirmed with their odds, and the odds a new report starts from
    (:class:`~objsearch.agent.task.SearchTask` acts on them)."""

    def __init__(self, agent: SearchingAgent, world: World, task_id: str, target: str) -> None:
        self.agent = agent
        self.world = world
        self.task_id = task_id
        self.target = target
        #: Inspections of each stop (by key) in this task: what the revisits' weights count.
        self.inspected: dict[str, int] = {}
        #: Each sighting confirmation rejected or left undecided, with its odds: a later sighting
        #: of the same object starts from them (one sequential test per object), and a revisit
        #: pass looks again at those still undecided.
        self.unconfirmed: list[tuple[Found, float]] = []
        #: Sightings of the target made during another's confirming looks, still to confirm.
        self.queued: list[Found] = []
        #: The stop (of the target's) each static belongs to, and the one being inspected.
        self.stop_of: dict[str, Stop] = {}
        self.current: str | None = None
        self._places: dict[str, tuple[dict[str, float], float]] = {}

    def looks_at(self, stop: Stop) -> int:
        return self.inspected.get(stop.key, 0)

    def prior_odds(self, position: Vec3, mask_area: float, pose: Pose) -> float:
        """The odds this task's earlier looks left at the object a report at ``position`` with
        ``mask_area``, seen from ``pose``, is (:func:`same_object`), or, for a first sighting
        there, :meth:`sighting_odds`."""
        for sighting, odds in reversed(self.unconfirmed):
            if same_object(sighting, position, mask_area, pose):
                return odds
        return self.sighting_odds(position, mask_area)

    def places(self, d: str) -> tuple[dict[str, float], float]:
        """:meth:`SearchingAgent.place_probabilities` of ``d``, once per task (the model learns
        when a task ends)."""
        if d not in self._places:
            self._places[d] = self.agent.place_probabilities(d)
        return self._places[d]

    def place_probability(self, place: str | None) -> float:
        """P(the target is at ``place`` (a static id; None: away from every mapped static))
        before this look: the model's, after this task's earlier inspections of the place's
        stop that did not see it (:meth:`SearchingAgent.stop_miss_after` of them), never below
        an even share over the home's statics of elsewhere's mass (at least ``ELSEWHERE_PRIOR``):
        a model's zero is not certainty, and a pose error can put a sighting at a neighbour."""
        values, elsewhere = self.places(self.target)
        if place is None:
            return elsewhere
        weights: dict[str, float] = {}
        for static_id, v in values.items():
            stop = self.stop_of.get(static_id)
            if stop is not None and v > 0:
                looks = self.looks_at(stop) - (1 if stop.key == self.current else 0)
                v *= self.agent.stop_miss_after(self.target, stop, looks)
            weights[static_id] = v
        total = math.fsum(weights.values()) + elsewhere
        p = weights.get(place, 0.0) / total if total > 0 else 0.0
        return max(p, max(elsewhere, ELSEWHERE_PRIOR) / max(len(values), 1))

    def sighting_odds(self, position: Vec3, mask_area: float) -> float:
        """Prior odds that a first report of the target at ``position`` is the target and not a
        false report (docs/perception.md, "The prior of a sighting"): π r / f, the chance the
        target is there and reported against the chance of a false report there, which comes
        whether the target is there or not (so even a place the target surely holds leaves odds
        of r / f: a false positive beside the real object is no find);
        π = P(target at that place) (:meth:`place_probability`),
        r = the detector's recall for the mask it showed, taken as occluded (the lower one),
        f = the false reports of the target's class per view: its share of the false positives
        (``fp_per_image`` over the movable classes), all taken to land at this place (the upper
        bound), plus confusions of the similar classes the model expects there."""
        agent = self.agent
        model = agent.config.perception
        pose = self.world.pose()
        nearest = agent.semmap.nearest(position, agent.navmap.room_at(pose.x, pose.y))
        place = (
            nearest[0].id
            if nearest is not None and nearest[1] <= agent.config.support_radius
            else None
        )
        pi = self.place_probability(place)
        recall = model.recall(mask_area, visible=0.0)
        false = model.fp_per_image / max(agent.movable_classes, 1)
        for other, similar in SIMILAR.items():
            if self.target in similar and other in agent.vocabulary.classes:
                values, elsewhere = self.places(other)
                there = elsewhere if place is None else values.get(place, 0.0)
                false += model.confusion * recall * there / len(similar)
        if false <= 0.0:
            return SURE_ODDS
        return min(SURE_ODDS, pi * recall / false)

    def undecided(self) -> list[tuple[Found, float]]:
        """The sightings whose odds are still above the rejection bound, likeliest first (the
        latest odds of each object)."""
        model = self.agent.config.perception
        latest: list[tuple[Found, float]] = []
        for sighting, odds in reversed(self.unconfirmed):
            if all(math.dist(sighting.position, s.position) > SAME_OBJECT_M for s, _ in latest):
                latest.append((sighting, odds))
        kept = [(s, o) for s, o in latest if model.posterior(o) >= REJECT_BELOW]
        return sorted(kept, key=lambda so: -so[1])

    def is_sure(self, det: Detection) -> bool:
        """Whether one detection of the target is a sighting by itself: its score's likelihood
        ratio times the odds earlier looks left at its place reach ``accept_posterior``."""
        model = self.agent.config.perception
        if model.perfect:
            return True
        odds = self.prior_odds(
            det.position, det.mask_area, self.world.pose()
        ) * model.likelihood_ratio(det.score)
        return model.posterior(odds) >= model.accept_posterior
