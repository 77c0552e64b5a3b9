"""A memory that knows the hour: :class:`RoutineBelief`, the relation model
``RelationSpec("routine-belief", k, half_life_scenes=h)``.

The time-blind belief (:class:`~objsearch.agent.belief.PlaceBelief`) learns where a class is *on
a day*; a household runs on routines — the mug on the desk in the morning, in the sink after
lunch. This belief is that same belief (it *is* one: the time-blind fold is its own, unchanged)
plus, for every time-of-day slot and day type a search began in (``task_started.clock``), a
belief of the same kind fed only those episodes, and a learned mix of the three predictions
(docs/paper-readings.md, "The belief that knows the hour"):

- **Slots**: fixed, a human day's — night [22:00, 05:00), morning [05:00, 12:00), afternoon
  [12:00, 17:00), evening [17:00, 22:00); **day types**: weekday (Monday–Friday), weekend.
- **Components**: the time-blind belief; the slot's belief (every day's mornings); the slot's
  belief on this day type (weekday mornings). Each slot belief is a
  :class:`~objsearch.agent.belief.PlaceBelief` (long memory, short memory, "yesterday" — the same
  slot's last episode — mixed by responsibilities) whose Dirichlet prior is its parent's prediction
  with weight ``BUCKET_PRIOR_STRENGTH`` episodes (the slot's parent is the time-blind belief, the
  slot-and-day-type's the slot's): an empty slot predicts what its parent does, a few episodes
  move it — a hierarchical Dirichlet, so a weekend morning borrows from every morning.
- **Mix**: per class, the three predictions are mixed by the posterior probability of each as a
  model of the class's outcomes (a Bayesian model average), starting equal, with forgetting: each
  episode the log-evidence gathered so far is multiplied by ``MIX_MEMORY`` (the time-blind
  belief's step: about the last ten episodes count) before the episode's likelihood is added, so
  the weights can follow a routine that starts or stops. A class without a routine is predicted
  as well or better by the time-blind belief, which has four to eight times the evidence, so its
  weight goes there; a class with a routine is predicted better by its slot's. Episode outcomes
  (sightings, censored searches) are the time-blind belief's, counted into each component of the
  episode's clock. (The first version moved the weights toward each episode's responsibilities,
  as the time-blind belief mixes its memories: on schedules with no routine it kept about half
  the weight on the slots, docs/results-routine.md, "The stats regression".)
- **Today**: the mix is conditioned on the episode's looks and sightings as the time-blind belief
  is (:class:`~objsearch.agent.belief.Today`).

**Pooled** (:class:`PooledRoutineBelief`, ``RelationSpec("routine-pooled", k, h)``, docs/results-routine.md
"Protocol v-next"): the model average picks, per class, the one component that has predicted it
best; on a routine home the best forecast is a *mixture* (the slot's usual place most days, the
class's alternates and strays, which the time-blind belief carries, on the others), and one
class's ten or so scenes per slot are too few to learn its weights. This belief learns one
mixture of the three components for the whole home — each episode every class's posterior
responsibilities, averaged, move it (a step 1/(n+2), never below ``STEP``) — and offers it to each
class's model average as a fourth component: a class that keeps a routine like the rest of the
home gets it from the other classes' scenes, a class (or home) without one keeps the time-blind
belief, whose evidence the model average still weighs. The model average keeps its forgetting
(``MIX_MEMORY``) as log-evidence, each episode's floored at ``LIKELIHOOD_FLOOR`` so a component
that once gave an outcome nothing can come back; and a class's log-evidence is added to the
home's — each episode the mean over its classes of what they added — so whether the hour matters
in this home is learned from all of its classes at once (on a home without routines the
time-blind belief wins within a few scenes, not a few scenes per class).

A log with no clock (v1 ``task_started``, runs without a time of day) folds to exactly the
time-blind belief: no slot belief is ever fed, and an empty slot predicts its parent.
:meth:`distribution_at` answers for another time of day (``objsearch where --at``): that slot's
mix, conditioned on today only when the time is the current episode's slot and day type.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

from objsearch.agent.belief import STEP, PlaceBelief, responsibilities
from objsearch.agent.catalogue import DayClock, TaskStarted, decode
from objsearch.events.projection import EventView

#: (name, first minute after midnight), in order; the first slot also takes the day's last hours.
SLOTS: tuple[tuple[str, int], ...] = (
    ("night", 0),
    ("morning", 5 * 60),
    ("afternoon", 12 * 60),
    ("evening", 17 * 60),
    ("night", 22 * 60),
)
WEEKEND = (5, 6)
#: A slot belief's prior weight on its parent's prediction (episodes). Fixed before any run.
BUCKET_PRIOR_STRENGTH = 1.0
#: Share of the mix's log-evidence kept from one of a class's episodes to the next (1 − the
#: time-blind belief's smallest step ``belief.STEP``: about the last ten episodes count).
MIX_MEMORY = 1.0 - STEP
#: The mix's starting weights: time-blind, slot, slot and day type.
START_MIX = (1 / 3, 1 / 3, 1 / 3)
COMPONENTS = ("blind", "slot", "slot_day")
#: The pooled belief's components: the three, and the home's mixture of them.
POOLED_COMPONENTS = (*COMPONENTS, "pooled")
#: Smallest likelihood an episode adds to a component's log-evidence (pooled belief).
LIKELIHOOD_FLOOR = 1e-12


def slot_of(minute: int) -> str:
    """The slot a minute after midnight falls in."""
    name = SLOTS[0][0]
    for slot, first in SLOTS:
        if minute >= first:
            name = slot
    return name


def day_type(weekday: int) -> str:
    return "weekend" if weekday in WEEKEND else "weekday"


def buckets_of(clock: DayClock) -> tuple[str, str]:
    """The names of a clock's slot belief and slot-and-day-type belief."""
    slot = slot_of(clock.minute)
    return slot, f"{slot}/{day_type(clock.weekday)}"


def model_average(
    weights: tuple[float, float, float],
    predictions: tuple[Mapping[str, float], ...],
    outcome: Mapping[str, float],
    memory: float = MIX_MEMORY,
) -> tuple[float, float, float]:
    """The posterior of each prediction as the model of a class's outcomes after one more
    episode: w_i ∝ START_i^(1 − memory) · w_i^memory · P_i(outcome) — a Bayesian model average
    whose log-evidence is multiplied by ``memory`` each episode (so it decays toward the start
    weights); unchanged when no prediction gave the outcome any probability."""
    likelihood = [
        math.fsum(w * pred.get(p, 0.0) for p, w in outcome.items()) for pred in predictions
    ]
    joint = [
        start ** (1.0 - memory) * w**memory * lk
        for start, w, lk in zip(START_MIX, weights, likelihood, strict=True)
    ]
    total = math.fsum(joint)
    if total <= 0:
        return weights
    return joint[0] / total, joint[1] / total, joint[2] / total


@dataclass
class SlotBelief(PlaceBelief):
    """A belief of the episodes of one slot (and day type): counts handed to it by
    :class:`RoutineBelief`, its prior its parent's prediction."""

    parent: Callable[[str], dict[str, float]] | None = field(
        default=None, repr=False, compare=False
    )

    def _prior_weights(self, d: str) -> dict[str, float]:
        if self.parent is None:
            return super()._prior_weights(d)
        k = self.prior_strength
        return {p: k * v for p, v in self.parent(d).items() if v > 0}

    def base(self, d: str) -> dict[str, float]:
        """P(place) for a new episode of this slot."""
        return self._base(d)


@dataclass
class RoutineBelief(PlaceBelief):
    """The belief that knows the hour (see the module doc)."""

    buckets: dict[str, SlotBelief] = field(default_factory=dict)
    #: Mixing weights of the time-blind, slot and slot-and-day-type predictions, per class.
    mix: dict[str, tuple[float, float, float]] = field(default_factory=dict)
    #: The clock of the current episode (its first task's), None when the log gave none.
    clock: DayClock | None = None

    # -- the fold -----------------------------------------------------------------------------

    def apply(self, event: EventView) -> None:
        if event.type == "task_started":
            started = decode(event, TaskStarted)
            if self.today.starts(event, started):
                self._close_episode()
                self.clock = started.clock
        super().apply(event)

    def _close_episode(self) -> None:
        if self.today.key is None:
            return
        counted, outcomes = self._outcomes()
        if self.clock is not None:
            slot, slot_day = (self._bucket(name) for name in buckets_of(self.clock))
            for d, outcome in sorted(outcomes.items()):
                self._weigh_mix(d, outcome, self._components(d, self.clock))
            slot_day._count(counted, outcomes)
            slot._count(counted, outcomes)
        self._count(counted, outcomes)
        self.today.key = None

    def _bucket(self, name: str) -> SlotBelief:
        bucket = self.buckets.get(name)
        if bucket is None:
            bucket = self.buckets[name] = SlotBelief(
                prior_strength=BUCKET_PRIOR_STRENGTH, half_life_scenes=self.half_life_scenes
            )
            self._link(name, bucket)
        return bucket

    def _link(self, name: str, bucket: SlotBelief) -> None:
        slot = name.partition("/")[0]
        bucket.parent = self._blind if slot == name else self._slot_prediction(slot)

    def _slot_prediction(self, slot: str) -> Callable[[str], dict[str, float]]:
        def predict(d: str) -> dict[str, float]:
            bucket = self.buckets.get(slot)
            return bucket.base(d) if bucket is not None else self._blind(d)

        return predict

    def _weigh_mix(
        self, d: str, outcome: Mapping[str, float], predictions: tuple[dict[str, float], ...]
    ) -> None:
        self.mix[d] = model_average(self.mix.get(d, START_MIX), predictions, outcome)

    # -- the distribution ---------------------------------------------------------------------

    def _blind(self, d: str) -> dict[str, float]:
        """The time-blind belief's prediction for a new episode."""
        return super()._base(d)

    def _components(self, d: str, clock: DayClock) -> tuple[dict[str, float], ...]:
        """The time-blind, slot and slot-and-day-type predictions at ``clock``."""
        slot_name, slot_day_name = buckets_of(clock)
        blind = self._blind(d)
        slot = self.buckets.get(slot_name)
        slot_pred = slot.base(d) if slot is not None else blind
        slot_day = self.buckets.get(slot_day_name)
        if slot_day is not None:
            return blind, slot_pred, slot_day.base(d)
        return blind, slot_pred, slot_pred

    def _base_at(self, d: str, clock: DayClock | None) -> dict[str, float]:
        if clock is None:
            return self._blind(d)
        weights = self.mix.get(d, START_MIX)
        out: dict[str, float] = {}
        for w, pred in zip(weights, self._components(d, clock), strict=True):
            for p in sorted(pred):
                out[p] = out.get(p, 0.0) + w * pred[p]
        return out

    def _base(self, d: str) -> dict[str, float]:
        return self._base_at(d, self.clock)

    def habit_at(self, d: str, clock: DayClock) -> dict[str, float]:
        """Where class d usually is at ``clock``: each component's long memory (its Dirichlet
        over every episode it was fed, without the short memory or the last episode), mixed by
        the class's weights. Nothing the search agent decides reads it; ``bench stot`` forecasts
        its lookahead steps beyond the next with it (docs/results-stot.md)."""
        slot_name, slot_day_name = buckets_of(clock)
        blind = self._dirichlet(self._prior_weights(d), self.long.get(d))
        slot_bucket = self.buckets.get(slot_name)
        slot = (
            blind
            if slot_bucket is None
            else slot_bucket._dirichlet(slot_bucket._prior_weights(d), slot_bucket.long.get(d))
        )
        day_bucket = self.buckets.get(slot_day_name)
        slot_day = (
            slot
            if day_bucket is None
            else day_bucket._dirichlet(day_bucket._prior_weights(d), day_bucket.long.get(d))
        )
        return mixture(self.mix.get(d, START_MIX), (blind, slot, slot_day))

    def component_weights(self, d: str) -> dict[str, float]:
        """Class d's weight on each component of the mix (what ``where`` shows)."""
        return dict(zip(COMPONENTS, self.mix.get(d, START_MIX), strict=True))

    def distribution_at(self, d: str, clock: DayClock | None) -> dict[str, float]:
        """P(place) for class d at ``clock`` (None: now, the current episode's time): today's
        looks and sightings count only in the current episode's slot and day type. A belief that
        never folded a time of day answers as the time-blind one, whatever the time."""
        if not self.knows_hours or clock is None:
            return self.distribution(d)
        if self.clock is not None and buckets_of(clock) == buckets_of(self.clock):
            return self.today.condition(d, self._base_at(d, clock))
        return self._base_at(d, clock)

    @property
    def knows_hours(self) -> bool:
        """Whether any episode with a time of day was folded (else it is the time-blind belief)."""
        return bool(self.buckets)

    # -- snapshots ------------------------------------------------------------------------------

    snapshot_name: ClassVar[str] = "routine_belief"
    snapshot_version: ClassVar[int] = 2  # 2: the mix is a model average with forgetting

    def to_snapshot(self) -> dict[str, Any]:
        return {
            **super().to_snapshot(),
            "buckets": {name: b.to_snapshot() for name, b in sorted(self.buckets.items())},
            "mix": {d: list(w) for d, w in sorted(self.mix.items())},
            "clock": None if self.clock is None else [self.clock.weekday, self.clock.minute],
        }

    @classmethod
    def from_snapshot(cls, state: Mapping[str, Any], last_seq: int) -> RoutineBelief:
        belief = super().from_snapshot(state, last_seq)
        assert isinstance(belief, RoutineBelief)
        for name, snap in state["buckets"].items():
            bucket = SlotBelief.from_snapshot(snap, last_seq)
            assert isinstance(bucket, SlotBelief)
            belief.buckets[name] = bucket
            belief._link(name, bucket)
        belief.mix = {d: (float(w[0]), float(w[1]), float(w[2])) for d, w in state["mix"].items()}
        clock = state["clock"]
        belief.clock = None if clock is None else DayClock(weekday=clock[0], minute=clock[1])
        return belief


def mixture(
    weights: tuple[float, ...], predictions: tuple[Mapping[str, float], ...]
) -> dict[str, float]:
    """Σ_i w_i · prediction_i."""
    out: dict[str, float] = {}
    for w, pred in zip(weights, predictions, strict=True):
        for p in sorted(pred):
            out[p] = out.get(p, 0.0) + w * pred[p]
    return out


def log_likelihoods(
    predictions: tuple[Mapping[str, float], ...], outcome: Mapping[str, float]
) -> tuple[float, ...]:
    """log P_i(outcome) of each prediction, floored at ``LIKELIHOOD_FLOOR``."""
    return tuple(
        math.log(max(math.fsum(w * pred.get(p, 0.0) for p, w in outcome.items()), LIKELIHOOD_FLOOR))
        for pred in predictions
    )


def softmax(evidence: tuple[float, ...]) -> tuple[float, ...]:
    """Weights ∝ exp(log-evidence), equal when no evidence was gathered."""
    top = max(evidence)
    raw = [math.exp(v - top) for v in evidence]
    total = math.fsum(raw)
    return tuple(v / total for v in raw)


@dataclass
class PooledRoutineBelief(RoutineBelief):
    """The belief that knows the hour, with the home's mixture of its components as a fourth
    component of each class's model average (see the module doc, "Pooled")."""

    #: The home's mixture of the time-blind, slot and slot-and-day-type predictions.
    pooled: tuple[float, float, float] = START_MIX
    #: Episodes that moved it.
    pooled_episodes: int = 0
    #: Per class, each of the four components' log-evidence (forgetting ``MIX_MEMORY``).
    evidence: dict[str, tuple[float, float, float, float]] = field(default_factory=dict)
    #: The home's: each episode the mean over its classes of what they added (same forgetting).
    home_evidence: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)

    def _close_episode(self) -> None:
        if self.today.key is None:
            return
        counted, outcomes = self._outcomes()
        if self.clock is not None:
            slot, slot_day = (self._bucket(name) for name in buckets_of(self.clock))
            moved: list[tuple[float, float, float]] = []
            gained: list[tuple[float, ...]] = []
            for d, outcome in sorted(outcomes.items()):
                predictions = self._four(d, self.clock)
                gain = log_likelihoods(predictions, outcome)
                before = self.evidence.get(d, (0.0, 0.0, 0.0, 0.0))
                after = [MIX_MEMORY * e + g for e, g in zip(before, gain, strict=True)]
                self.evidence[d] = (after[0], after[1], after[2], after[3])
                gained.append(gain)
                moved.append(responsibilities(self.pooled, predictions[:3], outcome, 0, 1.0))
            if moved:
                self._pool(moved)
                mean = [math.fsum(g[i] for g in gained) / len(gained) for i in range(4)]
                home = [MIX_MEMORY * e + m for e, m in zip(self.home_evidence, mean, strict=True)]
                self.home_evidence = (home[0], home[1], home[2], home[3])
            slot_day._count(counted, outcomes)
            slot._count(counted, outcomes)
        self._count(counted, outcomes)
        self.today.key = None

    def _pool(self, moved: list[tuple[float, float, float]]) -> None:
        """The home's mixture moved toward this episode's mean responsibilities."""
        mean = [math.fsum(r[i] for r in moved) / len(moved) for i in range(3)]
        step = max(1.0 / (self.pooled_episodes + 2.0), STEP)
        new = [(1 - step) * w + step * m for w, m in zip(self.pooled, mean, strict=True)]
        self.pooled = (new[0], new[1], new[2])
        self.pooled_episodes += 1

    def _four(self, d: str, clock: DayClock) -> tuple[dict[str, float], ...]:
        three = self._components(d, clock)
        return (*three, mixture(self.pooled, three))

    def _weights(self, d: str) -> tuple[float, ...]:
        own = self.evidence.get(d, (0.0, 0.0, 0.0, 0.0))
        return softmax(tuple(e + h for e, h in zip(own, self.home_evidence, strict=True)))

    def _base_at(self, d: str, clock: DayClock | None) -> dict[str, float]:
        if clock is None:
            return self._blind(d)
        return mixture(self._weights(d), self._four(d, clock))

    def component_weights(self, d: str) -> dict[str, float]:
        return dict(zip(POOLED_COMPONENTS, self._weights(d), strict=True))

    snapshot_name: ClassVar[str] = "pooled_routine_belief"
    snapshot_version: ClassVar[int] = 1

    def to_snapshot(self) -> dict[str, Any]:
        return {
            **super().to_snapshot(),
            "pooled": list(self.pooled),
            "pooled_episodes": self.pooled_episodes,
            "evidence": {d: list(e) for d, e in sorted(self.evidence.items())},
            "home_evidence": list(self.home_evidence),
        }

    @classmethod
    def from_snapshot(cls, state: Mapping[str, Any], last_seq: int) -> PooledRoutineBelief:
        belief = super().from_snapshot(state, last_seq)
        assert isinstance(belief, PooledRoutineBelief)
        w = state["pooled"]
        belief.pooled = (float(w[0]), float(w[1]), float(w[2]))
        belief.pooled_episodes = int(state["pooled_episodes"])
        belief.evidence = {
            d: (float(e[0]), float(e[1]), float(e[2]), float(e[3]))
            for d, e in state["evidence"].items()
        }
        h = state["home_evidence"]
        belief.home_evidence = (float(h[0]), float(h[1]), float(h[2]), float(h[3]))
        return belief
