"""Where a search looks (paper §5.1): stops (one viewpoint, one class of static objects), their
value for a target, the camera's aim at a static, and the second pass's looks along long statics
(inspection ``cover``). The one statement of each rule: the agent, the audit and the bench's
failure causes share them."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from objsearch.agent.camera_frames import pitch_towards
from objsearch.agent.geometry import Point
from objsearch.agent.navmap import NavigationMap
from objsearch.agent.relations import RelationModel, instance_value, per_instance
from objsearch.agent.semmap import MappedStatic, SemanticMap

#: Inspection ``cover`` (a reading of §4 beside the paper's single N_s): when a search found nothing,
#: a second pass looks at each static longer than this from the viewpoint nearest each stretch of
#: at most this length along (and, if it is this deep, across) its top.
COVER_SPAN_M = 1.5


@dataclass(frozen=True, slots=True)
class Stop:
    """Where the robot goes to check static objects: one viewpoint, one class, ≥ 1 instances."""

    statics: tuple[MappedStatic, ...]
    rel: float

    @property
    def key(self) -> str:
        return self.statics[0].id

    @property
    def cls(self) -> str:
        return self.statics[0].cls

    @property
    def viewpoint(self) -> Point:
        return self.statics[0].viewpoint


def static_pitch(here: Point, static: MappedStatic) -> float:
    """The camera tilt for a view of ``static`` from ``here`` (as AI2-THOR's ``horizon``): at
    the middle of its top surface, where movable things lie, or, for a container, at its centre,
    where they lie once it is open; clamped to the tilt unit's range."""
    c, size = static.box.center, static.box.size
    z = c[2] if static.container else c[2] + size[2] / 2
    return pitch_towards((here.x, here.y), (static.loc.x, static.loc.y, z))


def static_point(static: MappedStatic) -> tuple[float, float, float]:
    """Where a movable thing at ``static`` is looked for: the middle of its top surface, or, for
    a container, its centre (as :func:`static_pitch` aims)."""
    c, size = static.box.center, static.box.size
    z = c[2] if static.container else c[2] + size[2] / 2
    return (static.loc.x, static.loc.y, z)


def cover_points(static: MappedStatic) -> list[Point]:
    """The centres of a grid of stretches at most ``COVER_SPAN_M`` long over a long static's top,
    along its long side and, when it is that long too, across it (an L-shaped worktop's box is
    deep as well as long); none for a static shorter than that both ways."""
    sx, sy = static.box.size[0], static.box.size[1]
    if max(sx, sy) <= COVER_SPAN_M:
        return []
    cx, cy = static.box.center[0], static.box.center[1]

    def centres(length: float) -> list[float]:
        n = max(1, math.ceil(length / COVER_SPAN_M))
        return [-length / 2 + (k + 0.5) * length / n for k in range(n)]

    # Along the long side first, so a one-row static keeps its order.
    if sx >= sy:
        return [Point(cx + a, cy + b) for b in centres(sy) for a in centres(sx)]
    return [Point(cx + a, cy + b) for a in centres(sx) for b in centres(sy)]


@dataclass(frozen=True, slots=True)
class CoverView:
    """One look of the second pass: from ``viewpoint``, towards ``stretch`` of ``static``."""

    viewpoint: Point
    stretch: Point
    static: MappedStatic


def cover_views(
    navmap: NavigationMap, stop_viewpoint: Point, statics: Sequence[MappedStatic]
) -> list[CoverView]:
    """The second pass's looks at a stop's statics: each stretch (:func:`cover_points`) of a static
    that is not a container, from the viewpoint nearest it, one look per viewpoint, none from the
    stop's own — the one rule the search and the bench's failure causes share."""
    views: list[CoverView] = []
    for s in statics:
        if s.container:
            continue
        for point in cover_points(s):
            vp = navmap.nearest_viewpoint(point.x, point.y, s.room)
            if vp != stop_viewpoint and all(vp != v.viewpoint for v in views):
                views.append(CoverView(vp, point, s))
    return views


def stop_value(graph: RelationModel, target: str, statics: Sequence[MappedStatic]) -> float:
    """A stop's value: Rel(target, class), or, for a per-instance model, the summed values of its
    instances (capped at 1). The one rule; the agent and the audit both use it."""
    if not per_instance(graph):
        return graph.rel(target, statics[0].cls)
    return min(1.0, math.fsum(instance_value(graph, target, s.id, s.cls) for s in statics))


def stop_statics(semmap: SemanticMap, room: str, key: MappedStatic) -> list[MappedStatic]:
    """The statics grouped into the stop whose first instance is ``key``."""
    return [s for s in semmap.in_room(room) if s.viewpoint == key.viewpoint and s.cls == key.cls]
