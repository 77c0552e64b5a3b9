"""Opens the transport backend a :class:`~objsearch.runtime.transport.TransportConfig` names.

The factory stands apart from the seam (:mod:`objsearch.runtime.transport`) so imports point one
way: each backend imports the seam's types, this module imports the backends, and the seam imports
none of them. A backend's middleware (zenoh, cyclonedds, rclpy) is imported only when it is chosen.
"""

from __future__ import annotations

from objsearch.runtime.transport import Backend, Transport, TransportConfig


def open_transport(config: TransportConfig) -> Transport:
    if config.backend is Backend.ZENOH:
        from objsearch.runtime.zenoh_transport import ZenohTransport

        return ZenohTransport(config)
    if config.backend is Backend.ROS2:  # rclpy is imported only here
        from objsearch.runtime.ros2_transport import Ros2Transport

        return Ros2Transport(config)
    from objsearch.runtime.dds_transport import DdsTransport

    return DdsTransport(config)
