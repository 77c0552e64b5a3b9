"""The socket filter that keeps a wildcard-bound UDP socket to one destination address, tried
with real datagrams on loopback (127.0.0.2 is this host too, but not 127.0.0.1)."""

from __future__ import annotations

import socket
import sys

import pytest

from objsearch.runtime.errors import TransportError
from objsearch.runtime.udpfilter import attach, attached, interface_address, program, udp_sockets

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="Linux only")


def received(receiver: socket.socket, to: str) -> bytes | None:
    port = receiver.getsockname()[1]
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sender:
        sender.sendto(to.encode(), (to, port))
    try:
        return receiver.recv(100)
    except TimeoutError:
        return None


def wildcard_socket() -> socket.socket:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("0.0.0.0", 0))
    s.settimeout(0.5)
    return s


def test_without_the_filter_a_wildcard_socket_takes_any_destination() -> None:
    with wildcard_socket() as s:
        assert received(s, "127.0.0.2") == b"127.0.0.2"
        assert attached(s.fileno()) == b""


def test_the_filter_keeps_only_datagrams_for_its_address() -> None:
    with wildcard_socket() as s:
        attach(s, "127.0.0.1")
        assert attached(s.fileno()) == program("127.0.0.1")
        assert received(s, "127.0.0.2") is None
        assert received(s, "127.0.0.1") == b"127.0.0.1"
        assert received(s, "127.0.0.3") is None


def test_interface_address() -> None:
    assert interface_address("lo") == "127.0.0.1"
    assert interface_address("127.0.0.1") == "127.0.0.1"
    for bad in ["no-such-nic0", "", "a" * 40, "eth0/1", "1.2.3.256"]:
        with pytest.raises(TransportError, match=r"interface|address"):
            interface_address(bad)


def test_udp_sockets_lists_this_process_sockets() -> None:
    with wildcard_socket() as s:
        port = s.getsockname()[1]
        mine = [u for u in udp_sockets() if u.port == port]
        assert [(u.fd, u.address) for u in mine] == [(s.fileno(), "0.0.0.0")]
