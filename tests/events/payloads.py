"""One valid payload per event type at its latest version (and the older versions' examples),
shared by the events tests."""

from __future__ import annotations

from typing import Any

POSE = {"x": 1.0, "y": -2.5, "yaw": 1.5707963}

EXAMPLES: dict[str, dict[str, Any]] = {
    "run_started": {
        "home": "paper-4room",
        "home_digest": "sha256:0123abcd",
        "strategy": "wpl-neg-decay",
        "method": "wpl",
        "planner": "wpl",
        "relations": {
            "model": "beta",
            "prior_strength": 2.0,
            "half_life_tasks": 64.0,
            "recent_weight": None,
        },
        "alpha": 10.0,
        "update_mode": "targets",
        "seed": 7,
        "support_radius": 0.5,
        "schedule": "stats-3",
        "params": {"fov_deg": 90, "nested": {"ok": [1, 2]}},
    },
    "scene_graph_seeded": {
        "source": "data/priors/visual_genome.json",
        "values": [
            {"dynamic": "Cup", "static": "Table", "rel": 0.42},
            {"dynamic": "Cup", "static": "Sink", "rel": 0.0},
        ],
    },
    "task_started": {
        "target": "Cup",
        "start": "kitchen",
        "pose": POSE,
        "scene": 3,
        "clock": {"weekday": 5, "minute": 450},
    },
    "plan_computed": {
        "room": "kitchen",
        "room_order": ["kitchen", "living_room"],
        "objective": "wpl",
        "alpha": 10.0,
        "candidates": [
            {"static_id": "Table|1", "static_class": "Table", "viewpoint": [1.0, 2.0], "rel": 0.4},
            {"static_id": "Sink|1", "static_class": "Sink", "viewpoint": [3.0, 0.5], "rel": 1},
        ],
        "order": ["Table|1", "Sink|1"],
        "terms": [0.31, 0.12],
        "value": 0.43,
    },
    "moved": {
        "start": POSE,
        "end": {"x": 2.0, "y": 0.0, "yaw": 0.0},
        "metres": 3.2,
        "rooms": ["kitchen", "living_room"],
        "interrupted": False,
    },
    "view_taken": {"pose": POSE, "pitch": 0.0, "static_id": None, "reason": "on_the_way"},
    "container_opened": {"static_id": "Fridge|1", "pose": POSE},
    "detection": {
        "object_class": "Cup",
        "instance_id": "Cup|3",
        "mask_area": 812.0,
        "position": [1.0, 2.0, 0.9],
        "accepted": True,
        "support": {"static_id": "Table|1", "static_class": "Table", "at": True},
        "score": 1.0,
        "classes": [],
    },
    "sighting_rejected": {
        "object_class": "Cup",
        "instance_id": "Cup|3",
        "position": [1.0, 2.0, 0.9],
        "score": 0.62,
        "posterior": 0.31,
        "looks": 2,
    },
    "target_detected": {
        "instance_id": "Cup|3",
        "position": [1.0, 2.0, 0.9],
        "pose": POSE,
        "path_length": 10.25,
    },
    "target_found": {"instance_id": "Cup|3", "position": [1.0, 2.0, 0.9], "approach": POSE},
    "search_failed": {"reason": "all candidates visited"},
    "record_quarantined": {
        "reason": "its bytes were damaged",
        "quarantine": "events.log.repair-1024",
        "offset": 0,
        "length": 312,
        "chain": None,
    },
    "task_ended": {"target": "Cup", "success": True, "path_length": 12.5},
    "task_aborted": {"target": "Cup", "reason": "restart", "path_length": 3.25},
    "pose_observed": {"pose": POSE, "frame_id": "map", "topic": "/odom"},
    "objects_detected": {
        "frame_id": "map",
        "topic": "/objsearch/detections",
        "detections": [
            {
                "instance_id": "Cup|3",
                "class_id": "Cup",
                "score": 1.0,
                "bbox": [320.0, 240.0, 28.5, 28.5],
                "position": [1.0, 2.0, 0.9],
            }
        ],
    },
}

#: Payloads of superseded versions, keyed (type, version); the upcast of each must equal
#: ``EXAMPLES[type]`` where noted in the tests.
OLD_EXAMPLES: dict[tuple[str, int], dict[str, Any]] = {
    ("run_started", 1): {
        "home": "paper-4room",
        "home_digest": "sha256:0123abcd",
        "method": "wpl",
        "alpha": 10.0,
        "update_mode": "targets",
        "seed": 7,
        "params": {"strategy": "wpl-neg-decay", "support_radius": 0.5, "schedule": "stats-3"},
    },
    ("run_started", 2): {
        "home": "paper-4room",
        "home_digest": "sha256:0123abcd",
        "strategy": "wpl-neg-decay",
        "method": "wpl",
        "planner": "wpl",
        "relations": {"model": "beta", "prior_strength": 2.0, "half_life_tasks": 64.0},
        "alpha": 10.0,
        "update_mode": "targets",
        "seed": 7,
        "support_radius": 0.5,
        "schedule": "stats-3",
        "params": {},
    },
    ("detection", 1): {
        "object_class": "Cup",
        "instance_id": "Cup|3",
        "mask_area": 812.0,
        "position": [1.0, 2.0, 0.9],
        "accepted": True,
        "nearest_static_id": "Table|1",
        "nearest_static_class": "Table",
        "at_static": True,
    },
    ("detection", 2): {
        "object_class": "Cup",
        "instance_id": "Cup|3",
        "mask_area": 812.0,
        "position": [1.0, 2.0, 0.9],
        "accepted": True,
        "support": {"static_id": "Table|1", "static_class": "Table", "at": True},
    },
    ("task_started", 1): {"target": "Cup", "start": "kitchen", "pose": POSE, "scene": 3},
    ("view_taken", 1): {"pose": POSE, "static_id": None, "reason": "on_the_way"},
}

LATEST: dict[str, int] = {t: 1 for t in EXAMPLES} | {
    "detection": 3,
    "run_started": 5,
    "task_started": 2,
    "view_taken": 2,
}
