"""``vision_msgs/Detection2D`` (ROS 2 4.x or ROS 1 layout) → an ``objects_detected`` detection:
the payload entry (:func:`detection_payload`) and a hypothesis's score (:func:`hypothesis_score`)."""

from __future__ import annotations

import math
from typing import Any

from objsearch.pipeline.bags.posetrack import coord


def detection_payload(d: Any) -> dict[str, Any]:
    best = max(d.results, key=lambda r: hypothesis_score(r), default=None)
    center = d.bbox.center
    cx, cy = (
        (center.position.x, center.position.y)
        if hasattr(center, "position")
        else (center.x, center.y)
    )
    bbox = [float(cx), float(cy), float(d.bbox.size_x), float(d.bbox.size_y)]
    if not all(math.isfinite(v) for v in bbox):
        raise ValueError("bounding box has a non-finite value")
    position = None
    class_id, score = "", 0.0
    if best is not None:
        hyp = getattr(best, "hypothesis", best)
        class_id = str(getattr(hyp, "class_id", getattr(hyp, "id", "")))
        score = float(hyp.score)
        if not math.isfinite(score):
            raise ValueError("hypothesis score is not finite")
        pt = best.pose.pose.position
        position = [coord(pt.x), coord(pt.y), coord(pt.z)]
    return {
        "instance_id": str(getattr(d, "id", "")),
        "class_id": class_id,
        "score": score,
        "bbox": bbox,
        "position": position,
    }


def hypothesis_score(r: Any) -> float:
    return float(getattr(getattr(r, "hypothesis", r), "score", 0.0))
