"""ROS 2 over Zenoh the way ``rmw_zenoh_cpp`` does it (see docs/runtime.md for the sources).

* key expression ``<domain>/<topic without leading />/<pkg>::msg::dds_::<Name>_/RIHS01_<hash>``;
* a liveliness token per node, publisher and subscription under ``@ros2_lv/<domain>/…``;
* each sample carries an attachment: sequence number (int64 LE), source timestamp (ns since the
  epoch, int64 LE), the GID length (one byte, 16) and the publisher's 16-byte GID;
* a service is a queryable (declared complete) on ``<domain>/<service>/<pkg>::srv::dds_::Name_/
  RIHS01_<hash of the service type>``; a client's request is a ``get`` (target ALL_COMPLETE, no
  consolidation) with the attachment above carrying its sequence number and GID, and the reply
  echoes the sequence number and GID with its own timestamp. Tokens ``SS`` and ``SC``.
"""

from __future__ import annotations

import itertools
import json
import logging
import os
import struct
import threading
import time
from typing import Any

from objsearch.ros.qos import SERVICES, QoS
from objsearch.runtime.errors import TransportError
from objsearch.runtime.messages import dds_type_name, type_hash
from objsearch.runtime.transport import Handler, ServiceHandler, TransportConfig

GID_SIZE = 16
#: How often a client asks again while no server answers (discovery still under way).
RETRY_S = 0.2

log = logging.getLogger("objsearch.runtime")


def topic_key(domain_id: int, topic: str, msgtype: str) -> str:
    return f"{domain_id}/{topic.strip('/')}/{dds_type_name(msgtype)}/{type_hash(msgtype)}"


def mangle(name: str) -> str:
    return name.replace("/", "%")


def liveliness_key(
    domain_id: int,
    session_id: str,
    node_id: int,
    entity_id: int,
    kind: str,
    node: str,
    topic: str | None = None,
    msgtype: str | None = None,
    qos: QoS | None = None,
) -> str:
    """``@ros2_lv/<domain>/<session>/<node id>/<entity id>/<kind>/<enclave>/<ns>/<node>[/…]``."""
    key = f"@ros2_lv/{domain_id}/{session_id}/{node_id}/{entity_id}/{kind}/%/%/{node}"
    if topic is None or msgtype is None or qos is None:
        return key
    return f"{key}/{mangle('/' + topic.strip('/'))}/{dds_type_name(msgtype)}/{type_hash(msgtype)}/{qos.zenoh_key()}"


def attachment(seq: int, timestamp_ns: int, gid: bytes) -> bytes:
    if len(gid) != GID_SIZE:
        raise ValueError(f"a publisher GID has {GID_SIZE} bytes, not {len(gid)}")
    return struct.pack("<qqB", seq, timestamp_ns, GID_SIZE) + gid


def parse_attachment(data: bytes) -> tuple[int, int, bytes]:
    if len(data) != 17 + GID_SIZE or data[16] != GID_SIZE:
        raise ValueError(f"not an rmw_zenoh attachment ({len(data)} bytes)")
    seq, ts, _ = struct.unpack_from("<qqB", data)
    return seq, ts, data[17:]


class _ZenohPublisher:
    def __init__(self, transport: ZenohTransport, key: str, gid: bytes) -> None:
        self._pub = transport.session.declare_publisher(key)
        self._gid = gid
        self._seq = itertools.count(1)
        self._lock = threading.Lock()

    def publish(self, cdr: bytes) -> None:
        with self._lock:
            seq = next(self._seq)
        self._pub.put(cdr, attachment=attachment(seq, time.time_ns(), self._gid))


class _ZenohClient:
    def __init__(self, transport: ZenohTransport, key: str, gid: bytes) -> None:
        self._transport = transport
        self._key = key
        self._gid = gid
        self._seq = itertools.count(1)
        self._lock = threading.Lock()

    def call(self, request: bytes, timeout_s: float) -> bytes | None:
        import zenoh

        deadline = time.monotonic() + timeout_s
        while (left := deadline - time.monotonic()) > 0:
            with self._lock:
                seq = next(self._seq)
            start = time.monotonic()
            replies = self._transport.session.get(
                self._key,
                payload=request,
                attachment=attachment(seq, time.time_ns(), self._gid),
                target=zenoh.QueryTarget.ALL_COMPLETE,
                consolidation=zenoh.ConsolidationMode.NONE,
                timeout=left,
            )
            for reply in replies:
                if reply.ok is not None:
                    return bytes(reply.ok.payload.to_bytes())
            # No server yet (the get ends at once): wait a little and ask again.
            time.sleep(max(0.0, RETRY_S - (time.monotonic() - start)))
        return None


class ZenohTransport:
    def __init__(self, config: TransportConfig) -> None:
        try:
            import zenoh
        except ImportError as exc:  # the `robot` extra
            raise TransportError(
                "the zenoh transport needs eclipse-zenoh: pip install 'objsearch[robot]'"
            ) from exc
        self.config = config
        conf = zenoh.Config()
        conf.insert_json5("mode", json.dumps(config.mode))
        conf.insert_json5("scouting/multicast/enabled", "false")
        conf.insert_json5("connect/endpoints", json.dumps(list(config.connect)))
        conf.insert_json5("listen/endpoints", json.dumps(list(config.listen)))
        for path, value in config.extra.items():
            conf.insert_json5(path, value)
        try:
            self.session: Any = zenoh.open(conf)
        except zenoh.ZError as exc:  # bad endpoint, port taken, no router
            raise TransportError(
                f"cannot open a zenoh session ({config.mode}, connect {list(config.connect)}, "
                f"listen {list(config.listen)}): {exc}"
            ) from exc
        self.session_id = str(self.session.info.zid())
        self._entities = itertools.count(10)
        self._tokens: list[Any] = [self._token(0, "NN")]
        self._subscribers: list[Any] = []
        self._closed = False
        routers = [str(z) for z in self.session.info.routers_zid()]
        # On a shared host the default endpoint and domain may be someone else's router: say
        # exactly what was joined, so a stranger's graph is noticed.
        log.info(
            "joined zenoh as %s %s, ROS domain %d: connect %s, listen %s; routers reached: %s",
            config.mode,
            self.session_id,
            config.domain_id,
            ", ".join(config.connect) or "none",
            ", ".join(config.listen) or "none",
            ", ".join(routers) or "none yet",
        )

    def _token(self, entity_id: int, kind: str, *args: Any) -> Any:
        key = liveliness_key(
            self.config.domain_id, self.session_id, 0, entity_id, kind, self.config.node, *args
        )
        return self.session.liveliness().declare_token(key)

    def publisher(self, topic: str, msgtype: str, qos: QoS) -> _ZenohPublisher:
        entity = next(self._entities)
        self._tokens.append(self._token(entity, "MP", topic, msgtype, qos))
        return _ZenohPublisher(
            self, topic_key(self.config.domain_id, topic, msgtype), self._gid(entity)
        )

    def subscribe(self, topic: str, msgtype: str, qos: QoS, handler: Handler) -> None:
        entity = next(self._entities)
        self._tokens.append(self._token(entity, "MS", topic, msgtype, qos))

        def on_sample(sample: Any) -> None:
            handler(bytes(sample.payload.to_bytes()))

        key = topic_key(self.config.domain_id, topic, msgtype)
        self._subscribers.append(self.session.declare_subscriber(key, on_sample))

    def serve(self, service: str, srvtype: str, handler: ServiceHandler) -> None:
        entity = next(self._entities)
        self._tokens.append(self._token(entity, "SS", service, srvtype, SERVICES))
        gid = self._gid(entity)

        def on_query(query: Any) -> None:
            try:
                seq, _, client_gid = parse_attachment(bytes(query.attachment.to_bytes()))
            except (AttributeError, ValueError):  # not a ROS 2 client: answer it all the same
                seq, client_gid = 0, gid
            payload = query.payload
            request = bytes(payload.to_bytes()) if payload is not None else b""
            lock = threading.Lock()

            def respond(response: bytes) -> None:
                # Kept alive by this closure until answered (get_result answers late); the
                # query is finished (dropped) right after its one reply.
                with lock:
                    query.reply(
                        query.key_expr,
                        response,
                        attachment=attachment(seq, time.time_ns(), client_gid),
                    )
                    query.drop()

            handler(request, respond)

        key = topic_key(self.config.domain_id, service, srvtype)
        self._subscribers.append(self.session.declare_queryable(key, on_query, complete=True))

    def client(self, service: str, srvtype: str) -> _ZenohClient:
        entity = next(self._entities)
        self._tokens.append(self._token(entity, "SC", service, srvtype, SERVICES))
        return _ZenohClient(
            self, topic_key(self.config.domain_id, service, srvtype), self._gid(entity)
        )

    def reachable(self) -> int:
        """How many zenoh routers and peers this session is connected to right now (0: nobody
        to talk to, e.g. no router at the ``connect`` endpoints)."""
        info = self.session.info
        return len(list(info.routers_zid())) + len(list(info.peers_zid()))

    def _gid(self, entity: int) -> bytes:
        return (self.session_id.encode() + entity.to_bytes(4, "little") + os.urandom(16))[:GID_SIZE]

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        for token in self._tokens:
            token.undeclare()
        self.session.close()
