"""Values as the agent's events record them: poses and points rounded to 0.1 mm (0.1 mrad)."""

from __future__ import annotations

from collections.abc import Sequence

from objsearch.agent.catalogue import XY, XYZ, PlanarPose
from objsearch.agent.geometry import Pose


def planar(pose: Pose) -> PlanarPose:
    """A pose as events record it: to 0.1 mm and 0.1 mrad (as ``Pose.as_dict``)."""
    return PlanarPose(x=round(pose.x, 4), y=round(pose.y, 4), yaw=round(pose.yaw, 4))


def xy(v: Sequence[float]) -> XY:
    return (round(float(v[0]), 4), round(float(v[1]), 4))


def xyz(v: Sequence[float]) -> XYZ:
    return (round(float(v[0]), 4), round(float(v[1]), 4), round(float(v[2]), 4))
