"""Asking a running agent to search (``objsearch agent find``), where it last saw something
(``objsearch agent where``) and, for tests and demos, telling
the stand-in robot where things are (``/objsearch_sim/reset``)."""

from __future__ import annotations

from typing import Any

from objsearch.runtime.backends import open_transport
from objsearch.runtime.config import RuntimeConfig
from objsearch.runtime.node import Node, Requester
from objsearch.runtime.requests import (
    check_find_result,
    check_reset_result,
    check_where_result,
)


class AgentClient:
    def __init__(self, config: RuntimeConfig) -> None:
        self.node = Node(open_transport(config.transport))
        t, q = config.topics, config.qos.requests
        self._find = Requester(self.node, t.find, t.find_result, q, check_find_result)
        self._where = Requester(self.node, t.where, t.where_result, q, check_where_result)
        self._reset = Requester(self.node, t.sim_reset, t.sim_reset_result, q, check_reset_result)

    def find(
        self,
        target: str,
        *,
        start: str | None = None,
        scene: int | None = None,
        not_before_ns: int = 0,
        timeout_s: float,
    ) -> dict[str, Any]:
        """``not_before_ns``: start from odometry stamped at or after this robot time (e.g. the
        stand-in's reset answer), not from a message sent before it."""
        body: dict[str, Any] = {
            "target": target,
            "start": start,
            "scene": scene,
            "not_before_ns": not_before_ns,
        }
        return self._find.call(body, timeout_s=timeout_s, resend_s=1.0, what=f"find {target}")

    def where(self, target: str, *, timeout_s: float) -> dict[str, Any]:
        """The agent's answer from its live memory (``ok`` false: ``error`` says why)."""
        body = {"target": target}
        return self._where.call(body, timeout_s=timeout_s, resend_s=1.0, what=f"where {target}")

    def reset_sim(self, scene: int | None, start: str, *, timeout_s: float) -> dict[str, Any]:
        body = {"scene": scene, "start": start}
        return self._reset.call(body, timeout_s=timeout_s, what="reset of the stand-in robot")

    def close(self) -> None:
        self.node.close()

    def __enter__(self) -> AgentClient:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
