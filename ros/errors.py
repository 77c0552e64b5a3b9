"""Errors of the ROS message layer. All are :class:`ObjsearchError`, so the CLI reports them cleanly."""

from __future__ import annotations

from objsearch.agent.errors import ObjsearchError


class TopicMapError(ObjsearchError):
    """A topic map (topics → roles, frame names) that cannot be used."""


class TransformError(ObjsearchError):
    """A transform cannot be looked up: frames not connected, or the stamp is out of range."""


class QosError(ObjsearchError):
    """A QoS setting that cannot be used."""
