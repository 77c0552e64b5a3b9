"""What can go wrong between the agent and a robot, each with a message an operator can act on."""

from __future__ import annotations

from objsearch.agent.errors import ObjsearchError


class RuntimeConfigError(ObjsearchError):
    """A robot configuration (robot.toml, command-line options) that cannot be used."""


class TransportError(ObjsearchError):
    """The middleware could not be opened or used (library missing, port taken, bad endpoint)."""


class MessageError(ObjsearchError):
    """A message that could not be decoded or does not make sense (reported, never fatal)."""


class RobotError(ObjsearchError):
    """The robot did not do what it was asked: it timed out, disappeared or refused."""


class SearchCancelled(RobotError):
    """The client that asked for the search cancelled it (a FindObject goal's cancel_goal)."""


class AnotherAgentError(ObjsearchError):
    """Another agent serves the same robot on this graph: this one does not serve."""
