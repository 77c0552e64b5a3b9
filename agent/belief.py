"""A belief over places: P(the target is at static instance s | the map, everything in the log).

:class:`PlaceBelief` is the relation model ``RelationSpec("belief", k, half_life_scenes=h)``.
Unlike the memory (:mod:`objsearch.agent.memory`), whose per-place values are independent "is it
there" chances that sum to anything, its values are a probability distribution per target over the
home's static instances plus ``ELSEWHERE`` (not at any mapped place): a room's probability is the
sum of its places', and the planners' normalisations become conditioning.

The model, per target class d (docs/paper-readings.md, "The belief"):

- **An episode is a scene** (a day of the schedule; a task when the log records no scene). Within
  an episode objects stay put; between episodes each is drawn again from its habits.
- **Prior**: a Dirichlet with total weight k spread over the home's places in proportion to the
  Visual Genome relation of their class, Rel₀(d, class(s)), plus ``ELSEWHERE_PRIOR`` of it for
  elsewhere. Places whose class Rel₀ is 0 and where d was never seen get no mass (as before).
- **Evidence**: once per episode, the place where d was (last) seen, at a mapped place or away from
  all of them (elsewhere); which classes count follows the run's update mode. A target searched for
  and not found in an episode is a censored outcome: one count spread over the places not ruled out
  that day (not looked at), in proportion to the belief.
- **Change**: three predictions from the same outcomes — a long memory (Dirichlet, no forgetting),
  a short one (counts halve every h episodes) and yesterday (where d was last seen: objects that
  stay put) — mixed with weights learned online as the posterior responsibility of each for d's
  outcomes (a step 1/(n+2), never below ``STEP``, so the mix keeps adapting). A stable habit is
  carried by the long memory, a moved one by the short one within a few episodes, objects that
  wander off and stay (the stats schedules' Markov chain) by yesterday.
- **Today**: what the robot saw earlier in the same episode. A sighting of d at s makes s almost
  certain (1 − ``MOVED_TODAY``); a look at s that did not see d multiplies P(s) by the detector's
  miss probability ``MISS``. This is where "a Cup passed while looking for the Apple" counts.
  Under a modelled detector whose ``reports`` are ``evidence``, a report of d at s that is no
  sighting (its score or its mask too low to take) is not such a miss: it multiplies P(s) by its
  likelihood ratio (:meth:`~objsearch.agent.detector_model.PerceptionModel.look_ratio`).

The constants below were fixed before any run (docs/results.md, "The belief's protocol") and are
not tuned; k and h are recorded in the run spec.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any, ClassVar

from objsearch.agent.catalogue import (
    Detected,
    PlanComputed,
    RunStarted,
    SceneGraphSeeded,
    TaskStarted,
    ViewTaken,
    decode,
)
from objsearch.agent.detector_model import PerceptionModel
from objsearch.agent.home import Home, load_home
from objsearch.agent.scene_graph import Pair, UpdateMode
from objsearch.agent.sightings import LastSeen
from objsearch.events.projection import EventView

#: The place that is no mapped static: on the floor, in a hand, in a room never mapped.
ELSEWHERE = "(elsewhere)"
#: Share of the prior's weight on elsewhere.
ELSEWHERE_PRIOR = 0.05
#: Probability that a look at a place holding the target does not see it (occlusion, range).
MISS = 0.2
#: Probability that an object seen earlier today has been moved since.
MOVED_TODAY = 0.02
#: Smallest step of the mixing weights' update (about the last 10 episodes count).
STEP = 0.1
#: How much of yesterday's prediction is the prior (a place never seen is not impossible).
YESTERDAY_SMOOTHING = 0.05
#: Belief values below this are reported as 0 (a place is then no candidate).
FLOOR = 1e-9
#: The most a day's reports that were no sighting can multiply a place's odds by: finite, as a
#: score of 1 has an infinite likelihood ratio (such a report under its class's mask threshold).
REPORTS_CAP = 1e6


@dataclass(frozen=True, slots=True)
class Place:
    """A static instance of the home as the belief knows it."""

    static_id: str
    static_class: str
    room: str


@dataclass
class _Counts:
    """Dirichlet evidence of one memory: place -> (fractional) episodes."""

    total: float = 0.0
    at: dict[str, float] = field(default_factory=dict)

    def add(self, place: str, weight: float) -> None:
        self.at[place] = self.at.get(place, 0.0) + weight
        self.total += weight

    def fade(self, factor: float) -> None:
        self.at = {p: v * factor for p, v in self.at.items() if v * factor > 1e-9}
        self.total = math.fsum(self.at.values())


@dataclass
class Today:
    """What the robot saw in the current episode, folded from the log: where each class was seen
    (its last sighting), the places looked at without seeing a class, the targets searched for.

    :meth:`condition` turns a distribution for a new episode into one for now. The belief and the
    distribution oracle share it, so the reference knows today exactly what a robot could.

    A task's looks and sightings count when the task ends: a search plans every room from the
    values at its start (the ``plan_computed`` events record them, and the audit checks that they
    are the fold's), and within one search the planner's expected path already assumes that the
    places it passed did not hold the target.
    """

    key: tuple[str, int] | None = None
    target: str | None = None
    classes: tuple[str, ...] = ()
    seen: dict[str, str] = field(default_factory=dict)
    #: The running task's sightings and looks, counted when it ends.
    sighted: dict[str, str] = field(default_factory=dict)
    looked: dict[str, int] = field(default_factory=dict)
    missed: dict[str, dict[str, int]] = field(default_factory=dict)
    searched: set[str] = field(default_factory=set)
    #: P(a look at a place holding the target does not see it): ``MISS`` with a perfect
    #: detector; with a modelled one (the run's ``params.perception``) also its own miss
    #: probability at a medium-sized mask (:func:`look_miss`).
    miss: float = MISS
    #: The run's detector when its reports that are no sighting count as evidence (``reports``
    #: ``evidence``), else None: every view of a place that took no sighting of d is a miss.
    reports_model: PerceptionModel | None = None
    #: The running task's reports that were no sighting: class -> place -> scores.
    reported: dict[str, dict[str, list[float]]] = field(default_factory=dict)
    #: This episode's product of those reports' likelihood ratios: class -> place -> factor.
    support: dict[str, dict[str, float]] = field(default_factory=dict)

    def starts(self, event: EventView, started: TaskStarted) -> bool:
        """A task starts; True if it opens a new episode (the caller closes the old one first)."""
        key = ("scene", started.scene) if started.scene is not None else ("task", event.seq)
        return key != self.key or started.scene is None

    def open(self, event: EventView, started: TaskStarted) -> None:
        self.key = ("scene", started.scene) if started.scene is not None else ("task", event.seq)
        self.seen, self.sighted, self.looked, self.missed = {}, {}, {}, {}
        self.searched = set()
        self.reported, self.support = {}, {}

    def apply(self, event: EventView) -> None:
        kind = event.type
        if kind == "run_started":
            perception = decode(event, RunStarted).params.get("perception")
            self.miss = look_miss(perception)
            self.reports_model = reports_model(perception)
        elif kind == "task_started":
            self.target = decode(event, TaskStarted).target
            self.searched.add(self.target)
        elif kind == "view_taken":
            static_id = decode(event, ViewTaken).static_id
            if static_id is not None:
                self.looked[static_id] = self.looked.get(static_id, 0) + 1
        elif kind == "detection":
            detected = decode(event, Detected)
            support = detected.support
            at = support is not None and support.at
            if detected.accepted:
                self.sighted[detected.object_class] = (
                    support.static_id if support is not None and at else ELSEWHERE
                )
            elif self.reports_model is not None and support is not None and at:
                scores = self.reported.setdefault(detected.object_class, {})
                scores.setdefault(support.static_id, []).append(detected.score)
        elif kind in ("task_ended", "task_aborted"):
            # What a search saw happened, whether it ended or was cut short. A look that did not
            # see a class is a miss for it today: every class the detector reports, not only the
            # target (the robot saw the place without it).
            self.seen.update(self.sighted)
            for place, looks in self.looked.items():
                for d in self.classes:
                    # A view whose report of d there was no sighting is no miss of d there.
                    misses = looks - len(self.reported.get(d, {}).get(place, ()))
                    if self.sighted.get(d) != place and misses > 0:
                        per = self.missed.setdefault(d, {})
                        per[place] = per.get(place, 0) + misses
            self._count_reports()
            self.sighted, self.looked, self.reported = {}, {}, {}
            self.target = None

    def _count_reports(self) -> None:
        """The running task's reports that were no sighting, each by its likelihood ratio (a
        report of the class where it was also sighted adds nothing to the sighting)."""
        model = self.reports_model
        if model is None:
            return
        for d, places in sorted(self.reported.items()):
            for place, scores in sorted(places.items()):
                if self.sighted.get(d) == place:
                    continue
                factor = self.support.setdefault(d, {}).get(place, 1.0)
                for score in scores:
                    factor *= model.look_ratio(TYPICAL_MASK_PX, score)
                self.support[d][place] = min(factor, REPORTS_CAP)

    def condition(self, d: str, base: Mapping[str, float]) -> dict[str, float]:
        """``base`` conditioned on this episode's looks and sightings (sums to 1 if base does)."""
        missed = self.missed.get(d, {})
        support = self.support.get(d, {})
        seen = self.seen.get(d)
        today = {p: v * self.miss ** missed.get(p, 0) for p, v in base.items()}
        if support:
            today = {p: v * support.get(p, 1.0) for p, v in today.items()}
        total = math.fsum(today.values())
        today = {p: v / total for p, v in today.items()} if total > 0 else dict(base)
        if seen is not None:
            today = {p: MOVED_TODAY * v for p, v in today.items()}
            today[seen] = today.get(seen, 0.0) + (1 - MOVED_TODAY)
        return today

    def to_snapshot(self) -> dict[str, Any]:
        return {
            "key": None if self.key is None else list(self.key),
            "target": self.target,
            "classes": list(self.classes),
            "seen": dict(sorted(self.seen.items())),
            "sighted": dict(sorted(self.sighted.items())),
            "looked": dict(sorted(self.looked.items())),
            "missed": {d: dict(sorted(m.items())) for d, m in sorted(self.missed.items())},
            "searched": sorted(self.searched),
            # Only when a modelled detector set it: perfect runs' snapshots stay as they were.
            **({"miss": self.miss} if self.miss != MISS else {}),
            # Only when reports count as evidence: other runs' snapshots stay as they were.
            **(
                {
                    "reports_model": self.reports_model.params(),
                    "reported": {
                        d: {p: list(v) for p, v in sorted(m.items())}
                        for d, m in sorted(self.reported.items())
                    },
                    "support": {
                        d: dict(sorted(m.items())) for d, m in sorted(self.support.items())
                    },
                }
                if self.reports_model is not None
                else {}
            ),
        }

    @classmethod
    def from_snapshot(cls, state: Mapping[str, Any]) -> Today:
        key = state["key"]
        return cls(
            key=None if key is None else (str(key[0]), int(key[1])),
            target=state["target"],
            classes=tuple(state["classes"]),
            seen=dict(state["seen"]),
            sighted=dict(state["sighted"]),
            looked={p: int(n) for p, n in state["looked"].items()},
            missed={d: {p: int(n) for p, n in m.items()} for d, m in state["missed"].items()},
            searched=set(state["searched"]),
            miss=float(state.get("miss", MISS)),
            reports_model=reports_model(state.get("reports_model")),
            reported={
                d: {p: [float(x) for x in v] for p, v in m.items()}
                for d, m in state.get("reported", {}).items()
            },
            support={
                d: {p: float(x) for p, x in m.items()} for d, m in state.get("support", {}).items()
            },
        )


#: The mask a target shows from a stop's viewpoint, for the detector's miss probability there: the
#: middle of COCO's medium bin (a cup at about 1.5 m). A per-view size is not modelled yet.
TYPICAL_MASK_PX = 48.0 * 48.0


def reports_model(perception: object) -> PerceptionModel | None:
    """The run's detector (``params.perception``) if its reports that are no sighting count as
    evidence (``reports`` ``evidence``), else None (a perfect detector, or a run spec that names
    no ``reports``: recorded before the option, folded as it ran)."""
    if not isinstance(perception, Mapping):
        return None
    model = PerceptionModel.from_params(perception)
    return None if model.perfect or model.reports != "evidence" else model


def look_miss(perception: object, mask_px: float = TYPICAL_MASK_PX) -> float:
    """P(a look misses a target that is there) for a run's detector (``params.perception``;
    None: perfect): the belief's own ``MISS`` (occlusion, range), or else the detector's miss on
    top of it, for a target showing ``mask_px`` pixels (the belief's fold: a typical mask; a
    revisit: the target's expected mask from each stop, agent/policy.py)."""
    if not isinstance(perception, Mapping):
        return MISS
    model = PerceptionModel.from_params(perception)
    if model.perfect:
        return MISS
    return 1.0 - (1.0 - MISS) * model.recall(mask_px)


def responsibilities(
    weights: tuple[float, float, float],
    predictions: tuple[Mapping[str, float], ...],
    outcome: Mapping[str, float],
    episodes: float,
    step_floor: float = STEP,
) -> tuple[float, float, float]:
    """Mixing weights moved toward each prediction's posterior responsibility for ``outcome``
    (a step 1/(n+2) after n episodes, never below ``step_floor``); unchanged when no prediction
    gave the outcome any probability."""
    likelihood = [
        math.fsum(w * pred.get(p, 0.0) for p, w in outcome.items()) for pred in predictions
    ]
    joint = [w * lk for w, lk in zip(weights, likelihood, strict=True)]
    total = math.fsum(joint)
    if total <= 0:
        return weights
    step = max(1.0 / (episodes + 2.0), step_floor)
    new = [(1 - step) * w + step * j / total for w, j in zip(weights, joint, strict=True)]
    return new[0], new[1], new[2]


@dataclass
class PlaceBelief:
    """The belief (see the module doc); a relation model with per-instance values."""

    prior_strength: float = 1.0
    half_life_scenes: float = 3.0
    update_mode: UpdateMode = UpdateMode.ALL
    last_seq: int = 0
    tasks_folded: int = 0
    home: str | None = None
    places: dict[str, Place] = field(default_factory=dict)
    prior: dict[Pair, float] = field(default_factory=dict)
    long: dict[str, _Counts] = field(default_factory=dict)
    short: dict[str, _Counts] = field(default_factory=dict)
    #: Mixing weights of the long memory, the short one and yesterday, per class.
    weights: dict[str, tuple[float, float, float]] = field(default_factory=dict)
    #: Where each class was seen in its last episode with an outcome (not a censored one).
    yesterday: dict[str, str] = field(default_factory=dict)
    #: Evidence age: the episode in which each class's last outcome was counted.
    last_outcome: dict[str, int] = field(default_factory=dict)
    episodes: int = 0
    today: Today = field(default_factory=Today)
    #: Where each class was last seen (with its position), for ``where``.
    sightings: LastSeen = field(default_factory=LastSeen)
    #: The data folder the run's home is read from (None: ``datapaths.data_dir()``).
    data: Path | None = field(default=None, repr=False, compare=False)
    _cache: dict[str, dict[str, float]] = field(default_factory=dict, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.prior_strength <= 0 or self.half_life_scenes <= 0:
            raise ValueError("the belief needs prior strength > 0 and half-life > 0")

    # -- the fold -----------------------------------------------------------------------------

    def apply(self, event: EventView) -> None:
        self._cache = {}
        kind = event.type
        if kind == "run_started":
            run = decode(event, RunStarted)
            self.update_mode = UpdateMode(run.update_mode)
            if self.home is None:
                self.use_home(load_home(run.home, self.data))
        elif kind == "scene_graph_seeded":
            self.prior = {
                (v.dynamic, v.static): v.rel for v in decode(event, SceneGraphSeeded).values
            }
            self.today.classes = tuple(sorted({d for d, _ in self.prior}))
        elif kind == "task_started":
            started = decode(event, TaskStarted)
            if self.today.starts(event, started):
                self._close_episode()
                self.today.open(event, started)
        elif kind == "plan_computed":
            for c in decode(event, PlanComputed).candidates:
                if c.static_id not in self.places:
                    self.places[c.static_id] = Place(c.static_id, c.static_class, "")
        self.today.apply(event)
        self.sightings.apply(event)
        if kind == "task_ended":
            self.tasks_folded += 1
            if self.today.key is not None and self.today.key[0] == "task":
                self._close_episode()
        self.last_seq = event.seq

    def use_home(self, home: Home) -> None:
        """The places the belief is over: the home's static instances."""
        self.home = home.name
        for room in home.rooms:
            for s in room.statics:
                self.places[s.id] = Place(s.id, s.cls, room.name)

    def _close_episode(self) -> None:
        if self.today.key is None:
            return
        counted, outcomes = self._outcomes()
        self._count(counted, outcomes)
        self.today.key = None

    def _outcomes(self) -> tuple[dict[str, str], dict[str, dict[str, float]]]:
        """The closing episode's evidence: where each counted class was seen, and each class's
        outcome (a place, or a censored search's spread)."""
        today = self.today
        if self.update_mode is UpdateMode.ALL:
            counted = dict(today.seen)
        elif self.update_mode is UpdateMode.TARGETS:
            counted = {d: p for d, p in today.seen.items() if d in today.searched}
        else:
            counted = {}
        outcomes: dict[str, dict[str, float]] = {d: {p: 1.0} for d, p in counted.items()}
        if self.update_mode is not UpdateMode.NONE:
            for d in sorted(today.searched - set(today.seen)):
                outcomes[d] = self._censored(d)
        return counted, outcomes

    def _count(
        self, counted: Mapping[str, str], outcomes: Mapping[str, Mapping[str, float]]
    ) -> None:
        """One episode's outcomes into the memories and their mixing weights."""
        factor = 0.5 ** (1.0 / self.half_life_scenes)
        for d, outcome in sorted(outcomes.items()):
            self._weigh_memories(d, outcome)
            if d in counted:
                self.yesterday[d] = counted[d]
            long = self.long.setdefault(d, _Counts())
            short = self.short.setdefault(d, _Counts())
            short.fade(factor)
            for place, w in outcome.items():
                long.add(place, w)
                short.add(place, w)
            self.last_outcome[d] = self.episodes
        self.episodes += 1

    def _censored(self, d: str) -> dict[str, float]:
        """A search that never saw d: one episode spread over what today's looks left open."""
        now = self.today.condition(d, self._base(d))
        total = math.fsum(now.values())
        return {p: v / total for p, v in now.items() if v > 0} if total > 0 else {}

    def _weigh_memories(self, d: str, outcome: Mapping[str, float]) -> None:
        """Each prediction's responsibility for the outcome, averaged into the mixing weights."""
        weights = self.weights.get(d, (1 / 3, 1 / 3, 1 / 3))
        n = self.long[d].total if d in self.long else 0.0
        self.weights[d] = responsibilities(weights, self._predictions(d), outcome, n)

    # -- the distribution ---------------------------------------------------------------------

    def _prior_weights(self, d: str) -> dict[str, float]:
        """The Dirichlet prior: weight k over the places by their class's Rel₀, a share on
        elsewhere (all of it when no place is related at all)."""
        raw = {sid: self.prior.get((d, p.static_class), 0.0) for sid, p in self.places.items()}
        total = math.fsum(raw.values())
        k = self.prior_strength
        if total <= 0:
            return {ELSEWHERE: k}
        weights = {s: k * (1 - ELSEWHERE_PRIOR) * v / total for s, v in raw.items() if v > 0}
        weights[ELSEWHERE] = k * ELSEWHERE_PRIOR
        return weights

    def _dirichlet(self, alpha: Mapping[str, float], counts: _Counts | None) -> dict[str, float]:
        total = math.fsum(alpha.values()) + (counts.total if counts else 0.0)
        seen = counts.at if counts else {}
        return {
            p: (alpha.get(p, 0.0) + seen.get(p, 0.0)) / total for p in alpha.keys() | seen.keys()
        }

    def _predictions(self, d: str) -> tuple[dict[str, float], ...]:
        """The long memory's, the short one's and yesterday's P(place) for a new episode."""
        alpha = self._prior_weights(d)
        long = self._dirichlet(alpha, self.long.get(d))
        short = self._dirichlet(alpha, self.short.get(d))
        last = self.yesterday.get(d)
        if last is None:
            return long, short, long
        yesterday = {p: YESTERDAY_SMOOTHING * v for p, v in long.items()}
        yesterday[last] = yesterday.get(last, 0.0) + (1 - YESTERDAY_SMOOTHING)
        return long, short, yesterday

    def _base(self, d: str) -> dict[str, float]:
        """P(place) for a new episode: the three predictions mixed by their weights."""
        weights = self.weights.get(d, (1 / 3, 1 / 3, 1 / 3))
        out: dict[str, float] = {}
        for w, pred in zip(weights, self._predictions(d), strict=True):
            for p in sorted(pred):
                out[p] = out.get(p, 0.0) + w * pred[p]
        return out

    def distribution(self, d: str) -> dict[str, float]:
        """P(place) for class d now: every place with mass, and ``ELSEWHERE``; sums to 1."""
        cached = self._cache.get(d)
        if cached is None:
            cached = self._cache[d] = self.today.condition(d, self._base(d))
        return cached

    def instance_rel(self, dynamic: str, static_id: str, static_class: str) -> float:
        p = self.distribution(dynamic).get(static_id, 0.0)
        return p if p > FLOOR else 0.0

    def rel(self, dynamic: str, static: str) -> float:
        """The class-level view: P(d at some instance of class ``static``)."""
        return min(
            1.0,
            math.fsum(
                v
                for p, v in self.distribution(dynamic).items()
                if p in self.places and self.places[p].static_class == static
            ),
        )

    def rooms(self, d: str) -> dict[str, float]:
        """P(room) for class d: sums of its places' probabilities (elsewhere apart)."""
        out: dict[str, float] = {}
        for p, v in self.distribution(d).items():
            if p in self.places:
                room = self.places[p].room
                out[room] = out.get(room, 0.0) + v
        return out

    @property
    def state(self) -> Mapping[Pair, float]:
        values = {(d, s): self.rel(d, s) for d, s in sorted(self.prior)}
        return MappingProxyType({pair: v for pair, v in values.items() if v > 0})

    def as_table(self) -> dict[str, dict[str, float]]:
        table: dict[str, dict[str, float]] = {}
        for (d, s), v in self.state.items():
            table.setdefault(d, {})[s] = v
        return table

    # -- snapshots ------------------------------------------------------------------------------

    snapshot_name: ClassVar[str] = "place_belief"
    snapshot_version: ClassVar[int] = 1

    def to_snapshot(self) -> dict[str, Any]:
        def counts(c: Mapping[str, _Counts]) -> dict[str, dict[str, float]]:
            return {d: dict(sorted(v.at.items())) for d, v in sorted(c.items())}

        return {
            "prior_strength": self.prior_strength,
            "half_life_scenes": self.half_life_scenes,
            "update_mode": self.update_mode.value,
            "tasks_folded": self.tasks_folded,
            "home": self.home,
            "places": [[p.static_id, p.static_class, p.room] for p in self.places.values()],
            "prior": [[d, s, v] for (d, s), v in sorted(self.prior.items())],
            "long": counts(self.long),
            "short": counts(self.short),
            "weights": {d: list(w) for d, w in sorted(self.weights.items())},
            "yesterday": dict(sorted(self.yesterday.items())),
            "last_outcome": dict(sorted(self.last_outcome.items())),
            "episodes": self.episodes,
            "today": self.today.to_snapshot(),
            "sightings": self.sightings.to_snapshot(),
        }

    @classmethod
    def from_snapshot(cls, state: Mapping[str, Any], last_seq: int) -> PlaceBelief:
        def counts(c: Mapping[str, Mapping[str, float]]) -> dict[str, _Counts]:
            out = {}
            for d, at in c.items():
                values = {p: float(v) for p, v in at.items()}
                out[d] = _Counts(math.fsum(values.values()), values)
            return out

        return cls(
            prior_strength=float(state["prior_strength"]),
            half_life_scenes=float(state["half_life_scenes"]),
            update_mode=UpdateMode(state["update_mode"]),
            last_seq=last_seq,
            tasks_folded=int(state["tasks_folded"]),
            home=state["home"],
            places={r[0]: Place(r[0], r[1], r[2]) for r in state["places"]},
            prior={(d, s): float(v) for d, s, v in state["prior"]},
            long=counts(state["long"]),
            short=counts(state["short"]),
            weights={
                d: (float(w[0]), float(w[1]), float(w[2])) for d, w in state["weights"].items()
            },
            yesterday=dict(state["yesterday"]),
            last_outcome={d: int(v) for d, v in state["last_outcome"].items()},
            episodes=int(state["episodes"]),
            today=Today.from_snapshot(state["today"]),
            sightings=LastSeen.from_snapshot(state["sightings"]),
        )
