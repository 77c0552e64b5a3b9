"""Keep a UDP socket bound to the wildcard address to the datagrams sent to one address.

Cyclone DDS (11.0.1, and master as of this writing) binds its unicast *receive* sockets to
``0.0.0.0`` whatever ``General/Interfaces`` says (``ddsi_udp_create_conn``: ``bind_to_any`` for
``DDSI_TRAN_QOS_RECV_UC``; eclipse-cyclonedds/cyclonedds issues #1923 and #2090), and has no
option to bind them to the interface's address. Only its transmit socket is bound to the
interface. So after the participant is up, :func:`restrict` attaches a classic BPF socket filter
(``SO_ATTACH_FILTER``, Linux) to each wildcard-bound UDP socket it opened: the kernel then
delivers only datagrams whose IPv4 destination is the configured interface's address, which is
what binding to that address would do for receiving (a datagram to another address of the host,
from this host or any other, is discarded before Cyclone reads it).
"""

from __future__ import annotations

import ctypes
import fcntl
import ipaddress
import os
import socket
import struct
import sys
from dataclasses import dataclass
from pathlib import Path

from objsearch.runtime.errors import TransportError

SO_ATTACH_FILTER = 26  # also SO_GET_FILTER
SIOCGIFADDR = 0x8915
_SKF_NET_OFF = -0x100000  # BPF loads relative to the network (IP) header
_IPV4_DST = 16  # the destination address's offset in an IPv4 header


def interface_address(interface: str) -> str:
    """The IPv4 address of ``interface`` (a name such as ``lo`` or ``eth0``, or an address)."""
    try:
        return str(ipaddress.IPv4Address(interface))
    except ValueError:
        pass
    if not interface or len(interface) > 15 or not interface.isprintable() or "/" in interface:
        raise TransportError(f"{interface!r} is neither an IPv4 address nor an interface name")
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            packed = struct.pack("256s", interface.encode())
            return socket.inet_ntoa(fcntl.ioctl(s.fileno(), SIOCGIFADDR, packed)[20:24])
    except OSError as exc:
        raise TransportError(
            f"interface {interface!r} has no IPv4 address here ({exc.strerror or exc})"
        ) from None


def program(address: str) -> bytes:
    """``accept if ip.dst == address else drop``, as ``struct sock_filter`` instructions."""
    dst = int(ipaddress.IPv4Address(address))
    ld_abs_w, jeq_k, ret_k = 0x20, 0x15, 0x06
    return b"".join(
        struct.pack("HBBI", code, jt, jf, k)
        for code, jt, jf, k in (
            (ld_abs_w, 0, 0, (_SKF_NET_OFF + _IPV4_DST) & 0xFFFFFFFF),
            (jeq_k, 0, 1, dst),
            (ret_k, 0, 0, 0xFFFFFFFF),
            (ret_k, 0, 0, 0),
        )
    )


def attach(sock: socket.socket, address: str) -> None:
    code = program(address)
    buf = ctypes.create_string_buffer(code, len(code))
    fprog = struct.pack("HP", len(code) // 8, ctypes.addressof(buf))
    sock.setsockopt(socket.SOL_SOCKET, SO_ATTACH_FILTER, fprog)


def attached(fd: int) -> bytes:
    """The filter on socket ``fd``, as :func:`program` returns it (empty if none).

    Through libc: ``SO_GET_FILTER`` counts its length in instructions, not bytes, which
    ``socket.getsockopt`` cannot express."""
    blocks = 64
    buf = ctypes.create_string_buffer(blocks * 8)
    length = ctypes.c_uint32(blocks)
    libc = ctypes.CDLL(None, use_errno=True)
    if libc.getsockopt(fd, socket.SOL_SOCKET, SO_ATTACH_FILTER, buf, ctypes.byref(length)):
        return b""
    return buf.raw[: length.value * 8]


@dataclass(frozen=True, slots=True)
class UdpSocket:
    fd: int
    inode: str
    address: str
    port: int


def udp_sockets() -> list[UdpSocket]:
    """This process's IPv4 UDP sockets (from ``/proc``), with their local address and port."""
    if not sys.platform.startswith("linux"):
        raise TransportError(
            "restricting DDS to one interface needs Linux (/proc, SO_ATTACH_FILTER)"
        )
    inodes: dict[str, int] = {}
    for fd in os.listdir("/proc/self/fd"):
        try:
            target = os.readlink(f"/proc/self/fd/{fd}")
        except OSError:
            continue
        if target.startswith("socket:["):
            inodes.setdefault(target[8:-1], int(fd))
    found = []
    for line in Path("/proc/net/udp").read_text().splitlines()[1:]:
        fields = line.split()
        local, inode = fields[1], fields[9]
        if inode in inodes:
            hex_ip, hex_port = local.split(":")
            address = socket.inet_ntoa(struct.pack("<I", int(hex_ip, 16)))
            found.append(UdpSocket(inodes[inode], inode, address, int(hex_port, 16)))
    return found


def restrict(address: str, before: set[str]) -> list[UdpSocket]:
    """Filter every wildcard-bound UDP socket opened since ``before`` (a set of inodes) to
    datagrams for ``address``; returns them."""
    done = []
    for s in udp_sockets():
        if s.inode in before or s.address != "0.0.0.0":
            continue
        sock = socket.socket(fileno=os.dup(s.fd))
        try:
            attach(sock, address)
        except OSError as exc:
            raise TransportError(
                f"cannot restrict DDS port {s.port} to {address}: {exc.strerror or exc}"
            ) from None
        finally:
            sock.close()
        done.append(s)
    return done
