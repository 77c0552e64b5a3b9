"""Where the command line's options point on the network (argparse ``type=`` converters): hosts,
ports, ``HOST:PORT``, Zenoh endpoints and Ray addresses. Re-exported by :mod:`objsearch.cli_types`.
"""

from __future__ import annotations

import argparse
import ipaddress
import re

from objsearch.cli_values import text

_HOSTNAME = re.compile(r"[A-Za-z0-9](?:[A-Za-z0-9-]{0,62})(?:\.[A-Za-z0-9](?:[A-Za-z0-9-]{0,62}))*")


def _host(value: str, whole: str) -> str:
    try:
        ipaddress.ip_address(value)
    except ValueError:
        if len(value) > 253 or not _HOSTNAME.fullmatch(value):
            raise argparse.ArgumentTypeError(
                f"{whole!r}: {value!r} is not a host name or IP address"
            ) from None
    return value


def _port(value: str, whole: str) -> int:
    if not value.isdigit() or not 0 <= int(value) <= 65535:
        raise argparse.ArgumentTypeError(f"{whole!r}: the port must be a number 0-65535")
    return int(value)


def split_host_port(value: str, *, host_optional: bool = False) -> tuple[str | None, int]:
    """``HOST:PORT``, ``[IPv6]:PORT`` (or ``PORT`` alone with ``host_optional``)."""
    host, sep, port = value.rpartition(":")
    if not sep:
        if not host_optional:
            raise argparse.ArgumentTypeError(f"expected HOST:PORT, not {value!r}")
        return None, _port(port, value)
    if host.startswith("[") and host.endswith("]"):
        host = host[1:-1]
        try:
            ipaddress.IPv6Address(host)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"{value!r}: {host!r} is not an IPv6 address"
            ) from None
        return host, _port(port, value)
    if not host or ":" in host:
        raise argparse.ArgumentTypeError(
            f"expected {'[HOST:]PORT' if host_optional else 'HOST:PORT'} "
            f"(IPv6 as [addr]:PORT), not {value!r}"
        )
    return _host(host, value), _port(port, value)


def host_port(value: str) -> str:
    """``HOST:PORT`` (IPv6 as ``[addr]:PORT``)."""
    split_host_port(value)
    return value


def optional_host_port(value: str) -> str:
    """``PORT`` or ``HOST:PORT`` (IPv6 as ``[addr]:PORT``)."""
    split_host_port(value, host_optional=True)
    return value


def host(value: str) -> str:
    """A host name or an IP address."""
    return _host(text(value), value)


#: Zenoh locator protocols whose address is HOST:PORT.
_IP_PROTOCOLS = frozenset({"tcp", "udp", "tls", "quic", "ws"})
_OTHER_PROTOCOLS = frozenset({"unixsock-stream", "unixpipe", "serial", "vsock"})


def zenoh_endpoint(value: str) -> str:
    """A zenoh endpoint ``PROTO/ADDRESS`` such as ``tcp/127.0.0.1:7447`` or ``tcp/[::1]:7447``."""
    proto, sep, rest = value.partition("/")
    address = rest.split("?", 1)[0].split("#", 1)[0]
    if not sep or not address:
        raise argparse.ArgumentTypeError(
            f"expected a zenoh endpoint PROTO/ADDRESS such as tcp/127.0.0.1:7447, not {value!r}"
        )
    if proto in _IP_PROTOCOLS:
        split_host_port(address)
    elif proto not in _OTHER_PROTOCOLS:
        known = ", ".join(sorted(_IP_PROTOCOLS | _OTHER_PROTOCOLS))
        raise argparse.ArgumentTypeError(f"{value!r}: unknown protocol {proto!r} (known: {known})")
    return value


def ray_address(value: str) -> str:
    """A Ray cluster address: ``auto``, ``local``, ``HOST:PORT`` or ``ray://HOST:PORT``."""
    if value in ("auto", "local"):
        return value
    rest = value.removeprefix("ray://")
    split_host_port(rest)
    return value
