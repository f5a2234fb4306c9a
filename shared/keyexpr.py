"""rmw_zenoh wire conventions: topic key expressions, the sample attachment, liveliness tokens.

Topic key: ``<domain>/<namespace>/<topic>/<pkg>::msg::dds_::<Type>_/<RIHS01 hash>``, inner slashes
kept, as rmw_zenoh_cpp's ``TopicInfo`` builds it. The attachment is what rmw_zenoh >= 0.6 writes
with ``zenoh::ext::Serializer``: int64 sequence number, int64 source timestamp (ns since the
epoch), then the 16-byte publisher gid as a sequence (one LEB128 length byte, 0x10).
"""

from __future__ import annotations

import struct
from typing import Final, NamedTuple

from shared.messages import MessageError, dds_type_name, ros_type_name, type_hash

GID_SIZE: Final = 16
_ATTACHMENT = struct.Struct("<qqB16s")
ADMIN_SPACE: Final = "@ros2_lv"


class Attachment(NamedTuple):
    """Per-sample metadata rmw_zenoh sends beside the CDR payload."""

    sequence_number: int
    source_timestamp_ns: int
    gid: bytes

    def encode(self) -> bytes:
        if len(self.gid) != GID_SIZE:
            raise ValueError(f"gid must be {GID_SIZE} bytes, not {len(self.gid)}")
        return _ATTACHMENT.pack(self.sequence_number, self.source_timestamp_ns, GID_SIZE, self.gid)

    @classmethod
    def decode(cls, raw: bytes) -> Attachment:
        if len(raw) != _ATTACHMENT.size or raw[16] != GID_SIZE:
            raise MessageError(f"attachment of {len(raw)} bytes is not rmw_zenoh's 33-byte layout")
        seq, stamp, _, gid = _ATTACHMENT.unpack(raw)
        return cls(seq, stamp, gid)


class TopicKey(NamedTuple):
    """The parts of a received topic key expression."""

    domain_id: int
    namespace: str
    topic: str
    msgtype: str
    type_hash: str


def topic_key(domain_id: int, namespace: str, topic: str, msgtype: str) -> str:
    """The key expression rmw_zenoh uses for ``/<namespace>/<topic>`` of ``msgtype``."""
    name = "/".join(part for part in (namespace.strip("/"), topic.strip("/")) if part)
    if not name:
        raise ValueError("empty topic name")
    return f"{domain_id}/{name}/{dds_type_name(msgtype)}/{type_hash(msgtype)}"


def topic_selector(domain_id: int, namespace: str, topic: str, msgtype: str) -> str:
    """Key expression matching ``topic`` of ``msgtype`` under ``namespace`` with any type hash.

    ``namespace`` ``"*"`` matches every namespace, the root one included; the hash is a
    wildcard because ROS distributions before Jazzy publish without one.
    """
    ns = "**" if namespace == "*" else namespace.strip("/")
    name = "/".join(part for part in (ns, topic.strip("/")) if part)
    return f"{domain_id}/{name}/{dds_type_name(msgtype)}/*"


def parse_topic_key(key: str, *, topic: str | None = None) -> TopicKey:
    """Split a received key into domain, robot namespace, topic name, type and hash.

    With ``topic`` (the name subscribed to, e.g. ``fisheye/image_raw``) the namespace is what
    precedes it; without, the topic is taken to be the last path element (``scan`` in
    ``0/robot1/scan/...``) and everything between the domain and it is the namespace.
    """
    chunks = key.split("/")
    if len(chunks) < 4 or not chunks[0].isdigit():
        raise MessageError(f"{key!r} is not an rmw_zenoh topic key")
    name = chunks[1:-2]
    topic_chunks = topic.strip("/").split("/") if topic else name[-1:]
    if name[len(name) - len(topic_chunks):] != topic_chunks:
        raise MessageError(f"{key!r} is not a key of topic {topic!r}")
    return TopicKey(
        domain_id=int(chunks[0]),
        namespace="/".join(name[: len(name) - len(topic_chunks)]),
        topic="/".join(topic_chunks),
        msgtype=ros_type_name(chunks[-2]),
        type_hash=chunks[-1],
    )


def mangle(name: str) -> str:
    """rmw_zenoh's liveliness-token spelling of a ROS name: every ``/`` becomes ``%``."""
    return name.replace("/", "%") if name else "%"


def node_token(domain_id: int, zid: str, node_id: int, namespace: str, node_name: str) -> str:
    """A ROS 2 node liveliness token (``NN``) as rmw_zenoh declares it, so tools list the node."""
    ns = mangle("/" + namespace.strip("/")) if namespace.strip("/") else "%"
    return f"{ADMIN_SPACE}/{domain_id}/{zid}/{node_id}/{node_id}/NN/%/{ns}/{node_name}"


def node_selector(domain_id: int, namespace: str) -> str:
    """Key expression matching every node token under ``namespace``."""
    ns = mangle("/" + namespace.strip("/"))
    return f"{ADMIN_SPACE}/{domain_id}/*/*/*/NN/%/{ns}/*"
