"""The acting half of one search task: moves, views and detections, each recorded as an event, and
the confirming looks of the sequential test (docs/perception.md)."""

from __future__ import annotations

import math
from collections.abc import Sequence

from objsearch.agent.camera_frames import pitch_towards
from objsearch.agent.catalogue import (
    ClassScore,
    ContainerOpened,
    Detected,
    DetectedV2,
    Moved,
    Record,
    SightingRejected,
    Support,
    ViewReason,
    ViewTaken,
)
from objsearch.agent.confirmation import (
    CONFIRM_LOOKS,
    CONFIRM_VIEWPOINTS,
    REJECT_BELOW,
    TaskOdds,
    same_object,
)
from objsearch.agent.event_values import planar, xyz
from objsearch.agent.geometry import Point, Pose, heading, wrap_angle
from objsearch.agent.results import Found, SearchResult
from objsearch.agent.stops import Stop, cover_views, static_pitch
from objsearch.agent.world import Detection, Navigation

LOOK_OFFSETS = (0.0, math.pi / 4, -math.pi / 4)  # θ_s and ±45° (paper §5.1)


class SearchTask(TaskOdds):
    """The acting half of one search: moves, views and detections, each recorded as an event."""

    def emit(self, record: Record) -> None:
        self.agent.recorder.emit(record, time_ns=self.world.now_ns(), task_id=self.task_id)

    def detection(self, det: Detection, room: str, *, sure: bool | None = None) -> bool:
        """Record one detection; True if it is of the target and passes its class's threshold
        (a sighting, sure or still to confirm). It is ``accepted`` (learned) when it passes and is
        sure: by its score alone (:meth:`PerceptionModel.sure`), or as ``sure`` says (a
        confirming look's verdict)."""
        oc = self.agent.vocabulary.classes.get(det.object_class)
        passes = oc is not None and det.mask_area >= oc.min_mask_area_px
        model = self.agent.config.perception
        nearest = self.agent.semmap.nearest(det.position, room)
        at_static = nearest is not None and nearest[1] <= self.agent.config.support_radius
        support = (
            Support(static_id=nearest[0].id, static_class=nearest[0].cls, at=at_static)
            if nearest
            else None
        )
        object_class, instance_id = det.object_class, det.instance_id
        mask_area, position = round(det.mask_area, 2), xyz(det.position)
        if model.perfect:
            # What a perfect detector's logs always held (v2): every passing detection counts.
            self.emit(
                DetectedV2(
                    object_class=object_class,
                    instance_id=instance_id,
                    mask_area=mask_area,
                    position=position,
                    accepted=passes,
                    support=support,
                )
            )
        else:
            if sure is not None:
                counted = sure
            elif det.object_class == self.target:
                counted = self.is_sure(det)
            else:
                counted = model.sure(det.score)
            self.emit(
                Detected(
                    object_class=object_class,
                    instance_id=instance_id,
                    mask_area=mask_area,
                    position=position,
                    accepted=passes and counted,
                    support=support,
                    score=round(det.score, 4),
                    classes=tuple(
                        ClassScore(object_class=c, p=round(p, 4)) for c, p in det.class_scores
                    ),
                )
            )
        return passes and det.object_class == self.target

    def sighting(self, det: Detection, result: SearchResult, container: str | None = None) -> Found:
        """A sighting of the target by ``det``, made with ``container`` opened (or none)."""
        return Found(
            det.instance_id,
            det.position,
            self.world.pose(),
            result.path_length,
            det.score,
            det.mask_area,
            self.is_sure(det),
            container,
        )

    def confirm(
        self, found: Found, result: SearchResult, odds: float | None = None
    ) -> Found | None:
        """The sighting if it is confirmed, else None (a ``sighting_rejected`` is recorded).

        A sighting sure by its score (and the odds earlier looks left at its place) stands.
        Otherwise it is a sequential test: from those odds times its score's likelihood ratio,
        the robot looks at the object again, in turn from the :data:`CONFIRM_VIEWPOINTS`
        viewpoints it was seen from or nearest it, at most :data:`CONFIRM_LOOKS` looks: a
        detection of the target there or none multiplies the odds by the model's
        :meth:`~PerceptionModel.look_ratio` for the mask the object would show from there,
        occluded (the agent cannot tell how much of it is hidden; the unoccluded miss rejected
        true sightings that were partly hidden). It is
        confirmed once P(real) reaches the model's ``accept_posterior``, rejected when it falls
        below :data:`REJECT_BELOW` or the looks run out; its odds stay with its place for the
        rest of the task. A sighting of the target elsewhere during the looks is queued.
        ``odds``: go on with a test an earlier call left undecided (a revisit)."""
        if found.sure:
            return found
        model = self.agent.config.perception
        nav = self.agent.navmap
        if odds is None:
            odds = self.prior_odds(
                found.position, found.mask_area, found.pose
            ) * model.likelihood_ratio(found.score)
        room = nav.room_at(found.pose.x, found.pose.y)
        px, py, pz = found.position
        seen_from = math.dist((found.pose.x, found.pose.y, 1.0), (px, py, pz))
        nearest = self.confirming_viewpoints(found, room)
        looks = 0
        while looks < CONFIRM_LOOKS:
            dets, pose = self.confirming_look(found, nearest[looks % len(nearest)], result)
            looks += 1
            again = self.seen_again(found, dets, pose)
            here = math.dist((pose.x, pose.y, 1.0), (px, py, pz))
            expected = found.mask_area * (seen_from / max(here, 0.1)) ** 2
            odds *= model.look_ratio(expected, None if again is None else again.score)
            verdict = model.posterior(odds) >= model.accept_posterior
            for d in dets:
                hit = self.detection(d, room, sure=verdict if d is again else None)
                if hit and d is not again:
                    self.queued.append(self.sighting(d, result, found.container))
            if verdict and again is not None:
                return Found(
                    again.instance_id,
                    again.position,
                    found.pose,
                    found.path_length,
                    again.score,
                    again.mask_area,
                    True,
                    found.container,
                )
            if model.posterior(odds) < REJECT_BELOW:
                break
        self.unconfirmed.append((found, odds))
        self.emit(
            SightingRejected(
                object_class=self.target,
                instance_id=found.instance_id,
                position=xyz(found.position),
                score=round(found.score, 4),
                posterior=round(model.posterior(odds), 6),
                looks=looks,
            )
        )
        return None

    def confirming_viewpoints(self, found: Found, room: str) -> list[Point]:
        """Where the confirming looks at ``found`` are taken from, in turn: where it was seen
        from first (a look there costs no metres: this detector's draws are independent from
        view to view), then the viewpoints of ``room`` nearest it. Seen inside an opened
        container: only from where it was opened (within reach), opening it again each look."""
        px, py, _ = found.position
        others = 0 if found.container is not None else CONFIRM_VIEWPOINTS - 1
        return [
            found.pose.point,
            *sorted(
                (v for v in self.agent.navmap.viewpoints(room) if v != found.pose.point),
                key=lambda v: (math.dist((v.x, v.y), (px, py)), v),
            )[:others],
        ]

    def confirming_look(
        self, found: Found, viewpoint: Point, result: SearchResult
    ) -> tuple[Sequence[Detection], Pose]:
        """One confirming look at ``found`` from ``viewpoint`` (driven to, and recorded): its
        detections and the pose it was taken from."""
        px, py, pz = found.position
        # Opening a container turns the robot to it; otherwise it turns to the object.
        facing = None if found.container is not None else heading(viewpoint, Point(px, py))
        self.go(viewpoint, result, watch=False, final_yaw=facing)
        pitch = pitch_towards((viewpoint.x, viewpoint.y), (px, py, pz))
        reason: ViewReason = "look"
        if found.container is not None:
            dets = self.world.open(found.container, pitch)
            self.emit(ContainerOpened(static_id=found.container, pose=planar(self.world.pose())))
            reason = "inside"
        else:
            dets = self.world.look(heading(viewpoint, Point(px, py)), pitch)
        pose = self.world.pose()
        self.emit(
            ViewTaken(pose=planar(pose), pitch=round(pitch, 4), static_id=None, reason=reason)
        )
        return dets, pose

    def seen_again(self, found: Found, dets: Sequence[Detection], pose: Pose) -> Detection | None:
        """The object of ``found`` seen again in ``dets`` (a view from ``pose``): the report of
        its class nearest where it was seen, among those that are the same object
        (:func:`same_object`). Not the first in the view's order: a false one beside the real
        object, reported first, was then "found" though the object itself was seen in the same
        view (harsh procthor-00 habit-0 scene 1)."""
        return min(
            (
                d
                for d in dets
                if d.object_class == self.target
                and same_object(found, d.position, d.mask_area, pose)
            ),
            key=lambda d: math.dist(d.position, found.position),
            default=None,
        )

    def settle(self, sightings: Sequence[Found], result: SearchResult) -> Found | None:
        """Confirm ``sightings`` in turn, and any their confirming looks queued; the first
        confirmed one, or None."""
        todo = list(sightings)
        while todo or self.queued:
            if not todo:
                todo, self.queued = self.queued, []
            confirmed = self.confirm(todo.pop(0), result)
            if confirmed is not None:
                return confirmed
        return None

    def go(
        self,
        goal: Point,
        result: SearchResult,
        *,
        watch: bool = True,
        final_yaw: float | None = None,
    ) -> Found | None:
        """Drive to a viewpoint; with ``watch``, stop as soon as the target is seen on the way."""
        start = self.world.pose()
        if start.point == goal and (
            final_yaw is None or abs(wrap_angle(start.yaw - final_yaw)) < 1e-9
        ):
            return None
        seen: set[str] = set()
        found: list[Detection] = []

        def on_detection(det: Detection, pose: Pose) -> bool:
            if det.instance_id in seen:
                return False
            seen.add(det.instance_id)
            hit = self.detection(det, self.agent.navmap.room_at(pose.x, pose.y))
            if hit and watch:
                found.append(det)
                return True
            return False

        while True:
            nav: Navigation = self.world.navigate(
                goal, on_detection=on_detection, final_yaw=final_yaw
            )
            result.path_length += nav.metres
            result.route.extend(nav.path[1:])
            self.emit(
                Moved(
                    start=planar(start),
                    end=planar(nav.end),
                    metres=round(nav.metres, 4),
                    rooms=tuple(nav.rooms),
                    interrupted=nav.interrupted,
                )
            )
            if not found:
                return None
            sightings = [self.sighting(det, result) for det in found]
            found.clear()
            confirmed = self.settle(sightings, result)
            if confirmed is not None:
                return confirmed
            # Rejected: on to the goal, as if it had not been seen.
            start = self.world.pose()
            if start.point == goal and (
                final_yaw is None or abs(wrap_angle(start.yaw - final_yaw)) < 1e-9
            ):
                return None

    def inspect(self, stop: Stop, result: SearchResult) -> Found | None:
        """Open each container of the stop and look in; look at the others from θ_s and ±45°.
        Each view tilts the camera at the static (:func:`static_pitch`)."""
        self.inspected[stop.key] = self.inspected.get(stop.key, 0) + 1
        self.current = stop.key
        try:
            return self._inspect(stop, result)
        finally:
            self.current = None

    def _inspect(self, stop: Stop, result: SearchResult) -> Found | None:
        room = stop.statics[0].room
        yaws_done: list[float] = []
        for s in stop.statics:
            back = self.back_to(stop.viewpoint, result)
            if back:
                return back
            pitch = static_pitch(self.world.pose().point, s)
            if s.container:
                dets = self.world.open(s.id, pitch)
                pose = self.world.pose()
                self.emit(ContainerOpened(static_id=s.id, pose=planar(pose)))
                hit = self._view(pose, pitch, s.id, "inside", dets, room, result, s.id)
                if hit:
                    return hit
                continue
            for offset in LOOK_OFFSETS:
                yaw = wrap_angle(s.view_yaw + offset)
                if any(abs(wrap_angle(yaw - y)) < 1e-3 for y in yaws_done):
                    continue
                yaws_done.append(yaw)
                back = self.back_to(stop.viewpoint, result)
                if back:
                    return back
                dets = self.world.look(yaw, pitch)
                hit = self._view(self.world.pose(), pitch, s.id, "look", dets, room, result)
                if hit:
                    return hit
        return None

    def back_to(self, viewpoint: Point, result: SearchResult) -> Found | None:
        """Back at ``viewpoint`` after a rejected sighting's looks took the robot away (nothing
        happens when it is there: always so with a perfect detector)."""
        if self.world.pose().point == viewpoint:
            return None
        return self.go(viewpoint, result)

    def cover(self, stop: Stop, result: SearchResult) -> Found | None:
        """The stretches of the stop's long statics that its viewpoint may not see
        (:func:`cover_views`), nearest-first from here."""
        todo = cover_views(self.agent.navmap, stop.viewpoint, stop.statics)
        while todo:
            here = self.world.pose().point
            view = min(
                todo, key=lambda v: (self.agent.navmap.distance(here, v.viewpoint), v.viewpoint)
            )
            todo.remove(view)
            found = self.go(view.viewpoint, result)
            if found:
                return found
            pitch = static_pitch(view.viewpoint, view.static)
            dets = self.world.look(heading(view.viewpoint, view.stretch), pitch)
            hit = self._view(
                self.world.pose(), pitch, view.static.id, "look", dets, view.static.room, result
            )
            if hit:
                return hit
        return None

    def _view(
        self,
        pose: Pose,
        pitch: float,
        static_id: str,
        reason: ViewReason,
        dets: Sequence[Detection],
        room: str,
        result: SearchResult,
        container: str | None = None,
    ) -> Found | None:
        """Record a view and its detections; confirm its sightings (``container``: the one
        opened for it)."""
        self.emit(
            ViewTaken(pose=planar(pose), pitch=round(pitch, 4), static_id=static_id, reason=reason)
        )
        sightings = [
            self.sighting(det, result, container) for det in dets if self.detection(det, room)
        ]
        return self.settle(sightings, result)
