"""One clock per run: a recorder's receive time mapped onto the agent's clock.

A bag stores each message with the time the recorder *received* it. ``objsearch record`` writes
that time equal to each message's header stamp, so the two agree. A bag made by any other
recorder need not: ``rosbag play -r 20`` → ``rosbag record`` keeps every message's header stamp
(the agent's clock: 2026-01-01 + simulated time, or the robot's) but receives it on the recorder's
wall clock, 20 times faster. The agent's events carry both (their header stamp and their receive
time), so they give the map from one clock to the other: ``stamp ≈ stamp_ns + rate · (t −
recv_ns)``, fitted by least squares. Every derived event (poses, detections) is put on the agent's
clock with it; its ``recorded_at_ns`` keeps the receive time.

A derived event's time is its message's header stamp — what was recorded, the same in every
recording of that message — wherever the stamp can be trusted to be on the agent's clock: within
:data:`STAMP_TOLERANCE_NS` of the message's receive time mapped onto it (:func:`event_times`).
Elsewhere (no stamp; a stamp on another clock, or damaged) it is the mapped receive time, as
before. In a bag with no agent clock (no stamped agent events) the stamp is taken as it is: a
session that the bag joins later checks it against the session's clock.

A bag keeps at most :data:`MAX_PAIRS` of its (receive time, stamp) pairs in its report, spread
evenly over it, and is mapped with the fit over those; a session of several pieces (a split
recording) is mapped with the fit over all its pieces' pairs, so a piece whose few events span no
time (which gives no rate) is mapped like the rest of its recording. :func:`iso` prints a time
on either clock.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any, Final

import numpy as np
from numpy.typing import NDArray

Ints = NDArray[np.int64]
Bools = NDArray[np.bool_]

MAX_PAIRS: Final = 64
#: A header stamp farther than this from its message's receive time on the agent's clock is not
#: taken as the message's time. The recorder's delivery jitter times the playback rate stays
#: well inside it (272 ms at worst on the fixture played at 20×); a clock of another origin is
#: far outside it.
STAMP_TOLERANCE_NS: Final = 1_000_000_000


@dataclass(frozen=True, slots=True)
class ClockMap:
    """``receive time → recv_ns`` is mapped to ``stamp_ns``; ``rate`` agent ns per receive ns."""

    recv_ns: int
    stamp_ns: int
    rate: float
    events: int  # agent events it was fitted over
    residual_ns: int  # the largest |stamp − map(receive time)| among them
    #: False when the events span no time on one of the clocks: the rate is then 1 (an offset
    #: alone), until a session fits its pieces' events together.
    rate_fitted: bool = True

    def at(self, ns: int) -> int:
        return self.stamp_ns + round(self.rate * (ns - self.recv_ns))

    def apply(self, ns: Ints) -> Ints:
        delta = (ns - self.recv_ns).astype(np.float64) * self.rate
        return self.stamp_ns + np.rint(delta).astype(np.int64)

    def describe(self) -> str:
        if not self.rate_fitted:
            return (
                f"receive times moved onto the agent's clock (the events' header stamps) by an "
                f"offset alone: its {self.events} agent event(s) span no time, so they give no "
                "rate (in a session's run, the fit over all its pieces applies)"
            )
        return (
            f"receive times mapped onto the agent's clock (the events' header stamps): "
            f"rate {self.rate:.6g}, fitted over {self.events} agent event(s), "
            f"largest residual {self.residual_ns / 1e6:.3f} ms"
        )


def kept_pairs(pairs: Iterable[tuple[int, int]]) -> tuple[tuple[int, int], ...]:
    """At most :data:`MAX_PAIRS` of ``pairs``, in receive-time order, evenly spread, the first
    and last kept."""
    ordered = sorted(set(pairs))
    if len(ordered) <= MAX_PAIRS:
        return tuple(ordered)
    picks = np.linspace(0, len(ordered) - 1, MAX_PAIRS).round().astype(np.int64)
    return tuple(ordered[i] for i in sorted(set(picks.tolist())))


def pairs_from_doc(doc: Any) -> list[tuple[int, int]]:
    """A report's ``clock_pairs`` (JSON lists, or tuples before it was written) back as pairs;
    nothing for anything else."""
    if not isinstance(doc, list | tuple):
        return []
    pairs = []
    for item in doc:
        if isinstance(item, list | tuple) and len(item) == 2:
            try:
                pairs.append((int(item[0]), int(item[1])))
            except (TypeError, ValueError):
                continue
    return pairs


def fit_clock(pairs: Iterable[tuple[int, int]]) -> ClockMap | None:
    """The map from (receive time, header stamp) pairs, or None when the two clocks agree on
    every pair (nothing to map) or there are no pairs."""
    pairs = sorted(set(pairs))
    if not pairs or all(recv == stamp for recv, stamp in pairs):
        return None
    recv = np.array([p[0] for p in pairs], dtype=np.int64)
    stamp = np.array([p[1] for p in pairs], dtype=np.int64)
    # Centred on the first pair in integers, so the floats hold differences, not epoch ns.
    x = (recv - recv[0]).astype(np.float64)
    y = (stamp - stamp[0]).astype(np.float64)
    x_mean, y_mean = float(x.mean()), float(y.mean())
    spread = float(((x - x_mean) ** 2).sum())
    rate = float(((x - x_mean) * (y - y_mean)).sum() / spread) if spread > 0 else 0.0
    fitted = rate > 0  # none, or a clock running backwards (no recorder's): an offset alone
    rate = rate if fitted else 1.0
    recv_ns = int(recv[0]) + round(x_mean)
    stamp_ns = int(stamp[0]) + round(y_mean)
    clock = ClockMap(recv_ns, stamp_ns, rate, len(pairs), 0, fitted)
    return dataclasses.replace(clock, residual_ns=int(np.abs(clock.apply(recv) - stamp).max()))


def iso(ns: int) -> str:
    """A time (ns since the epoch) as reports print it: ISO 8601, UTC, to the millisecond."""
    import datetime as dt

    return dt.datetime.fromtimestamp(ns / 1e9, dt.UTC).isoformat(timespec="milliseconds")


def event_times(received: Ints, stamps: Ints, clock: ClockMap | None) -> tuple[Ints, Bools]:
    """Derived events' times from their messages' receive times and header stamps (0: none),
    and which of them took the stamp: the stamp where it is within :data:`STAMP_TOLERANCE_NS`
    of the receive time on ``clock``, else that mapped receive time. Without a clock fitted
    with a rate (no agent events, or events spanning no time), nothing can check a stamp: it
    is taken wherever there is one."""
    mapped = received if clock is None else clock.apply(received)
    took: Bools = stamps > 0
    if clock is not None and clock.rate_fitted:
        took &= np.abs(stamps - mapped) <= STAMP_TOLERANCE_NS
    times: Ints = np.where(took, stamps, mapped).astype(np.int64)
    return times, took


def on_receive_clock(time: Ints, received: Ints, clock: ClockMap | None) -> Bools:
    """Which derived rows' times are their receive times (as they are, or mapped by ``clock``,
    the clock they were put on) rather than header stamps: the rows a session maps again."""
    same: Bools = time == received
    return same if clock is None else same | (time == clock.apply(received))


def clock_from_doc(doc: Any) -> ClockMap | None:
    """A :class:`ClockMap` from its JSON (``dataclasses.asdict``); None for anything else."""
    if not isinstance(doc, dict):
        return None
    try:
        return ClockMap(
            int(doc["recv_ns"]),
            int(doc["stamp_ns"]),
            float(doc["rate"]),
            int(doc["events"]),
            int(doc["residual_ns"]),
            bool(doc.get("rate_fitted", True)),
        )
    except (KeyError, TypeError, ValueError):
        return None
