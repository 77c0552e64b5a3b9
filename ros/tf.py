"""A small TF buffer: the transforms of ``/tf`` and ``/tf_static``, looked up at a stamp.

Enough of tf2 for reading a bag offline: a frame tree (each child one parent), static edges valid
at all times, dynamic edges interpolated between the two samples around the stamp (translation
linearly, rotation by slerp) and never extrapolated — as ``tf2::BufferCore::lookupTransform``
refuses to. Only lookups into an ancestor frame are needed here (``map`` ← camera optical frame).
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from objsearch.ros.errors import TransformError

Vec = npt.NDArray[np.float64]


def quaternion_matrix(q: Vec) -> Vec:
    """3×3 rotation of a unit quaternion (x, y, z, w)."""
    x, y, z, w = (float(v) for v in q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def slerp(a: Vec, b: Vec, f: float) -> Vec:
    dot = float(np.dot(a, b))
    if dot < 0:  # the shorter way round
        b, dot = -b, -dot
    if dot > 0.9995:  # nearly equal: lerp is exact enough and avoids dividing by sin(≈0)
        out: Vec = a + (b - a) * f
        return out / np.linalg.norm(out)
    theta = math.acos(dot)
    s = math.sin(theta)
    res: Vec = (math.sin((1 - f) * theta) * a + math.sin(f * theta) * b) / s
    return res


def matrix(translation: Vec, rotation: Vec) -> Vec:
    t = np.eye(4)
    t[:3, :3] = quaternion_matrix(rotation)
    t[:3, 3] = translation
    return t


@dataclass
class _Edge:
    parent: str
    static: bool
    stamps: list[int] = field(default_factory=list)
    samples: list[tuple[Vec, Vec]] = field(default_factory=list)  # (translation, rotation xyzw)

    def at(self, stamp_ns: int, child: str) -> Vec:
        if self.static:
            return matrix(*self.samples[-1])
        i = bisect.bisect_left(self.stamps, stamp_ns)
        if i < len(self.stamps) and self.stamps[i] == stamp_ns:
            return matrix(*self.samples[i])
        if i == 0 or i == len(self.stamps):
            side = "before the first" if i == 0 else "after the last"
            near = self.stamps[0] if i == 0 else self.stamps[-1]
            raise TransformError(
                f"{self.parent} → {child} at {stamp_ns} ns: {side} transform ({near} ns); "
                "TF is not extrapolated"
            )
        t0, t1 = self.stamps[i - 1], self.stamps[i]
        (p0, q0), (p1, q1) = self.samples[i - 1], self.samples[i]
        f = (stamp_ns - t0) / (t1 - t0)
        return matrix(p0 + (p1 - p0) * f, slerp(q0, q1, f))


class TransformBuffer:
    def __init__(self) -> None:
        self._edges: dict[str, _Edge] = {}
        #: The newest stamp of any dynamic transform: frames up to it can be looked up.
        self.latest_ns: int | None = None

    def __contains__(self, frame: str) -> bool:
        return frame in self._edges or any(e.parent == frame for e in self._edges.values())

    def add(
        self,
        parent: str,
        child: str,
        stamp_ns: int,
        translation: Vec,
        rotation: Vec,
        *,
        static: bool = False,
    ) -> None:
        norm = float(np.linalg.norm(rotation))
        if not (np.isfinite(translation).all() and abs(norm - 1.0) < 1e-3):
            raise TransformError(f"{parent} → {child}: not a rigid transform")
        edge = self._edges.get(child)
        if edge is None or edge.parent != parent or edge.static != static:
            # tf2 lets a frame change parents; the newest parent wins here too.
            edge = self._edges[child] = _Edge(parent, static)
        sample = (np.asarray(translation, float), np.asarray(rotation, float) / norm)
        if static:
            edge.stamps, edge.samples = [stamp_ns], [sample]
            return
        i = bisect.bisect_left(edge.stamps, stamp_ns)
        if i < len(edge.stamps) and edge.stamps[i] == stamp_ns:
            edge.samples[i] = sample
        else:
            edge.stamps.insert(i, stamp_ns)
            edge.samples.insert(i, sample)
        self.latest_ns = stamp_ns if self.latest_ns is None else max(self.latest_ns, stamp_ns)

    def latest_common_ns(self, target: str, source: str) -> int | None:
        """tf2's "time 0": the newest stamp at which every dynamic transform from ``source`` up
        to ``target`` can be looked up (None: the chain is all static, or broken)."""
        latest: int | None = None
        frame, hops = source, 0
        while frame != target:
            edge = self._edges.get(frame)
            if edge is None or hops > len(self._edges):
                return None
            if not edge.static:
                latest = edge.stamps[-1] if latest is None else min(latest, edge.stamps[-1])
            frame, hops = edge.parent, hops + 1
        return latest

    def forget_before(self, stamp_ns: int) -> None:
        """Drops dynamic samples older than ``stamp_ns`` but the last of each edge (a live
        buffer, as tf2's cache time, stays bounded)."""
        for edge in self._edges.values():
            if edge.static:
                continue
            i = min(bisect.bisect_left(edge.stamps, stamp_ns), len(edge.stamps) - 1)
            if i > 0:
                del edge.stamps[:i], edge.samples[:i]

    def lookup(self, target: str, source: str, stamp_ns: int) -> Vec:
        """T_target_source: maps points in ``source`` to ``target`` (an ancestor of it)."""
        out = np.eye(4)
        frame, chain = source, [source]
        while frame != target:
            edge = self._edges.get(frame)
            if edge is None:
                known = ", ".join(
                    sorted(set(self._edges) | {e.parent for e in self._edges.values()})
                )
                raise TransformError(
                    f"no transform from {source} to {target}: {' → '.join(chain)} ends at "
                    f"{frame}, which has no parent in /tf or /tf_static (frames: {known or 'none'})"
                )
            out = edge.at(stamp_ns, frame) @ out
            frame = edge.parent
            chain.append(frame)
            if len(chain) > len(self._edges) + 1:
                raise TransformError(f"TF has a cycle: {' → '.join(chain)}")
        return out
