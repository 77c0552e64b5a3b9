"""The DDS transport listens on the configured interface only: every UDP socket Cyclone DDS opens
for it is bound to the interface's address, or (its receive sockets, which Cyclone always binds
to 0.0.0.0) filtered to datagrams for that address. A process that writes a topic it reads never
hangs on its own handler."""

from __future__ import annotations

import itertools
import os
import subprocess
import sys
import time

import pytest

pytest.importorskip("cyclonedds")

from objsearch.ros.qos import DEFAULT
from objsearch.runtime import messages as m
from objsearch.runtime.backends import open_transport
from objsearch.runtime.dds_transport import domain_xml
from objsearch.runtime.errors import TransportError
from objsearch.runtime.node import Node
from objsearch.runtime.transport import Backend, TransportConfig
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


#: A process that reads ``/chatter`` and writes it too, as an agent does its heartbeats: once a
#: message from another process is in its handler (which then waits a moment, as a handler may),
#: it writes one of its own. It prints what its handler heard.
WRITES_WHAT_IT_READS = """
import sys, threading
from objsearch.ros.qos import DEFAULT
from objsearch.runtime import messages as m
from objsearch.runtime.node import Node
from objsearch.runtime.transport import Backend, TransportConfig
from objsearch.runtime.backends import open_transport

config = TransportConfig(backend=Backend.DDS, domain_id=int(sys.argv[1]), node="agent")
node = Node(open_transport(config))
entered, release, heard = threading.Event(), threading.Event(), []

def on_message(msg):
    heard.append(msg.data)
    if not entered.is_set():
        entered.set()
        release.wait(2.0)

node.subscribe("/chatter", m.STRING, DEFAULT, on_message)
own = node.publisher("/chatter", m.STRING, DEFAULT)
print("ready", flush=True)
assert entered.wait(120), "nothing came from the other process"
own.publish(m.json_string({"from": "agent"}))
release.set()
print("wrote; heard", sorted(set(heard)), flush=True)
node.transport.close()
"""


def test_a_process_writing_a_topic_it_reads_never_waits_for_its_own_handler() -> None:
    """Before, the write was delivered to the process's own reader in the writing thread, which
    waited for the handler another process's message was in, while holding the GIL that handler
    needed: the process hung for good (an agent's heartbeats, issue 43 item 9). Now a reader
    never hears its own participant, as a ROS 2 node asked to ignore local publications."""
    domain = next(_domains) % 232
    proc = subprocess.Popen(
        [sys.executable, "-c", WRITES_WHAT_IT_READS, str(domain)],
        stdout=subprocess.PIPE,
        text=True,
    )
    assert proc.stdout is not None
    try:
        assert proc.stdout.readline() == "ready\n"
        other = Node(open_transport(TransportConfig(Backend.DDS, domain_id=domain, node="other")))
        try:
            pub = other.publisher("/chatter", m.STRING, DEFAULT)
            deadline = time.monotonic() + 120
            while proc.poll() is None and time.monotonic() < deadline:
                pub.publish(m.json_string({"from": "other"}))
                time.sleep(0.05)
        finally:
            other.transport.close()
        assert proc.poll() == 0, "the process hung writing what it reads"
        out = proc.stdout.read()
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.wait()
    assert """wrote; heard ['{"from":"other"}']""" in out, out
