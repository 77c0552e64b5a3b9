"""The simulated robot's detector: the search camera's perfect detections passed through a model of
a real detector (:class:`~objsearch.agent.detector_model.PerceptionModel`): misses, false
positives on surfaces, confusions between similar classes and scores.

Its draws come from generators seeded from the run's seed (never a global one), so a run replays
exactly: under the model's ``draws`` = ``view`` one per view, keyed by the view's index in the run
(the runs before 2026-12-07); under ``place`` one per object seen and one per view's false positives,
keyed by the search (:meth:`NoisyDetector.begin`), the viewpoint cell it is seen from and how often
it was seen from there in the search, so strategies run on the same schedule and seed meet the
same luck at the same place (common random numbers; each draw is still uniform).
docs/perception.md gives the numbers.
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Collection, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from objsearch.agent.detector_model import SIMILAR, PerceptionModel
from objsearch.agent.geometry import Pose
from objsearch.agent.home import Home
from objsearch.agent.world import Detection
from objsearch.sim.perception import Camera
from objsearch.sim.placements import Placement

if TYPE_CHECKING:
    from objsearch.agent.strategies import RunSpec

#: The grid a ``place`` draw's viewpoint is read on (m): the navigation map's 0.25 m viewpoints.
DRAW_CELL_M = 0.25
#: Headings a ``place`` draw's false positives are keyed by: eight 45° sectors.
DRAW_HEADINGS = 8
#: A ``place`` draw's stream for a view's false positives (an object's is its id's CRC).
_FALSE_STREAM = 1 << 32


def _natural(v: int) -> int:
    """An integer as a non-negative one (a generator's seed words must be), one to one."""
    return 2 * v if v >= 0 else -2 * v - 1


#: Mask area of a false positive: log-uniform over this range (px), from just under the smallest
#: class threshold (100 px) to the top of COCO's medium bin.
FALSE_MASK_PX = (64.0, 96.0 * 96.0)
#: Instance ids of false positives start with this (no placement has one).
FALSE_PREFIX = "false:"
#: The unoccluded camera: a detection's visible fraction is its mask over this one's box area.
_UNOCCLUDED = Camera()
#: A false positive drawn this close (m) to the box of a placed object of its own class is not
#: reported: a box there overlaps that object, so it is no false positive but a duplicate of its
#: detection, which the detector's per-class non-maximum suppression removes (or, when the object
#: itself was missed, a detection of it). Drawn there before, it was scored a false "found"
#: though the object lay where the robot said (harsh, paper habit-0 scene 4: 2.7 cm from the
#: Apple).
DUPLICATE_M = 0.05


class NoisyDetector:
    """Turns one view's perfect detections into what the modelled detector reports."""

    def __init__(self, model: PerceptionModel, seed: int, movable: Collection[str]) -> None:
        self.model = model
        self.seed = seed
        self.movable = tuple(sorted(movable))
        self.views = 0
        #: ``place`` draws: the running search's key words, and each (stream, cell[, heading])'s
        #: looks so far in it.
        self._search: tuple[int, ...] = ()
        self._looks: dict[tuple[int, ...], int] = {}
        #: (score, true) of every detection reported: true when the object is there with the
        #: reported class (what :func:`reliability` measures).
        self.scored: list[tuple[float, bool]] = []

    def begin(self, *key: object) -> None:
        """A search starts (its scene, target and start, say): under ``place`` draws its looks'
        draws are keyed by it and counted afresh; under ``view`` draws nothing changes."""
        self._search = tuple(zlib.crc32(repr(k).encode()) for k in key)
        self._looks = {}

    def _place_rng(self, stream: int, *where: int) -> np.random.Generator:
        """The generator of the next look at ``stream`` (an object, or the false positives) from
        ``where`` in this search."""
        key = (stream, *where)
        k = self._looks.get(key, 0)
        self._looks[key] = k + 1
        return np.random.default_rng([self.seed, *self._search, *key, k])

    def observe(
        self,
        home: Home,
        room: str,
        pose: Pose,
        placed: Sequence[Placement],
        seen: Sequence[Detection],
    ) -> tuple[Detection, ...]:
        """The detector's report of one view: ``seen`` are the camera's detections (every object
        in view), ``placed`` the placements of the room (for visible fractions)."""
        rng = np.random.default_rng([self.seed, self.views])
        self.views += 1
        model = self.model
        by_place = model.draws == "place"
        cell = (_natural(round(pose.x / DRAW_CELL_M)), _natural(round(pose.y / DRAW_CELL_M)))
        boxes = {p.instance_id: p.box for p in placed}
        out: list[Detection] = []
        for det in seen:
            box = boxes.get(det.instance_id)
            full = _UNOCCLUDED.mask_area(pose, box) if box is not None else det.mask_area
            visible = min(1.0, det.mask_area / full) if full > 0 else 1.0
            # Every draw is made whatever the outcome, so one view's draws never depend on another.
            draw = self._place_rng(zlib.crc32(det.instance_id.encode()), *cell) if by_place else rng
            detected, confused, pick, u = draw.random(4)
            if detected >= model.recall(det.mask_area, visible):
                continue
            cls, real = det.object_class, True
            similar = SIMILAR.get(cls, ())
            if similar and confused < model.confusion:
                cls, real = similar[int(pick * len(similar))], False
                if cls not in self.movable:
                    continue  # a class the robot's vocabulary drops: a miss
            score = self._score(u, real)
            self.scored.append((score, real))
            out.append(
                Detection(
                    cls,
                    det.instance_id,
                    det.mask_area,
                    det.position,
                    score,
                    self._distribution(cls, score),
                )
            )
        if by_place:
            heading = round(pose.yaw / (2 * math.pi / DRAW_HEADINGS)) % DRAW_HEADINGS
            rng = self._place_rng(_FALSE_STREAM, *cell, heading)
        out.extend(self._false_positives(rng, home, room, pose, placed))
        return tuple(out)

    def _score(self, u: float, real: bool) -> float:
        a, b = self.model.tp_score if real else self.model.fp_score
        # The Beta quantile of u by bisection on its CDF (scipy is not a dependency).
        q = _beta_quantile(u, a, b)
        t = self.model.threshold
        return round(t + (1.0 - t) * q, 4)

    def _distribution(self, cls: str, score: float) -> tuple[tuple[str, float], ...]:
        """The reported class at its score, the rest shared by its similar classes the
        vocabulary knows (what a softmax over them leaves)."""
        others = [c for c in SIMILAR.get(cls, ()) if c in self.movable]
        rest = round((1.0 - score) / (len(others) + 1), 4)
        return ((cls, score), *((c, rest) for c in others))

    def _false_positives(
        self,
        rng: np.random.Generator,
        home: Home,
        room: str,
        pose: Pose,
        placed: Sequence[Placement] = (),
    ) -> list[Detection]:
        n = int(rng.poisson(self.model.fp_per_image)) if self.model.fp_per_image > 0 else 0
        if n == 0 or not self.movable:
            return []
        surfaces = [s for s in home.room(room).statics if _UNOCCLUDED.in_view(pose, s.box)]
        out: list[Detection] = []
        for k in range(n):
            which, cls_pick, fx, fy, size, u = rng.random(6)
            if not surfaces:
                break
            s = surfaces[int(which * len(surfaces))]
            cls = self.movable[int(cls_pick * len(self.movable))]
            (cx, cy, _), (sx, sy, _) = s.box.center, s.box.size
            position = (cx + (fx - 0.5) * sx, cy + (fy - 0.5) * sy, s.box.top)
            if any(p.cls == cls and p.box.distance_to(position) <= DUPLICATE_M for p in placed):
                continue  # on an object of its class: a duplicate, not a false positive
            low, high = FALSE_MASK_PX
            mask = math.exp(math.log(low) + size * (math.log(high) - math.log(low)))
            score = self._score(u, False)
            self.scored.append((score, False))
            out.append(
                Detection(
                    cls,
                    f"{FALSE_PREFIX}{self.views - 1}:{k}",
                    round(mask, 2),
                    position,
                    score,
                    self._distribution(cls, score),
                )
            )
        return out


@dataclass(frozen=True, slots=True)
class Reliability:
    """How well a detector's scores say how often it is right (Küppers et al. 2020)."""

    detections: int
    #: Share of detections that are true.
    precision: float
    #: D-ECE: per score bin, |precision − mean score|, weighted by the bin's share.
    d_ece: float
    #: Mean squared difference between score and truth (1 true, 0 false).
    brier: float


def reliability(scored: Sequence[tuple[float, bool]], bins: int = 10) -> Reliability:
    """D-ECE and Brier of (score, true) pairs, scores binned evenly over [0, 1] (the D-ECE of
    Küppers et al. 2020 with only the confidence dimension, as Munir et al. 2023 report it)."""
    if not scored:
        raise ValueError("no detections to measure")
    n = len(scored)
    per: dict[int, list[tuple[float, bool]]] = {}
    for score, true in scored:
        per.setdefault(min(int(score * bins), bins - 1), []).append((score, true))
    d_ece = math.fsum(
        len(b) / n * abs(math.fsum(t for _, t in b) / len(b) - math.fsum(s for s, _ in b) / len(b))
        for b in per.values()
    )
    brier = math.fsum((s - t) ** 2 for s, t in scored) / n
    return Reliability(n, sum(t for _, t in scored) / n, d_ece, brier)


def _beta_quantile(u: float, a: float, b: float) -> float:
    """x with I_x(a, b) = u, by bisection on the regularized incomplete Beta (midpoint sums)."""
    lo, hi = 0.0, 1.0
    for _ in range(40):
        mid = (lo + hi) / 2
        if _beta_cdf(mid, a, b) < u:
            lo = mid
        else:
            hi = mid
    return (lo + hi) / 2


def _beta_cdf(x: float, a: float, b: float) -> float:
    if x <= 0.0:
        return 0.0
    if x >= 1.0:
        return 1.0
    # Continued fraction (Numerical Recipes' betacf), converging fast for the shapes used here.
    ln_front = (
        math.lgamma(a + b) - math.lgamma(a) - math.lgamma(b) + a * math.log(x) + b * math.log1p(-x)
    )
    if x < (a + 1.0) / (a + b + 2.0):
        return math.exp(ln_front) * _betacf(x, a, b) / a
    return 1.0 - math.exp(ln_front) * _betacf(1.0 - x, b, a) / b


def _betacf(x: float, a: float, b: float) -> float:
    tiny = 1e-300
    qab, qap, qam = a + b, a + 1.0, a - 1.0
    c, d = 1.0, 1.0 - qab * x / qap
    d = 1.0 / (d if abs(d) > tiny else tiny)
    h = d
    for m in range(1, 200):
        m2 = 2 * m
        aa = m * (b - m) * x / ((qam + m2) * (a + m2))
        d = 1.0 + aa * d
        d = 1.0 / (d if abs(d) > tiny else tiny)
        c = 1.0 + aa / c
        c = c if abs(c) > tiny else tiny
        h *= d * c
        aa = -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2))
        d = 1.0 + aa * d
        d = 1.0 / (d if abs(d) > tiny else tiny)
        c = 1.0 + aa / c
        c = c if abs(c) > tiny else tiny
        delta = d * c
        h *= delta
        if abs(delta - 1.0) < 1e-12:
            break
    return h


def perception_model(spec: RunSpec) -> PerceptionModel:
    """The perception model a run spec records (``params.perception``; none: perfect)."""
    doc = spec.params.get("perception")
    return PerceptionModel.from_params(doc if isinstance(doc, dict) else None)


def with_perception(
    spec: RunSpec, model: PerceptionModel | None = None, *, movable: Collection[str] = ()
) -> tuple[RunSpec, NoisyDetector | None]:
    """The spec with ``model`` recorded (``params.perception``; given none, the one it already
    records), and the detector that samples it for the run, None for a perfect one. A perfect
    model is not recorded, so a run without noise writes the log it always did."""
    chosen = model if model is not None else perception_model(spec)
    params = {k: v for k, v in spec.params.items() if k != "perception"}
    if chosen.perfect:
        return spec.with_changes(params=params), None
    spec = spec.with_changes(params={**params, "perception": chosen.params()})
    return spec, NoisyDetector(chosen, spec.seed, movable)
