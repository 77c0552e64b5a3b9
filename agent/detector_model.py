"""A model of a real object detector, shared by the simulator that samples from it
(:mod:`objsearch.sim.detector_model`) and the agent that reasons with it: a detection is evidence
with a likelihood, not truth.

Per view, an object in view is reported with probability :meth:`PerceptionModel.recall` (its COCO
size bin by mask area, its visible fraction); ``fp_per_image`` false positives of the vocabulary's
movable classes are reported on surfaces; a reported object carries a similar class with
probability ``confusion`` (:data:`SIMILAR`); scores lie above the detector's operating threshold,
true detections' drawn from ``tp_score``, false ones' from ``fp_score`` (Beta shapes over the
span above the threshold). docs/perception.md gives every number with its source.

``perfect`` is the simulator as it was before: every object in view reported, score 1, nothing
false; a run records no perception model then, so its log is byte for byte what it was.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, fields, replace
from functools import cache
from pathlib import Path
from typing import Any, Final

from objsearch.agent.categories import read_json
from objsearch.agent.datapaths import data_key
from objsearch.agent.errors import DataFileError, ObjsearchError

#: COCO's object size bins (mask or box area, pixels): small below 32², large above 96².
SMALL_PX: Final = 32.0 * 32.0
LARGE_PX: Final = 96.0 * 96.0
#: Mask R-CNN R-50-FPN 1x (Detectron), box AR (100 detections, IoU .50:.95) on COCO val2017,
#: small / medium / large: 32.3 / 54.8 / 64.8 (Detectron.pytorch BENCHMARK.md, Detectron row).
MASK_RCNN_RECALL: Final = (0.323, 0.548, 0.648)
#: D-ECE of a real detector's scores: Deformable DETR (R-50) on MS-COCO, 12.8 % (Munir et al.,
#: CVPR 2023, "Bridging Precision and Confidence", the baseline row of their repository's table).
#: The realistic preset's score shapes reproduce it (tests/sim/test_detector_model.py measures it).
PUBLISHED_D_ECE: Final = 0.128
#: An object less than this visible counts as occluded (recall times ``occluded_recall``).
OCCLUDED_BELOW: Final = 0.5
#: Classes a detector takes a class for: COCO's supercategories (the "Sim" errors of COCO's
#: analyze(), after Hoiem et al. 2012). A class outside the vocabulary is dropped by the robot's
#: vocabulary, so such a confusion is a miss (an Apple reported as an orange).
SIMILAR: Final[Mapping[str, tuple[str, ...]]] = {
    "Apple": ("Orange", "Tomato"),
    "Bowl": ("Cup",),
    "Cup": ("Bowl",),
    "Laptop": ("Phone",),
    "Phone": ("Laptop", "RemoteControl"),
}
PRESETS: Final = ("perfect", "realistic", "harsh")
#: How a confirming look's report or miss counts against a sighting (docs/perception.md, "The
#: consistent confirmation model"): ``score`` (the committed rule) takes a report by its score's
#: likelihood ratio alone and a miss by the detector's miss probability; ``consistent`` takes
#: both against the chance ``fp_recurrence`` that a false report recurs at the same spot.
CONFIRMATIONS: Final = ("score", "consistent")
#: Each preset's confirmation model. ``realistic`` confirms by ``consistent`` (q = 0.1): chosen by
#: the rule of docs/protocol-perception.md (amendment of 09:22 UTC, 2026-12-07) on evaluation A,
#: where it shortened the first search after day 10 to 0.836 [0.729, 0.943] × ``score``'s at
#: success 99.74 %, false found 0.12 % (docs/results-perception.md). ``harsh`` keeps ``score``:
#: on the development homes q = 0.1 under ``harsh`` cost false founds (docs/perception.md).
PRESET_CONFIRMATION: Final = {"perfect": "score", "realistic": "consistent", "harsh": "score"}
#: ``harsh``'s confirmation threshold: the lowest of 0.95, 0.99, 0.999 at which the default's false
#: founds on evaluation A are at most 0.2 % (the rule of docs/protocol-perception.md, amendment of
#: 09:22 UTC, 2026-12-07): 0.67 % at 0.95, 0.23 % at 0.99, 0.10 % at 0.999, at 22 % more path
#: than 0.99 and success 98.92 % (docs/results-perception.md). ``realistic`` keeps 0.99.
HARSH_ACCEPT_POSTERIOR: Final = 0.999
#: How the simulated detector's random draws are keyed (sim/detector_model.py; docs/perception.md,
#: "Draws keyed by place"): ``view``, by the view's index in the run (every run before
#: 2026-12-07, and any run spec that names none), or ``place``, by the search and what is seen
#: from where (the object, the viewpoint it is seen from, and how often it was looked at from
#: there in this search), so that strategies run on the same schedule and seed meet the same
#: luck at the same place (common random numbers). Each draw is uniform either way: a
#: strategy's outcomes have the same distribution, only the pairing between strategies differs.
DRAWS: Final = ("view", "place")
#: What the agent's memory of the day (``Today``, agent/belief.py) makes of a report that is no
#: sighting (its score or its mask too low to take): ``misses``, a miss like a view that reported
#: nothing (every run before 2026-12-07's second amendment, and any run spec that names none), or
#: ``evidence``, its likelihood ratio (:meth:`PerceptionModel.look_ratio`): a report at a place
#: says the class is likelier there, not less likely (docs/perception.md, "Reports that are no
#: sighting").
REPORTS: Final = ("misses", "evidence")
#: What the searcher does after an inspection of a stop that took no sighting of the target
#: (agent/policy.py, ``SearchAgent._relook``): ``off``, it moves on to the next stop of its
#: plan and comes back only in a revisit pass after the whole pass (``perfect``, every run before
#: this option, and any run spec that names none), or ``likeliest`` (the modelled presets'
#: default since the amendment of 21:12 UTC), it inspects the stop again from
#: where it stands (no metres: the detector's misses are independent from look to look) while
#: the stop's value times its per-look miss to the power of its inspections in this pass is
#: still above every stop the pass has yet to visit.
RELOOKS: Final = ("off", "likeliest")
#: What the searcher takes to be left of a stop's chance after ``n`` inspections of it that
#: missed (agent/policy.py, ``SearchAgent.stop_miss_after``): ``pooled``, the stop's per-look
#: miss averaged over its statics, to the n-th power (``perfect``, every run before this option,
#: and any run spec that names none), or ``per-static`` (the modelled presets' default since the
#: amendment of 23:03 UTC), each static's own per-look miss to the n-th power,
#: averaged: the chance n looks all miss when the target is at one of the stop's statics, equally
#: likely. The two agree for n = 1; beyond, the mean of powers is the larger (Jensen): a static
#: the camera sees badly keeps its chance, where the pooled miss lets repeated looks drain it.
STOP_MISSES: Final = ("pooled", "per-static")
#: The search camera's focal length (px): 640×480 at a 90° horizontal field of view.
FOCAL_PX: Final = 320.0
#: Nearer than this the mask estimate is capped (the camera then sees the whole object anyway).
NEAREST_M: Final = 0.5
#: The median AI2-THOR asset box of each movable class (x, y, z in metres), from the data
#: build's placement statistics: what the robot may know of a class's size in advance.
SIZES_FILE: Final = "priors/ai2thor_placements.json"
#: Options that override one parameter of a preset (``--recall-scale`` …), with their bounds.
OVERRIDES: Final[Mapping[str, tuple[float, float]]] = {
    "recall_scale": (0.0, 1.0),
    "fp_per_image": (0.0, 20.0),
    "confusion": (0.0, 1.0),
    "occluded_recall": (0.0, 1.0),
    "accept_posterior": (0.5, 1.0),
    "fp_recurrence": (0.01, 0.99),
}


@dataclass(frozen=True, slots=True)
class PerceptionModel:
    """The detector's statistics; ``preset`` names where they came from."""

    preset: str = "perfect"
    recall_small: float = 1.0
    recall_medium: float = 1.0
    recall_large: float = 1.0
    #: Multiplies every recall (``harsh``: 0.5).
    recall_scale: float = 1.0
    #: Recall factor of an object less than ``OCCLUDED_BELOW`` visible.
    occluded_recall: float = 1.0
    #: False positives of the vocabulary's movable classes per view (Poisson mean).
    fp_per_image: float = 0.0
    #: Probability that a reported object carries a similar class (:data:`SIMILAR`).
    confusion: float = 0.0
    #: The operating threshold: no score below it is reported.
    threshold: float = 0.5
    #: Beta shapes of a true / a false detection's score above the threshold: chosen so that
    #: the scores' D-ECE on simulated searches is a real detector's (docs/perception.md,
    #: :data:`PUBLISHED_D_ECE`): true scores rise linearly to 1, false ones crowd the threshold.
    tp_score: tuple[float, float] = (2.0, 1.0)
    fp_score: tuple[float, float] = (1.5, 4.0)
    #: Posterior P(real) at which the agent takes a sighting as confirmed.
    accept_posterior: float = 0.99
    #: The confirmation model (:data:`CONFIRMATIONS`) and, for ``consistent``, q: P(a false
    #: report recurs at the same spot on a look again). A choice, not a published figure.
    confirmation: str = "score"
    fp_recurrence: float = 0.1
    #: How the simulator keys this detector's random draws (:data:`DRAWS`); the agent never
    #: reads it.
    draws: str = "view"
    #: What a report that is no sighting tells the agent's memory of the day (:data:`REPORTS`).
    reports: str = "misses"
    #: Whether the searcher looks again at a stop that missed before moving on (:data:`RELOOKS`).
    relook: str = "off"
    #: How repeated misses at one stop are counted (:data:`STOP_MISSES`).
    stop_misses: str = "pooled"

    def __post_init__(self) -> None:
        if self.preset not in PRESETS:
            raise ObjsearchError(
                f"unknown perception preset {self.preset!r}; choose from {', '.join(PRESETS)}"
            )
        for name in (
            "recall_small",
            "recall_medium",
            "recall_large",
            "recall_scale",
            "occluded_recall",
            "confusion",
        ):
            value = getattr(self, name)
            if not 0.0 <= value <= 1.0:
                raise ObjsearchError(f"perception {name} must be in [0, 1], not {value}")
        if self.fp_per_image < 0:
            raise ObjsearchError(f"perception fp_per_image must be >= 0, not {self.fp_per_image}")
        if not 0.0 <= self.threshold < 1.0 or not 0.5 <= self.accept_posterior <= 1.0:
            raise ObjsearchError(
                "perception threshold must be in [0, 1) and accept_posterior in [0.5, 1]"
            )
        if min(*self.tp_score, *self.fp_score) <= 0:
            raise ObjsearchError("perception score shapes must be > 0")
        if self.confirmation not in CONFIRMATIONS:
            raise ObjsearchError(
                f"unknown confirmation {self.confirmation!r}; choose from {', '.join(CONFIRMATIONS)}"
            )
        if not 0.0 < self.fp_recurrence < 1.0:
            raise ObjsearchError(
                f"perception fp_recurrence must be in (0, 1), not {self.fp_recurrence}"
            )
        if self.draws not in DRAWS:
            raise ObjsearchError(f"unknown draws {self.draws!r}; choose from {', '.join(DRAWS)}")
        if self.reports not in REPORTS:
            raise ObjsearchError(
                f"unknown reports {self.reports!r}; choose from {', '.join(REPORTS)}"
            )
        if self.relook not in RELOOKS:
            raise ObjsearchError(
                f"unknown relook {self.relook!r}; choose from {', '.join(RELOOKS)}"
            )
        if self.stop_misses not in STOP_MISSES:
            raise ObjsearchError(
                f"unknown stop misses {self.stop_misses!r}; choose from {', '.join(STOP_MISSES)}"
            )

    @property
    def perfect(self) -> bool:
        """Every object in view reported with score 1, nothing false: the simulator of old."""
        return (
            min(self.recall_small, self.recall_medium, self.recall_large) == 1.0
            and self.recall_scale == 1.0
            and self.occluded_recall == 1.0
            and self.fp_per_image == 0.0
            and self.confusion == 0.0
        )

    # -- what the detector does ---------------------------------------------------------------

    def recall(self, mask_px: float, visible: float = 1.0) -> float:
        """P(an object in view showing ``mask_px`` pixels, ``visible`` of it, is reported)."""
        if mask_px < SMALL_PX:
            base = self.recall_small
        elif mask_px < LARGE_PX:
            base = self.recall_medium
        else:
            base = self.recall_large
        occluded = self.occluded_recall if visible < OCCLUDED_BELOW else 1.0
        return base * self.recall_scale * occluded

    def miss(self, mask_px: float, visible: float = 1.0) -> float:
        """P(not reported | present in view): what a look that saw nothing says."""
        return 1.0 - self.recall(mask_px, visible)

    # -- what a score says --------------------------------------------------------------------

    def likelihood_ratio(self, score: float) -> float:
        """p(score | true detection) / p(score | false one); infinite for a score of 1."""
        u = (score - self.threshold) / (1.0 - self.threshold)
        if u >= 1.0:
            return math.inf
        if u <= 0.0:
            return 0.0
        return math.exp(_log_beta_pdf(u, *self.tp_score) - _log_beta_pdf(u, *self.fp_score))

    def look_ratio(self, mask_px: float, score: float | None) -> float:
        """The factor one confirming look multiplies a sighting's odds by: a report of it at
        ``score`` (None: none), the object expected to show ``mask_px`` pixels, taken as
        occluded (the agent cannot tell how much of it is hidden): r = :meth:`recall` there.

        ``score``: a report counts by its score's likelihood ratio alone, a miss by 1 − r.
        ``consistent``: P(what was seen | real) / P(what was seen | false) for both, a false
        report recurring at the spot with probability q = ``fp_recurrence``: a report
        r · p(score | true) / (q · p(score | false)), a miss (1 − r) / (1 − q)."""
        r = self.recall(mask_px, visible=0.0)
        if self.confirmation == "score":
            return 1.0 - r if score is None else self.likelihood_ratio(score)
        q = self.fp_recurrence
        if score is None:
            return (1.0 - r) / (1.0 - q)
        ratio = self.likelihood_ratio(score)
        return ratio if math.isinf(ratio) and r > 0 else r / q * ratio

    def posterior(self, odds: float) -> float:
        """P(real) from the odds of real against false."""
        return 1.0 if math.isinf(odds) else odds / (1.0 + odds)

    def sure(self, score: float) -> bool:
        """Whether one detection at ``score`` is a sighting by itself (even prior odds)."""
        return self.perfect or self.posterior(self.likelihood_ratio(score)) >= self.accept_posterior

    # -- the run spec -------------------------------------------------------------------------

    def params(self) -> dict[str, Any]:
        """As the run spec records it (``params.perception``); the ``score`` confirmation,
        ``view`` draws, ``misses`` reports, ``off`` relook and ``pooled`` stop misses are left out, so a run spec is what
        it was before each option."""
        doc = asdict(self)
        doc["tp_score"] = list(self.tp_score)
        doc["fp_score"] = list(self.fp_score)
        if self.confirmation == "score":
            del doc["confirmation"], doc["fp_recurrence"]
        if self.draws == "view":
            del doc["draws"]
        if self.reports == "misses":
            del doc["reports"]
        if self.relook == "off":
            del doc["relook"]
        if self.stop_misses == "pooled":
            del doc["stop_misses"]
        return doc

    @classmethod
    def from_params(cls, doc: Mapping[str, Any] | None) -> PerceptionModel:
        """The model a run spec's ``params.perception`` names (none: ``perfect``)."""
        if doc is None:
            return cls()
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(doc) - known)
        if unknown:
            raise ObjsearchError(f"unknown perception parameter(s) {', '.join(unknown)}")
        values = dict(doc)
        for pair in ("tp_score", "fp_score"):
            if pair in values:
                a, b = values[pair]
                values[pair] = (float(a), float(b))
        return cls(**values)


def class_sizes(data: Path | None = None) -> Mapping[str, tuple[float, float, float]]:
    """Each movable class's typical box (m), from :data:`SIZES_FILE` of the data folder ``data``
    (None: ``datapaths.data_dir()``); read once per resolved folder."""
    return _class_sizes(data_key(data))


@cache
def _class_sizes(folder: Path) -> Mapping[str, tuple[float, float, float]]:
    path = folder / SIZES_FILE
    doc = read_json(path, "the AI2-THOR placement statistics")
    try:
        return {c: (float(v[0]), float(v[1]), float(v[2])) for c, v in doc["sizes"].items()}
    except (KeyError, TypeError, ValueError, IndexError) as exc:
        raise DataFileError(f"{path} is malformed: {exc!r}") from None


def expected_mask_px(size: tuple[float, float, float], distance: float, depression: float) -> float:
    """The mask (px) an object with box ``size`` shows ``distance`` metres from the camera, seen
    ``depression`` radians from above: its side (mean width × height) and its top, each
    foreshortened, times (f / distance)². Within a factor of about 2 of the occluding camera's
    masks of the development homes' placements seen from their statics' viewpoints."""
    width = (size[0] + size[1]) / 2
    area = width * size[2] * math.cos(depression) + size[0] * size[1] * math.sin(depression)
    return FOCAL_PX**2 * area / max(distance, NEAREST_M) ** 2


def _log_beta_pdf(u: float, a: float, b: float) -> float:
    return (
        (a - 1.0) * math.log(u)
        + (b - 1.0) * math.log1p(-u)
        - (math.lgamma(a) + math.lgamma(b) - math.lgamma(a + b))
    )


def preset(
    name: str,
    confirmation: str | None = None,
    draws: str | None = None,
    reports: str | None = None,
    relook: str | None = None,
    stop_misses: str | None = None,
    **overrides: float,
) -> PerceptionModel:
    """A preset, with some parameters overridden (:data:`OVERRIDES`).

    ``realistic``: Mask R-CNN's COCO recall by size bin (:data:`MASK_RCNN_RECALL`), 0.1 false
    positives of the vocabulary per view, 5 % confusions, occluded objects at half recall;
    ``harsh``: half its recall and twice its false positives and confusions, confirmed at
    :data:`HARSH_ACCEPT_POSTERIOR`; ``confirmation``
    names the confirmation model (:data:`CONFIRMATIONS`; None: the preset's own,
    :data:`PRESET_CONFIRMATION`), ``draws`` how the simulator keys its draws (:data:`DRAWS`;
    None: ``place``, but ``view`` for ``perfect``, which draws nothing), ``reports`` what a
    report that is no sighting tells the day's memory (:data:`REPORTS`; None: ``evidence``, but
    ``misses`` for ``perfect``, whose reports are all sightings but for their masks, as before).
    ``relook`` what the searcher does after an inspection that missed (:data:`RELOOKS`; None:
    ``likeliest``, chosen by the amendment of 2026-12-07 21:12 UTC of docs/protocol-perception.md,
    but ``off`` for ``perfect``, as before); ``stop_misses`` how repeated misses at a stop are
    counted (:data:`STOP_MISSES`; None: ``per-static``, by the rule of the amendment of
    2026-12-07 23:03 UTC, but ``pooled`` for ``perfect``, which never looks again)."""
    if name not in PRESETS:
        raise ObjsearchError(
            f"unknown perception preset {name!r}; choose from {', '.join(PRESETS)}"
        )
    model = PerceptionModel()
    if name != "perfect":
        small, medium, large = MASK_RCNN_RECALL
        model = PerceptionModel(
            preset=name,
            recall_small=small,
            recall_medium=medium,
            recall_large=large,
            occluded_recall=0.5,
            fp_per_image=0.1,
            confusion=0.05,
        )
    if name == "harsh":
        model = replace(
            model,
            recall_scale=0.5,
            fp_per_image=0.2,
            confusion=0.1,
            accept_posterior=HARSH_ACCEPT_POSTERIOR,
        )
    for key, value in overrides.items():
        if key not in OVERRIDES:
            raise ObjsearchError(f"unknown perception parameter {key!r}")
        low, high = OVERRIDES[key]
        if not low <= value <= high:
            raise ObjsearchError(f"perception {key} must be in [{low}, {high}], not {value}")
    for key, value in overrides.items():
        model = replace(model, **{key: float(value)})  # type: ignore[arg-type]
    return replace(
        model,
        confirmation=confirmation or PRESET_CONFIRMATION[name],
        # A perfect detector draws nothing: it stays the default model.
        draws=draws or ("view" if name == "perfect" else "place"),
        reports=reports or ("misses" if name == "perfect" else "evidence"),
        relook=relook or ("off" if name == "perfect" else "likeliest"),
        stop_misses=stop_misses or ("pooled" if name == "perfect" else "per-static"),
    )
