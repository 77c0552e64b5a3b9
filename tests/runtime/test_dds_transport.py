"""The DDS transport listens on the configured interface only: every UDP socket Cyclone DDS opens
for it is bound to the interface's address, or (its receive sockets, which Cyclone always binds
to 0.0.0.0) filtered to datagrams for that address."""

from __future__ import annotations

import itertools
import os
import sys

import pytest

pytest.importorskip("cyclonedds")

from objsearch.runtime.dds_transport import domain_xml
from objsearch.runtime.errors import TransportError
from objsearch.runtime.transport import Backend, TransportConfig, open_transport
from objsearch.runtime.udpfilter import attached, program, udp_sockets

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")

_domains = itertools.count(150 + os.getpid() % 50)


@pytest.mark.parametrize("interface", ["lo", "127.0.0.1"])
def test_no_socket_listens_beyond_the_interface(interface: str) -> None:
    before = {s.inode for s in udp_sockets()}
    config = TransportConfig(
        backend=Backend.DDS, domain_id=next(_domains) % 232, interface=interface
    )
    transport = open_transport(config)
    try:
        opened = [s for s in udp_sockets() if s.inode not in before]
        assert opened, "Cyclone DDS opened no UDP socket?"
        wildcard = [s for s in opened if s.address == "0.0.0.0"]
        assert {s.address for s in opened} <= {"127.0.0.1", "0.0.0.0"}
        for s in wildcard:  # Cyclone's receive sockets: each carries the filter
            assert attached(s.fd) == program("127.0.0.1"), s
        assert {s.inode for s in wildcard} == {s.inode for s in transport.restricted}  # type: ignore[attr-defined]
        assert any(s.address == "127.0.0.1" for s in opened)  # the transmit socket
    finally:
        transport.close()


def test_a_bad_interface_is_a_clear_error() -> None:
    config = TransportConfig(backend=Backend.DDS, domain_id=next(_domains) % 232, interface="nic9")
    with pytest.raises(TransportError, match="'nic9' has no IPv4 address"):
        open_transport(config)


def test_domain_xml_names_the_address_and_escapes_peers() -> None:
    xml = domain_xml(TransportConfig(peers=('10.0.0.2"/><Evil x="',)), "127.0.0.1")
    assert '<NetworkInterface address="127.0.0.1"/>' in xml
    assert "<AllowMulticast>false</AllowMulticast>" in xml
    assert "<Evil" not in xml.replace("&lt;Evil", "")
