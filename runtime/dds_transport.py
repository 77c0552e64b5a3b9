"""ROS 2 over Cyclone DDS the way ``rmw_cyclonedds_cpp`` does it.

Topic ``/pose`` is DDS topic ``rt/pose``; the type is registered under rosidl's DDS name
(``geometry_msgs::msg::dds_::PoseStamped_``) with the same members, so a ROS 2 node's reader and
writer match ours; QoS maps one to one (a best-effort writer never meets a reliable reader, a
volatile writer never meets a transient-local reader). The Python binding serialises typed
samples, so each message type is declared from its rosbags definition and the CDR bytes
round-trip through it (they are identical: tested).

A service ``/svc`` is the topic pair ``rq/svcRequest`` and ``rr/svcReply`` with types
``pkg::srv::dds_::Name_Request_`` / ``_Response_`` (``pkg::action::dds_::…`` for an action's
services), each sample led by rmw_cyclonedds_cpp's ``cdds_request_header_t``: the client's 64-bit
id (its request writer's instance handle there) and a 64-bit sequence number, both echoed in the
reply; the client keeps only replies carrying its own id. As the header is 16 bytes, the message
that follows keeps its CDR alignment, so the wire bytes are the encapsulation header, the two
numbers (little endian) and the message's own CDR body.
"""

from __future__ import annotations

import itertools
import logging
import os
import struct
import threading
import time
from collections.abc import Sequence
from functools import cache
from typing import Any
from xml.sax.saxutils import quoteattr

from objsearch.ros.qos import SERVICES, Durability, QoS, Reliability
from objsearch.ros.untrusted import attempt
from objsearch.runtime.errors import MessageError, TransportError
from objsearch.runtime.messages import dds_type_name, store, type_hash
from objsearch.runtime.transport import Handler, ServiceHandler, TransportConfig
from objsearch.runtime.udpfilter import interface_address, restrict, udp_sockets

#: How often a client sends its request again while unanswered (discovery still under way).
RETRY_S = 0.5
#: Samples taken per read; a listener loops until the reader is empty.
BATCH = 64

log = logging.getLogger("objsearch.runtime")

#: DDS QoS policy ids (the DDS specification's numbering, Cyclone's ``dds_qos_policy_id_t``), as
#: The RTPS vendor id eProsima's Fast DDS puts at the head of its GUIDs (OMG's vendor list).
FAST_DDS_VENDOR = b"\x01\x0f"
#: an incompatible-QoS status names the last policy that failed to match.
POLICY_NAMES = {
    2: "durability",
    3: "presentation",
    4: "deadline",
    5: "latency budget",
    6: "ownership",
    8: "liveliness",
    10: "partition",
    11: "reliability",
    12: "destination order",
    25: "data representation",
}

_BASE = {
    "bool": "bool",
    "byte": "uint8",
    "char": "uint8",
    "int8": "int8",
    "uint8": "uint8",
    "int16": "int16",
    "uint16": "uint16",
    "int32": "int32",
    "uint32": "uint32",
    "int64": "int64",
    "uint64": "uint64",
    "float32": "float32",
    "float64": "float64",
}


def topic_name(topic: str) -> str:
    """ROS 2 topic → DDS topic (``rt/`` prefix, no leading slash)."""
    return "rt/" + topic.strip("/")


def _field_type(node: Any) -> Any:
    import cyclonedds.idl.types as t
    from rosbags.interfaces import Nodetype

    kind, detail = node
    if kind == Nodetype.BASE:
        name, bound = detail
        if name == "string":
            return t.bounded_str[bound] if bound else str  # type: ignore[misc]
        if name == "bool":
            return bool
        return getattr(t, _BASE[name])
    if kind == Nodetype.NAME:
        return idl_type(detail)
    if kind == Nodetype.ARRAY:
        sub, length = detail
        return t.array[_field_type(sub), length]  # type: ignore[misc]
    if kind == Nodetype.SEQUENCE:
        sub, bound = detail
        if bound:
            return t.sequence[_field_type(sub), bound]  # type: ignore[misc]
        return t.sequence[_field_type(sub)]  # type: ignore[misc]
    raise MessageError(f"unsupported field kind {kind!r}")


def service_topics(service: str) -> tuple[str, str]:
    """ROS 2 service → its request and reply topics (``rq/<svc>Request``, ``rr/<svc>Reply``)."""
    name = service.strip("/")
    return f"rq/{name}Request", f"rr/{name}Reply"


@cache
def idl_type(msgtype: str, *, request_header: bool = False) -> Any:
    """A Cyclone DDS struct with the ROS 2 type's DDS name and members (led by
    ``cdds_request_header_t`` for a service's request or response)."""
    import cyclonedds.idl.types as t
    from cyclonedds.idl import make_idl_struct

    try:
        _, fields = store().fielddefs[msgtype]
    except KeyError:
        raise MessageError(f"unknown message type {msgtype!r}") from None
    members = {name: _field_type(node) for name, node in fields}
    if request_header:
        members = {"client_guid_": t.uint64, "sequence_number_": t.int64, **members}
    cls_name = dds_type_name(msgtype).rsplit("::", 1)[1]
    return make_idl_struct(cls_name, dds_type_name(msgtype), members)


def wrap(cdr: bytes, guid: int, seq: int) -> bytes:
    """Message CDR → the same with ``cdds_request_header_t`` in front."""
    return cdr[:4] + struct.pack("<Qq", guid, seq) + cdr[4:]


def unwrap(data: bytes) -> tuple[int, int, bytes]:
    if len(data) < 20:
        raise MessageError(f"a service sample of {len(data)} bytes has no request header")
    guid, seq = struct.unpack_from("<Qq", data, 4)
    return guid, seq, data[:4] + data[20:]


def valid_samples(reader: Any) -> list[bytes]:
    """Everything ``reader`` holds, as CDR bytes, without the samples that carry no data.

    When a writer leaves (a node exits) or disposes an instance, DDS hands each reader an
    *invalid* sample — only a key and a changed instance state, which Cyclone's Python binding
    returns as an ``InvalidSample`` — in the same batch as the data around it. Those are skipped,
    never allowed to cost the valid samples of the batch."""
    out: list[bytes] = []
    if reader is None:  # the listener fired while the transport closed: the reader is gone
        return out
    while batch := reader.take(N=BATCH):
        out += [bytes(s.serialize()) for s in batch if s.sample_info.valid_data]
        if len(batch) < BATCH:
            break
    return out


def describe_qos(qos: QoS) -> str:
    return f"{qos.reliability.value}, {qos.durability.value}, depth {qos.depth}"


def _incompatible(what: str, name: str, qos: QoS) -> Any:
    """A listener argument that logs a QoS mismatch naming the topic, our QoS and the policy the
    peer disagrees on (each new mismatch once: ``total_count_change``)."""
    side, peer = (
        ("reader", "a writer offers") if what == "requested" else ("writer", "a reader requests")
    )

    def on_incompatible(entity: Any, status: Any) -> None:
        if status.total_count_change <= 0:
            return
        policy = POLICY_NAMES.get(status.last_policy_id, f"policy {status.last_policy_id}")
        log.warning(
            "QoS mismatch on %s: %s QoS this %s (%s) cannot match: %s differs "
            "(%d incompatible so far); nothing flows between them",
            name,
            peer,
            side,
            describe_qos(qos),
            policy,
            status.total_count,
        )

    return {f"on_{what}_incompatible_qos": on_incompatible}


def _qos(qos: QoS, type_hash: str | None = None, *, reader: bool = False) -> Any:
    """``type_hash``: announced in USER_DATA as rmw_cyclonedds and rmw_fastrtps do
    (``typehash=RIHS01_…;``), so ROS 2's graph shows the endpoint's type hash.

    A ``reader`` never hears its own participant's writers (``IgnoreLocal``). A sample written
    to a topic this participant also reads is delivered to our reader in the writing thread
    (Cyclone's local delivery), which first waits until no other thread is in that reader's
    listener; ``DataWriter.write`` keeps the GIL meanwhile (cyclonedds-python's ``ddspy_write``),
    and a listener that a sample from another process has entered waits for that GIL: neither
    moves again and the whole process hangs (an agent writing its heartbeat as another agent's
    came in, issue 43 item 9). A process has one participant per domain (Cyclone refuses a
    second), so with this no write of ours is delivered locally, and none waits on a listener."""
    from cyclonedds.core import Policy, Qos

    reliability = (
        Policy.Reliability.Reliable(max_blocking_time=100_000_000)
        if qos.reliability is Reliability.RELIABLE
        else Policy.Reliability.BestEffort
    )
    durability = (
        Policy.Durability.TransientLocal
        if qos.durability is Durability.TRANSIENT_LOCAL
        else Policy.Durability.Volatile
    )
    policies = [reliability, durability, Policy.History.KeepLast(qos.depth)]
    if type_hash is not None:
        policies.append(Policy.Userdata(f"typehash={type_hash};".encode()))
    if reader:
        policies.append(Policy.IgnoreLocal.Participant)
    return Qos(*policies)


#: ROS 2's graph topic (rmw_dds_common): each participant says which nodes it hosts and which
#: readers and writers belong to each, by GID; latched, one sample per participant.
DISCOVERY_TOPIC = "ros_discovery_info"


@cache
def discovery_type() -> Any:
    """``rmw_dds_common/msg/ParticipantEntitiesInfo`` as Iron and later define it (a GID is 16
    bytes: the DDS GUID; Humble's were 24)."""
    import cyclonedds.idl.types as t
    from cyclonedds.idl import make_idl_struct

    ns = "rmw_dds_common::msg::dds_::"
    gid = make_idl_struct("Gid_", f"{ns}Gid_", {"data": t.array[t.uint8, 16]})  # type: ignore[misc]
    node = make_idl_struct(
        "NodeEntitiesInfo_",
        f"{ns}NodeEntitiesInfo_",
        {
            "node_namespace": t.bounded_str[256],  # type: ignore[misc]
            "node_name": t.bounded_str[256],  # type: ignore[misc]
            "reader_gid_seq": t.sequence[gid],  # type: ignore[misc]
            "writer_gid_seq": t.sequence[gid],  # type: ignore[misc]
        },
    )
    return (
        make_idl_struct(
            "ParticipantEntitiesInfo_",
            f"{ns}ParticipantEntitiesInfo_",
            {"gid": gid, "node_entities_info_seq": t.sequence[node]},  # type: ignore[misc]
        ),
        gid,
        node,
    )


def _gid(entity: Any) -> bytes:
    return bytes(entity.guid.bytes)


def domain_xml(config: TransportConfig, address: str) -> str:
    """Unicast discovery on one interface, named by its IPv4 ``address`` (no multicast:
    containers and CI often lack it, and it would need sockets on every interface)."""
    peers = "".join(f"<Peer address={quoteattr(p)}/>" for p in config.peers)
    return (
        "<CycloneDDS><Domain><General>"
        f"<Interfaces><NetworkInterface address={quoteattr(address)}/></Interfaces>"
        "<AllowMulticast>false</AllowMulticast></General>"
        "<Discovery><ParticipantIndex>auto</ParticipantIndex>"
        f"<MaxAutoParticipantIndex>30</MaxAutoParticipantIndex><Peers>{peers}</Peers>"
        "</Discovery></Domain></CycloneDDS>"
    )


class _DdsPublisher:
    def __init__(self, writer: Any, cls: Any, msgtype: str) -> None:
        self._writer = writer
        self._cls = cls
        self._msgtype = msgtype

    def publish(self, cdr: bytes) -> None:
        sample = attempt(lambda: self._cls.deserialize(cdr))
        if isinstance(sample, Exception):
            raise MessageError(f"cannot publish malformed {self._msgtype}: {sample}") from None
        self._writer.write(sample)


class _DdsClient:
    def __init__(self, transport: DdsTransport, service: str, srvtype: str) -> None:
        from cyclonedds.core import Listener
        from cyclonedds.pub import DataWriter
        from cyclonedds.sub import DataReader

        rq, rr = service_topics(service)
        self.service = service
        self._req_cls = idl_type(f"{srvtype}_Request", request_header=True)
        self._guid = int.from_bytes(os.urandom(8), "little") >> 1
        self._seq = itertools.count(1)
        self._cond = threading.Condition()
        self._replies: dict[int, bytes] = {}
        self._writer = DataWriter(
            transport.participant,
            transport._topic(rq, self._req_cls),
            _qos(SERVICES, type_hash(srvtype)),
            listener=Listener(**_incompatible("offered", rq, SERVICES)),  # type: ignore[no-untyped-call]
        )
        resp_cls = idl_type(f"{srvtype}_Response", request_header=True)

        def on_data(reader: Any) -> None:
            for data in valid_samples(reader):
                guid, seq, body = unwrap(data)
                if guid == self._guid:  # replies to other clients share the topic
                    with self._cond:
                        self._replies[seq] = body
                        self._cond.notify_all()

        self._reader = DataReader(
            transport.participant,
            transport._topic(rr, resp_cls),
            _qos(SERVICES, type_hash(srvtype), reader=True),
            listener=Listener(  # type: ignore[no-untyped-call]
                on_data_available=on_data, **_incompatible("requested", rr, SERVICES)
            ),
        )
        transport._entities += [self._writer, self._reader]
        transport._announce(readers=[self._reader], writers=[self._writer])

    def why_unanswered(self) -> str | None:
        """Why no server answered, if the graph can tell: a server whose request reader this
        client's writer matched belongs to a Fast DDS participant (RTPS vendor id 0x010F at the
        head of its GUID), which cannot read rmw_cyclonedds' request header (it travels in the
        payload here; Fast DDS identifies requests in the RTPS inline QoS)."""
        vendors = set()
        for handle in self._writer.get_matched_subscriptions():
            data = self._writer.get_matched_subscription_data(handle)
            if data is not None:
                vendors.add(data.participant_key.bytes[:2])
        if FAST_DDS_VENDOR in vendors:
            return (
                f"the server of {self.service} is a Fast DDS node (rmw_fastrtps_cpp): the dds "
                "transport's services meet rmw_cyclonedds servers only; use --transport ros2 "
                "to call a Fast DDS robot's services (docs/runtime.md, the transport x "
                "capability matrix)"
            )
        if not vendors:
            return f"no server of {self.service} on the graph"
        return None

    def call(self, request: bytes, timeout_s: float) -> bytes | None:
        deadline = time.monotonic() + timeout_s
        sent: set[int] = set()
        with self._cond:
            while (left := deadline - time.monotonic()) > 0:
                seq = next(self._seq)
                sent.add(seq)
                self._writer.write(self._req_cls.deserialize(wrap(request, self._guid, seq)))
                self._cond.wait(min(RETRY_S, left))
                for s in sorted(sent & set(self._replies)):
                    return self._replies.pop(s)
        return None


class DdsTransport:
    def __init__(self, config: TransportConfig) -> None:
        try:
            from cyclonedds.core import DDSException
            from cyclonedds.domain import Domain, DomainParticipant
        except ImportError as exc:
            raise TransportError(
                "the dds transport needs cyclonedds: pip install 'objsearch[robot]'"
            ) from exc
        self.config = config
        self.address = interface_address(config.interface)
        before = {s.inode for s in udp_sockets()}
        try:
            self._domain = Domain(config.domain_id, domain_xml(config, self.address))
            self.participant: Any = DomainParticipant(config.domain_id)
        except DDSException as exc:
            raise TransportError(
                f"cannot join DDS domain {config.domain_id} on {config.interface}: {exc}"
            ) from exc
        # Cyclone binds its receive sockets to 0.0.0.0 (no option says otherwise): keep them to
        # datagrams for the configured interface's address (see udpfilter).
        self._topics: dict[str, Any] = {}
        self._entities: list[Any] = []
        try:
            self.restricted = restrict(self.address, before)
        except TransportError:
            self.close()
            raise
        self._readers: list[bytes] = []
        self._writers: list[bytes] = []
        self._announcer: Any = None
        try:
            self._announce()
        except DDSException as exc:
            self.close()
            raise TransportError(f"cannot announce the node on {DISCOVERY_TOPIC}: {exc}") from exc
        log.info(
            "joined DDS domain %d (ROS_DOMAIN_ID) on %s (%s), unicast discovery with %s",
            config.domain_id,
            config.interface,
            self.address,
            ", ".join(config.peers) or "no peers",
        )

    def _announce(self, readers: Sequence[Any] = (), writers: Sequence[Any] = ()) -> None:
        """Tells ROS 2's graph (``ros_discovery_info``) that this participant hosts the node
        ``config.node`` with these readers and writers, as every rmw does, so ``ros2 node
        list`` lists the agent and ties its endpoints to it. Sent again as entities are added
        (latched: a graph that joins later gets the latest)."""
        from cyclonedds.core import Policy, Qos
        from cyclonedds.pub import DataWriter

        info, gid, node = discovery_type()
        self._readers += [_gid(r) for r in readers]
        self._writers += [_gid(w) for w in writers]
        if self._announcer is None:
            qos = Qos(
                Policy.Reliability.Reliable(max_blocking_time=100_000_000),
                Policy.Durability.TransientLocal,
                Policy.History.KeepLast(1),
            )
            self._announcer = DataWriter(self.participant, self._topic(DISCOVERY_TOPIC, info), qos)
            self._entities.append(self._announcer)
        self._announcer.write(
            info(
                gid=gid(data=list(_gid(self.participant))),
                node_entities_info_seq=[
                    node(
                        node_namespace="/",
                        node_name=self.config.node,
                        reader_gid_seq=[gid(data=list(g)) for g in self._readers],
                        writer_gid_seq=[gid(data=list(g)) for g in self._writers],
                    )
                ],
            )
        )

    def _topic(self, name: str, cls: Any) -> Any:
        from cyclonedds.topic import Topic

        if name not in self._topics:
            self._topics[name] = Topic(self.participant, name, cls)
        return self._topics[name]

    def publisher(self, topic: str, msgtype: str, qos: QoS) -> _DdsPublisher:
        from cyclonedds.core import Listener
        from cyclonedds.pub import DataWriter

        writer = DataWriter(
            self.participant,
            self._topic(topic_name(topic), idl_type(msgtype)),
            _qos(qos, type_hash(msgtype)),
            listener=Listener(**_incompatible("offered", topic, qos)),  # type: ignore[no-untyped-call]
        )
        self._entities.append(writer)
        self._announce(writers=[writer])
        return _DdsPublisher(writer, idl_type(msgtype), msgtype)

    def subscribe(self, topic: str, msgtype: str, qos: QoS, handler: Handler) -> None:
        from cyclonedds.core import Listener
        from cyclonedds.sub import DataReader

        def on_data(reader: Any) -> None:
            for data in valid_samples(reader):
                handler(data)

        reader = DataReader(
            self.participant,
            self._topic(topic_name(topic), idl_type(msgtype)),
            _qos(qos, type_hash(msgtype), reader=True),
            listener=Listener(  # type: ignore[no-untyped-call]
                on_data_available=on_data, **_incompatible("requested", topic, qos)
            ),
        )
        self._entities.append(reader)
        self._announce(readers=[reader])

    def serve(self, service: str, srvtype: str, handler: ServiceHandler) -> None:
        from cyclonedds.core import Listener
        from cyclonedds.pub import DataWriter
        from cyclonedds.sub import DataReader

        rq, rr = service_topics(service)
        req_cls = idl_type(f"{srvtype}_Request", request_header=True)
        resp_cls = idl_type(f"{srvtype}_Response", request_header=True)
        writer = DataWriter(
            self.participant,
            self._topic(rr, resp_cls),
            _qos(SERVICES, type_hash(srvtype)),
            listener=Listener(**_incompatible("offered", rr, SERVICES)),  # type: ignore[no-untyped-call]
        )

        def on_data(reader: Any) -> None:
            for data in valid_samples(reader):
                guid, seq, body = unwrap(data)

                def respond(response: bytes, guid: int = guid, seq: int = seq) -> None:
                    writer.write(resp_cls.deserialize(wrap(response, guid, seq)))

                handler(body, respond)

        reader = DataReader(
            self.participant,
            self._topic(rq, req_cls),
            _qos(SERVICES, type_hash(srvtype), reader=True),
            listener=Listener(  # type: ignore[no-untyped-call]
                on_data_available=on_data, **_incompatible("requested", rq, SERVICES)
            ),
        )
        self._entities += [writer, reader]
        self._announce(readers=[reader], writers=[writer])

    def client(self, service: str, srvtype: str) -> _DdsClient:
        return _DdsClient(self, service, srvtype)

    def close(self) -> None:
        # Dropping the participant deletes its readers and writers; robots see it leave.
        self._entities.clear()
        self._topics.clear()
        participant, self.participant = self.participant, None
        del participant
