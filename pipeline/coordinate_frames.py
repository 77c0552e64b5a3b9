"""Unity (AI2-THOR) frame <-> ROS REP-103 ``map`` frame.

Unity: y up, x/z on the floor, left-handed, yaw in degrees clockwise seen from above, 0 facing +z.
REP-103: z up, x/y on the floor, right-handed, yaw in radians counter-clockwise from +x.
The map (x, y, z)_unity -> (z, -x, y)_ros has determinant -1, which is what turns the left-handed
frame right-handed; the same reflection reverses the sense of rotation, hence the minus on yaw.
"""

from __future__ import annotations

import math

from objsearch.agent.geometry import Vec3


def wrap_angle(angle: float) -> float:
    """Wrap radians into (-pi, pi]; -pi itself maps to pi so each heading has one value."""
    wrapped = math.remainder(angle, math.tau)
    if wrapped <= -math.pi:
        wrapped += math.tau
    return wrapped + 0.0


def unity_to_ros(point: Vec3) -> Vec3:
    x, y, z = point
    return (z + 0.0, -x + 0.0, y + 0.0)


def ros_to_unity(point: Vec3) -> Vec3:
    x, y, z = point
    return (-y + 0.0, z + 0.0, x + 0.0)


def unity_floor_to_ros(x: float, z: float) -> tuple[float, float]:
    """A Unity floor point (x, z) as a ROS floor point (x, y)."""
    return (z + 0.0, -x + 0.0)


def ros_floor_to_unity(x: float, y: float) -> tuple[float, float]:
    """A ROS floor point (x, y) as a Unity floor point (x, z)."""
    return (-y + 0.0, x + 0.0)


def unity_size_to_ros(size: Vec3) -> Vec3:
    """Axis-aligned box extents: sizes are unsigned, so the axis swap carries no minus sign."""
    sx, sy, sz = size
    return (sz, sx, sy)


def ros_size_to_unity(size: Vec3) -> Vec3:
    sx, sy, sz = size
    return (sy, sz, sx)


def unity_yaw_to_ros(yaw_deg: float) -> float:
    """Unity yaw (degrees, clockwise from +z) -> ROS yaw (radians, counter-clockwise from +x)."""
    return wrap_angle(-math.radians(yaw_deg))


def ros_yaw_to_unity(yaw_rad: float) -> float:
    """ROS yaw (radians) -> Unity yaw in degrees in [0, 360)."""
    degrees = (-math.degrees(yaw_rad)) % 360.0
    # Floating-point noise can land a hair below 360; that heading is 0.
    return 0.0 if math.isclose(degrees, 360.0, abs_tol=1e-9) else degrees + 0.0
