"""``objsearch bench stot``: our belief at SpatioTemporalObjectTracking's task, beside its baselines.

SpatioTemporalObjectTracking (STOT) is the public code of Patel & Chernova, "Proactive Robot
Assistance via Spatio-Temporal Object Modeling" (CoRL 2022), ``Maithili/SpatioTemporalObjectTracking``
(MIT), with the HOMER households' processed days in its ``data/`` folder. It is not part of
objsearch: the user checks it out at :data:`PINNED_COMMIT` and passes the folder (``--source`` or
``$OBJSEARCH_STOT_SOURCE``). :func:`verify_source` compares every file the harness imports or
reads with that commit's git blob ids (:mod:`objsearch.experiments.stot_pins`) and refuses one
that differs, and any day file the commit does not have; day files that are absent are listed,
and every figure says how many days it is over.

**Its task** (its ``helpers/evaluations.py``, ``evaluate_all_breakdowns``, as its ``run.py
--baselines`` calls it): a test day is a sequence of 10-minute steps; at each step a method is
given the scene graph of the step before (every object's parent: fully observed) and the time,
and predicts every movable object's parent at the next step; for the following steps of a
12-step (2 h) lookahead its own previous output is fed back as the input. An object the method
says moves within the lookahead, and that does move, is *correct* if the predicted parent is
the one it moves to and *wrong* otherwise; a move it did not predict is *missed*; a predicted
move of an object that stays is a *false positive*. Its baselines (``baselines/baselines.py``)
are built from the training days as its ``run.py`` builds them.

**Ours** enters at its method seam (``step(batch)`` returning its ``details``), not by
subclassing: :class:`BeliefMethod` folds our own events into the project's belief,
:class:`~objsearch.agent.routine_belief.RoutineBelief` (``routine-belief``, the belief that knows
the hour; ``routine-habit`` and ``routine-hour``, the same fold forecasting the lookahead's steps
beyond the next from the slot's habit or the hour's histogram, :meth:`BeliefMethod.forecast`;
``belief``, the time-blind
:class:`~objsearch.agent.belief.PlaceBelief`, as a further row), with the constants of the
strategies that use it (k, h). What maps to what:

========================================  ==================================================
STOT                                      objsearch
========================================  ==================================================
a node that held a movable node in its    a place: id = its index, class = its class name
training days
a movable node (a row of its dynamic-     a target class d (its index and class name)
edges mask)
the parents its mask allows for d         the seed Rel₀(d, class) = 1 (no semantic prior:
                                          Visual Genome knows none of its node names)
an observed step (the input graph at      one episode: ``task_started`` with the step's
i = 0, the state at time − dt)            clock, a ``detection`` (support ``at``) of every
                                          movable object at its parent, ``task_ended``
the training days                         folded first, step by step, in file order
a prediction for time T                   the belief's prediction for a new episode at
                                          T's clock (``routine-belief``: its slot mix);
                                          ``ELSEWHERE`` dropped and the rest renormalised
========================================  ==================================================

The fed-back input of steps i > 0 is not an observation and is not folded: the belief forecasts
each lookahead time from what it has seen. Test days are folded as they are observed (the input
of each step), so the belief keeps learning during the test days, as it does on a robot; its
LastSeen and state-conditioned baselines also read every step's input.

Its files run unedited, with four bridges from outside them: a stand-in ``wandb`` (imported by
``evaluations.py``, never used); ``matplotlib.cm.get_cmap`` (removed in matplotlib 3.9) put back
as ``matplotlib.colormaps[name].resampled(lut)``; its evaluation module's numpy applies torch's
own ``bitwise_and/or/not`` to torch tensors (numpy's give ``uint8`` tensors under torch 2.x, which
its figure code cannot index with; its figures are drawn and dropped); and ``torch.load``
memoised by path while a household runs (:func:`loads_once`: its reader loads a day's whole file
for every sample, some 2,900 reads for each prior on household 3, about 0.17 s each).
"""

from __future__ import annotations

import contextlib
import copy
import hashlib
import importlib
import io
import math
import os
import random
import statistics
import sys
import time
import types
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from objsearch.agent.belief import ELSEWHERE, Place, PlaceBelief
from objsearch.agent.catalogue import (
    DayClock,
    Detected,
    PlanarPose,
    Record,
    SceneGraphSeeded,
    SeedValue,
    Support,
    TaskEnded,
    TaskStarted,
    encode,
)
from objsearch.agent.errors import ObjsearchError
from objsearch.agent.routine_belief import RoutineBelief
from objsearch.agent.strategies import BELIEF_HALF_LIFE_SCENES, BELIEF_PRIOR_STRENGTH
from objsearch.experiments.checkout import checkout_root
from objsearch.experiments.stot_hour import HourHistogram, hour_of
from objsearch.experiments.stot_pins import CODE, DATA

#: The commit of ``Maithili/SpatioTemporalObjectTracking`` the numbers are for (its last, 2023-01-22).
PINNED_COMMIT = "f4ce4141d3210ba2c18879c64450db6906e534ff"
SOURCE_ENV = "OBJSEARCH_STOT_SOURCE"
#: Its two folders of processed HOMER households (``data/HOMER`` is what its README's commands
#: name; ``data/householdsDifferent`` is the set ``sources/homer`` was extracted from).
DATASETS = ("HOMER", "householdsDifferent")
HOUSEHOLDS = (0, 1, 2, 3, 4)
#: Its baselines, as its ``run.py --baselines`` builds them, in its order.
THEIR_METHODS = (
    "LastSeen",
    "StaticSemantic",
    "LastSeenAndStaticSemantic",
    "Fremen",
    "FremenStateConditioned",
)
#: Ours: routine-belief, it with the slot's habit or the hour's histogram beyond one step, belief.
OUR_METHODS = ("routine-belief", "routine-habit", "routine-hour", "belief")
ROUTINE_METHODS = ("routine-belief", "routine-habit", "routine-hour")
#: A variant of ours is also paired with the method it changes.
PAIRED_WITH = {"routine-habit": "routine-belief", "routine-hour": "routine-habit"}
METHODS = (*OUR_METHODS, *THEIR_METHODS)
#: Its evaluation's lookahead (steps of dt) and its config's confidence threshold.
LOOKAHEAD = 12
CONFIDENCE = 0.0
_ORIGIN = PlanarPose(x=0.0, y=0.0, yaw=0.0)


def git_blob_id(data: bytes) -> str:
    """The id git gives a file's content (SHA-1 of ``blob <size>\\0`` + content)."""
    return hashlib.sha1(b"blob %d\x00" % len(data) + data, usedforsecurity=False).hexdigest()


@dataclass(frozen=True, slots=True)
class Checkout:
    root: Path
    #: Day files of the pinned commit that this checkout lacks (for the households asked for).
    missing: tuple[str, ...]


def household_dir(dataset: str, household: int) -> str:
    return f"data/{dataset}/household{household}/processed"


def verify_source(source: Path | str | None, dataset: str, households: Sequence[int]) -> Checkout:
    """The checkout, after checking every file used against the pinned blob ids."""
    root = checkout_root(
        source,
        SOURCE_ENV,
        command="bench stot",
        repo="Maithili/SpatioTemporalObjectTracking",
        commit=PINNED_COMMIT,
        doc="docs/results-stot.md",
    )
    changed: list[str] = []
    missing_code: list[str] = []
    for name, blob in CODE.items():
        path = root / name
        if not path.is_file():
            missing_code.append(name)
        elif git_blob_id(path.read_bytes()) != blob:
            changed.append(name)
    missing: list[str] = []
    for h in households:
        prefix = household_dir(dataset, h) + "/"
        pinned = {n: b for n, b in DATA.items() if n.startswith(prefix)}
        for name, blob in sorted(pinned.items()):
            path = root / name
            if not path.is_file():
                missing.append(name)
            elif git_blob_id(path.read_bytes()) != blob:
                changed.append(name)
        for split in ("train", "test"):
            folder = root / prefix / split
            if folder.is_dir():
                for f in sorted(folder.iterdir()):
                    rel = f"{prefix}{split}/{f.name}"
                    if rel not in pinned:
                        changed.append(f"{rel} (not in the pinned commit)")
    if missing_code or changed:
        raise ObjsearchError(
            f"--source {root} is not {PINNED_COMMIT} of SpatioTemporalObjectTracking: "
            + "; ".join(
                ([f"missing {', '.join(missing_code)}"] if missing_code else [])
                + ([f"differs: {', '.join(changed[:8])}"] if changed else [])
            )
        )
    for h in households:
        prefix = household_dir(dataset, h)
        for needed in ("common_data.json", "nonstatic_edges.pt", "home_graph.pt"):
            if f"{prefix}/{needed}" in missing:
                raise ObjsearchError(f"--source {root}: {prefix}/{needed} is missing")
    return Checkout(root, tuple(missing))


# -- its code ---------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Upstream:
    reader: Any
    evaluations: Any
    baselines: Any


def load_upstream(root: Path) -> Upstream:
    """Import its reader, evaluation and baselines from the checkout (bridged: see the module doc)."""
    os.environ.setdefault("MPLBACKEND", "Agg")
    import matplotlib
    from matplotlib import cm

    if not hasattr(cm, "get_cmap"):

        def get_cmap(name: str, lut: int | None = None) -> Any:
            cmap = matplotlib.colormaps[name]
            return cmap.resampled(lut) if lut is not None else cmap

        cm.get_cmap = get_cmap  # type: ignore[attr-defined]
    try:
        importlib.import_module("wandb")
    except ImportError:
        sys.modules.setdefault("wandb", types.ModuleType("wandb"))
    for path in (str(root / "helpers"), str(root)):
        if path not in sys.path:
            sys.path.insert(0, path)
    with contextlib.redirect_stdout(io.StringIO()):
        reader = importlib.import_module("reader")
        evaluations = importlib.import_module("evaluations")
        baselines = importlib.import_module("baselines.baselines")
    evaluations.__dict__["np"] = _bool_mask_numpy()
    return Upstream(reader, evaluations, baselines)


def _bool_mask_numpy() -> types.ModuleType:
    """numpy as its evaluation module sees it, except that ``bitwise_and/or/not`` of torch
    tensors stay torch tensors of their dtype (bool for its masks): with torch 2.x numpy hands
    back ``uint8`` tensors, which index as masks only with a deprecation warning and which its
    figure code's ``img[mask] *= -0.5`` refuses (RuntimeError, masked_fill_ needs bool)."""
    import numpy
    import torch

    proxy = types.ModuleType("numpy")
    proxy.__dict__.update(numpy.__dict__)

    def wrap(np_op: Callable[..., Any], torch_op: Callable[..., Any]) -> Callable[..., Any]:
        def op(*args: Any) -> Any:
            if all(isinstance(a, torch.Tensor) for a in args):
                return torch_op(*args)
            return np_op(*args)

        return op

    proxy.bitwise_and = wrap(numpy.bitwise_and, torch.bitwise_and)  # type: ignore[attr-defined]
    proxy.bitwise_or = wrap(numpy.bitwise_or, torch.bitwise_or)  # type: ignore[attr-defined]
    proxy.bitwise_not = wrap(numpy.bitwise_not, torch.bitwise_not)  # type: ignore[attr-defined]
    return proxy


@contextlib.contextmanager
def loads_once() -> Iterator[None]:
    """``torch.load`` memoised by path for the block (its code never changes what it loaded)."""
    import torch

    original = torch.load
    cache: dict[str, Any] = {}

    def load(f: Any, *args: Any, **kwargs: Any) -> Any:
        if not isinstance(f, str | os.PathLike) or args or kwargs:
            return original(f, *args, **kwargs)
        key = os.fspath(f)
        if key not in cache:
            cache[key] = original(f)
        return cache[key]

    torch.load = load
    try:
        yield
    finally:
        torch.load = original


# -- ours -------------------------------------------------------------------------------------


def clock_of(minutes: int) -> DayClock:
    """Its times are minutes from the first day's midnight (its ``time_external``)."""
    return DayClock(weekday=(minutes // 1440) % 7, minute=minutes % 1440)


@dataclass(frozen=True, slots=True)
class RecordEvent:
    """A record as the belief folds it, numbered."""

    seq: int
    type: str
    payload: Mapping[str, Any]
    task_id: str | None = None


def _sighting(target: str, static_id: str, static_class: str) -> Detected:
    return Detected(
        object_class=target,
        instance_id=target,
        mask_area=1.0,
        position=(0.0, 0.0, 0.0),
        accepted=True,
        support=Support(static_id=static_id, static_class=static_class, at=True),
        score=1.0,
        classes=(),
    )


@dataclass
class BeliefMethod:
    """Our belief at its method seam (see the module doc)."""

    model: str
    node_names: Sequence[str]
    #: Its dynamic-edges mask as nested lists: mask[i][j] = 1 when j may be i's parent.
    mask: Sequence[Sequence[float]]
    dt: int
    #: The nodes the belief is over: those that held a movable object in the training days
    #: (None: every node some movable node may be on).
    places: Sequence[int] | None = None
    belief: PlaceBelief = field(init=False)
    seq: int = 0
    episodes: int = 0
    targets: dict[int, str] = field(default_factory=dict)
    #: Its time (minutes) of the last real input folded, None before the first.
    observed_at: int | None = None
    hours: HourHistogram = field(default_factory=HourHistogram)
    _last_output: Any = None
    _cache: dict[tuple[int, ...], Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.model not in OUR_METHODS:
            raise ValueError(f"model {self.model!r}: one of {', '.join(OUR_METHODS)}")
        cls = PlaceBelief if self.model == "belief" else RoutineBelief
        self.belief = cls(
            prior_strength=BELIEF_PRIOR_STRENGTH, half_life_scenes=BELIEF_HALF_LIFE_SCENES
        )
        nodes = (
            sorted(set(self.places))
            if self.places is not None
            else [j for j in range(len(self.node_names)) if any(r[j] > 0 for r in self.mask)]
        )
        for j in nodes:
            self.belief.places[str(j)] = Place(str(j), self.node_names[j], "")
        values: list[SeedValue] = []
        for i, row in enumerate(self.mask):
            parents = {self.node_names[j] for j in nodes if row[j] > 0}
            if not parents:
                continue
            d = f"{i}:{self.node_names[i]}"
            self.targets[i] = d
            values.extend(SeedValue(dynamic=d, static=c, rel=1.0) for c in sorted(parents))
        self._add(SceneGraphSeeded(source="stot dynamic-edges mask", values=tuple(values)))

    def as_model(self, model: str) -> BeliefMethod:
        """A copy forecasting as ``model`` (the same belief class), folding on by itself."""
        if (model == "belief") != (self.model == "belief"):
            raise ValueError(f"{self.model} folds a different belief from {model}")
        twin = copy.deepcopy(self)
        twin.model = model
        twin._cache = {}
        if isinstance(twin.belief, RoutineBelief):
            # A slot-and-day-type belief's prior is a closure over its belief: re-link the copy's.
            for name, bucket in twin.belief.buckets.items():
                twin.belief._link(name, bucket)
        return twin

    def _add(self, record: Record) -> None:
        self.seq += 1
        self.belief.apply(RecordEvent(self.seq, record.TYPE, encode(record)))

    def observe(self, minutes: int, parents: Mapping[int, int]) -> None:
        """One step's graph (movable node -> parent node index) as one episode."""
        self._cache = {}
        self.episodes += 1
        self.observed_at = minutes
        seen = [(i, p) for i, p in sorted(parents.items()) if i in self.targets]
        self.hours.observe(minutes, {self.targets[i]: str(p) for i, p in seen})
        if not seen:
            return
        target = self.targets[seen[0][0]]
        self._add(
            TaskStarted(target=target, start="", pose=_ORIGIN, scene=None, clock=clock_of(minutes))
        )
        for i, p in seen:
            self._add(_sighting(self.targets[i], str(p), self.node_names[p]))
        self._add(TaskEnded(target=target, success=True, path_length=0.0))

    def forecast(self, d: str, minutes: int) -> dict[str, float]:
        """P(place) of d at that time: the belief's prediction for a new episode then (its mix is
        learned one episode, here one step, ahead); beyond the step after the last observation,
        ``routine-habit``'s slot habit (:meth:`RoutineBelief.habit_at`), ``routine-hour``'s
        hour histogram (:class:`~objsearch.experiments.stot_hour.HourHistogram`)."""
        b = self.belief
        if not isinstance(b, RoutineBelief):
            return b._base(d)
        if not b.knows_hours or not self._beyond_next_step(minutes):
            return b._base_at(d, clock_of(minutes) if b.knows_hours else None)
        if self.model == "routine-hour":
            return self.hours.forecast(d, minutes)
        return b.habit_at(d, clock_of(minutes))

    def _beyond_next_step(self, minutes: int) -> bool:
        seen = self.observed_at
        return self.model != "routine-belief" and seen is not None and minutes - seen > self.dt

    def observe_graph(self, minutes: int, edges: Any) -> None:
        """A graph given as its edges tensor [nodes, nodes] (row i: i's parent, one-hot)."""
        parents: dict[int, int] = {}
        for i in self.targets:
            row = edges[i]
            if float(row.sum()) > 0:
                parents[i] = int(row.argmax())
        self.observe(minutes, parents)

    def step(self, batch: Mapping[str, Any]) -> tuple[None, dict[str, Any], None]:
        """Its ``Baseline.step`` contract: the output graph's probabilities and argmax."""
        import torch

        edges = batch["edges"]
        t = int(batch["time"].reshape(-1)[0])
        if edges is not self._last_output:
            # A real input (i = 0): the graph at the step before t. Fed-back outputs are ours.
            self.observe_graph(t - self.dt, edges[0])
        dynamic = batch["dynamic_edges_mask"]
        key = self._slot_key(t)
        probs = self._cache.get(key)
        if probs is None:
            probs = self._cache[key] = self._probabilities(t, dynamic[0])
        result = edges.clone().to(torch.float32)
        rows = list(self.targets)
        result[0, rows, :] = probs[rows, :]
        result = result / (result.sum(dim=-1, keepdim=True) + 1e-8)
        self._last_output = result
        nodes = batch["nodes"].argmax(-1)
        evaluate_node = dynamic.sum(-1) > 0
        details = {
            "input": {"class": nodes, "location": edges.squeeze(-1).argmax(-1)},
            "output_probs": {"location": result},
            "gt": {"class": nodes, "location": batch["y_edges"].squeeze(-1).argmax(-1)},
            "losses": {"location": None},
            "output": {"class": nodes, "location": result.squeeze(-1).argmax(-1)},
            "evaluate_node": evaluate_node,
        }
        return None, details, None

    def _slot_key(self, minutes: int) -> tuple[int, ...]:
        """Times whose forecasts are equal: slot, day type, beyond one step, routine-hour's hour."""
        if self.model == "belief":
            return (0,)
        from objsearch.agent.routine_belief import buckets_of

        slot, slot_day = buckets_of(clock_of(minutes))
        hour = hour_of(minutes) if self.model == "routine-hour" else -1
        return (hash(slot), hash(slot_day), int(self._beyond_next_step(minutes)), hour)

    def _probabilities(self, minutes: int, dynamic: Any) -> Any:
        import torch

        n = len(self.node_names)
        out = torch.zeros((n, n), dtype=torch.float32)
        for i, d in self.targets.items():
            dist = self.forecast(d, minutes)
            for place, p in dist.items():
                if place == ELSEWHERE or p <= 0:
                    continue
                j = int(place)
                if dynamic[i, j] > 0:
                    out[i, j] = p
            if float(out[i].sum()) <= 0:
                out[i] = dynamic[i].to(torch.float32)
        return out


# -- the run ----------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Counts:
    """Its counts for one test day at one lookahead step (``results[conf]`` of its evaluation)."""

    correct: int
    wrong: int
    missed: int
    fp: int
    tn: int

    @property
    def moved(self) -> int:
        return self.correct + self.wrong + self.missed


@dataclass
class DayResult:
    household: int
    day: str
    method: str
    #: Counts per lookahead step (index 0: the next step; 11: within 2 h).
    by_step: list[Counts]


class _OneDay:
    """Its test split narrowed to one day, for its evaluation loop (per-day counts)."""

    def __init__(self, split: Any, idx: int) -> None:
        self.split = split
        self.idx = idx
        self.collate_fn = split.collate_fn

    def __iter__(self) -> Iterator[Any]:
        yield self.split[self.idx]


def _present(root: Path, dataset: str, household: int, split: str) -> int:
    folder = root / household_dir(dataset, household) / split
    return sum(1 for f in folder.iterdir() if f.is_file()) if folder.is_dir() else 0


def run_household(
    checkout: Checkout,
    dataset: str,
    household: int,
    methods: Sequence[str],
    *,
    max_test_days: int | None = None,
    log: Callable[[str], None] = lambda _: None,
) -> list[DayResult]:
    """Every method on one household's test days, scored by its evaluation, per day."""
    with loads_once():
        return _run_household(
            checkout, dataset, household, methods, max_test_days=max_test_days, log=log
        )


def _run_household(
    checkout: Checkout,
    dataset: str,
    household: int,
    methods: Sequence[str],
    *,
    max_test_days: int | None,
    log: Callable[[str], None],
) -> list[DayResult]:
    import matplotlib.pyplot as plt

    up = load_upstream(checkout.root)
    root = checkout.root
    n_train = _present(root, dataset, household, "train")
    n_test = _present(root, dataset, household, "test")
    if n_train == 0 or n_test == 0:
        raise ObjsearchError(
            f"household {household} of {dataset}: {n_train} training and {n_test} test days "
            "in the checkout; need at least one of each"
        )
    random.seed(23435)  # its run.py's seeds (nothing below draws)
    with contextlib.redirect_stdout(io.StringIO()):
        data = up.reader.RoutinesDataset(
            data_path=str(root / household_dir(dataset, household)),
            batch_size=1,
            max_routines=(n_train, n_test),
        )
    days = data.test_routines
    n_days = len(days) if max_test_days is None else min(len(days), max_test_days)
    built: dict[str, Any] = _their_methods(
        up, data, [m for m in methods if m in THEIR_METHODS], household, n_train, log
    )
    for m in methods:
        if m in OUR_METHODS:
            twin = next((built[o] for o in built if o in ROUTINE_METHODS), None)
            if m in ROUTINE_METHODS and twin is not None:
                built[m] = twin.as_model(m)
            else:
                built[m] = _our_method(m, data, household, log)
    results: list[DayResult] = []
    for m in methods:
        t0 = time.monotonic()
        for idx in range(n_days):
            with contextlib.redirect_stdout(io.StringIO()):
                info, _, _ = up.evaluations.evaluate_all_breakdowns(
                    built[m],
                    _OneDay(days, idx),
                    lookahead_steps=LOOKAHEAD,
                    node_names=data.common_data["node_classes"],
                    confidences=[CONFIDENCE],
                    learned_model=False,
                )
            plt.close("all")
            r = info[CONFIDENCE]
            by_step = [
                Counts(
                    r["moved"]["correct"][k],
                    r["moved"]["wrong"][k],
                    r["moved"]["missed"][k],
                    r["unmoved"]["fp"][k],
                    r["unmoved"]["tn"][k],
                )
                for k in range(LOOKAHEAD)
            ]
            results.append(DayResult(household, days.files[idx], m, by_step))
        log(f"household {household}: {m} on {n_days} test days in {time.monotonic() - t0:.0f} s")
    return results


def _their_methods(
    up: Any,
    data: Any,
    their: Sequence[str],
    household: int,
    n_train: int,
    log: Callable[[str], None],
) -> dict[str, Any]:
    """Its baselines, built as its run.py builds them (their priors from the training days)."""
    if not their:
        return {}
    t0 = time.monotonic()
    with contextlib.redirect_stdout(io.StringIO()):
        cf = data.get_cooccurence_frequency()
        spec = data.get_spectral_components(periods_mins=[float("inf"), 60 * 24, 60 * 24 / 2])
    bl = up.baselines
    make = {
        "LastSeen": lambda: bl.LastSeen(),
        "StaticSemantic": lambda: bl.StaticSemantic(cf),
        "LastSeenAndStaticSemantic": lambda: bl.LastSeenAndStaticSemantic(cf),
        "Fremen": lambda: bl.Fremen(spec),
        "FremenStateConditioned": lambda: bl.FremenStateConditioned(spec, data.params["dt"]),
    }
    built = {m: make[m]() for m in their}
    log(
        f"household {household}: its priors from {n_train} training days in {time.monotonic() - t0:.0f} s"
    )
    return built


def _our_method(m: str, data: Any, household: int, log: Callable[[str], None]) -> BeliefMethod:
    """Our belief over the nodes that held an object in the training days, folded from each step."""
    t0 = time.monotonic()
    mask = data.active_edges.tolist()
    train = [data.train_routines[r][0] for r in range(len(data.train_routines))]
    held = sorted(
        {
            int(p)
            for samples in train
            for s in samples
            for p in s[0].argmax(-1)[(s[0].sum(-1) > 0) & (data.active_edges.sum(-1) > 0)]
        }
    )
    ours = BeliefMethod(m, list(data.node_classes), mask, int(data.params["dt"]), places=held)
    for samples in train:
        for s in samples:
            ours.observe_graph(int(s[6]) - ours.dt, s[0])
        ours.observe_graph(int(samples[-1][6]), samples[-1][3])
    log(
        f"household {household}: {m} folded {ours.episodes} training steps in {time.monotonic() - t0:.0f} s"
    )
    return ours


# -- the summary ------------------------------------------------------------------------------


def scores(c: Counts) -> dict[str, float]:
    """Shares of the moved objects (its correct / wrong / missed), precision and F1 of the
    predicted moves."""
    moved = c.moved
    predicted = c.correct + c.wrong + c.fp
    recall = c.correct / moved if moved else math.nan
    precision = c.correct / predicted if predicted else math.nan
    f1 = 2 * c.correct / (moved + predicted) if moved + predicted else math.nan  # = 2PR/(P+R)
    return {
        "correct": recall,
        "wrong": c.wrong / moved if moved else math.nan,
        "missed": c.missed / moved if moved else math.nan,
        "fp_per_moved": c.fp / moved if moved else math.nan,
        "precision": precision,
        "f1": f1,
    }


def total(results: Sequence[DayResult], method: str, step: int) -> Counts:
    rows = [r.by_step[step] for r in results if r.method == method]
    return Counts(
        sum(c.correct for c in rows),
        sum(c.wrong for c in rows),
        sum(c.missed for c in rows),
        sum(c.fp for c in rows),
        sum(c.tn for c in rows),
    )


def paired_ci(
    results: Sequence[DayResult],
    a: str,
    b: str,
    step: int,
    metric: str,
    *,
    resamples: int = 2000,
    seed: int = 0,
) -> tuple[float, float, float, int]:
    """a − b on ``metric`` of the pooled counts, with a 95 % bootstrap CI over test days
    (resampled as pairs: the same days for both); returns (diff, lo, hi, days)."""
    keys = sorted(
        {(r.household, r.day) for r in results if r.method == a}
        & {(r.household, r.day) for r in results if r.method == b}
    )
    by = {(r.household, r.day, r.method): r.by_step[step] for r in results}

    def pooled(sample: Sequence[tuple[int, str]], m: str) -> float:
        cs = [by[(h, d, m)] for h, d in sample]
        c = Counts(
            *(sum(getattr(x, f) for x in cs) for f in ("correct", "wrong", "missed", "fp", "tn"))
        )
        return scores(c)[metric]

    diff = pooled(keys, a) - pooled(keys, b)
    rng = random.Random(seed)
    draws = []
    for _ in range(resamples):
        sample = [keys[rng.randrange(len(keys))] for _ in keys]
        v = pooled(sample, a) - pooled(sample, b)
        if not math.isnan(v):
            draws.append(v)
    draws.sort()
    if not draws:
        return diff, math.nan, math.nan, len(keys)
    lo = draws[int(0.025 * (len(draws) - 1))]
    hi = draws[math.ceil(0.975 * (len(draws) - 1))]
    return diff, lo, hi, len(keys)


def summary(results: Sequence[DayResult], checkout_missing: Sequence[str]) -> dict[str, Any]:
    methods = list(dict.fromkeys(r.method for r in results))
    table = {
        m: {
            str(step + 1): {**scores(total(results, m, step)), **vars_of(total(results, m, step))}
            for step in (0, LOOKAHEAD - 1)
        }
        for m in methods
    }
    comparisons = {}
    for ours in (m for m in methods if m in OUR_METHODS):
        others = [m for m in methods if m in THEIR_METHODS]
        if PAIRED_WITH.get(ours) in methods:
            others.insert(0, PAIRED_WITH[ours])
        for theirs in others:
            for step in (0, LOOKAHEAD - 1):
                for metric in ("f1", "correct", "wrong"):
                    d, lo, hi, n = paired_ci(results, ours, theirs, step, metric)
                    comparisons[f"{ours} - {theirs} {metric} @{step + 1}"] = {
                        "diff": d,
                        "lo": lo,
                        "hi": hi,
                        "days": n,
                    }
    days = sorted({(r.household, r.day) for r in results})
    return {
        "commit": PINNED_COMMIT,
        "days": len(days),
        "households": sorted({h for h, _ in days}),
        "missing_day_files": list(checkout_missing),
        "table": table,
        "paired": comparisons,
        "per_day_f1_12": {
            m: [scores(r.by_step[LOOKAHEAD - 1])["f1"] for r in results if r.method == m]
            for m in methods
        },
    }


def vars_of(c: Counts) -> dict[str, int]:
    return {"n_correct": c.correct, "n_wrong": c.wrong, "n_missed": c.missed, "n_fp": c.fp}


def format_text(s: Mapping[str, Any]) -> str:
    lines = [
        f"SpatioTemporalObjectTracking {s['commit'][:12]}: households {s['households']}, "
        f"{s['days']} test days; {len(s['missing_day_files'])} day files of the pinned commit "
        "absent from the checkout",
        "method                     @steps  correct  wrong  missed  fp/moved  precision  F1",
    ]
    for m, by in s["table"].items():
        for step, v in by.items():
            lines.append(
                f"{m:<26} {step:>6}  {v['correct']:7.3f}  {v['wrong']:5.3f}  {v['missed']:6.3f}  "
                f"{v['fp_per_moved']:8.3f}  {v['precision']:9.3f}  {v['f1']:5.3f}"
            )
    lines.append("paired over test days (95 % bootstrap CI, 2000 resamples, seed 0):")
    for k, v in s["paired"].items():
        lines.append(f"  {k}: {v['diff']:+.3f} [{v['lo']:+.3f}, {v['hi']:+.3f}] ({v['days']} days)")
    return "\n".join(lines)


def mean_or_nan(xs: Sequence[float]) -> float:
    xs = [x for x in xs if not math.isnan(x)]
    return statistics.fmean(xs) if xs else math.nan
