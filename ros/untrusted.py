"""The one place where bytes from outside meet a third-party decoder.

rosbags' readers and CDR deserialiser, rclpy's and Cyclone DDS's raise assorted errors on short,
garbled or damaged input (``struct.error``, ``IndexError``, ``UnicodeDecodeError``,
``ValueError``, their own classes …), and so does the code that reads the fields of a message
decoded from such bytes. Each caller decides what a failure means — a bag's message is counted
as rejected, a bag is salvaged by scanning instead, a malformed message becomes a
``MessageError`` — but none lets it escape as a traceback: :func:`attempt` is that boundary.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar

T = TypeVar("T")


def attempt(step: Callable[[], T]) -> T | Exception:
    """``step()``, or the exception it raised (never raised here: the caller records it)."""
    try:
        return step()
    except Exception as exc:  # boundary: outside bytes in a third-party decoder raise anything
        return exc
