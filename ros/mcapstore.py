"""rosbag2 bags whose MCAP file is written as ``ros2 bag record`` writes it: zstd chunks, CRCs.

rosbags' ROS 2 :class:`~rosbags.rosbag2.Writer` writes ``metadata.yaml`` and hands the storage
file to a plugin. Its own MCAP plugin writes chunks either raw or zstd-compressed, but leaves
every CRC zero. :class:`McapStorage` is a plugin for the same writer backed by the ``mcap``
library (Foxglove's reference writer): zstd chunks of 1 MiB with chunk and summary CRCs (data
CRC off), the defaults of the MCAP C++ writer that rosbag2's MCAP storage uses. Records are
what rosbag2's plugin writes: profile ``ros2``, one ``ros2msg`` schema per type, channels with
``offered_qos_profiles`` and ``topic_type_hash`` metadata, and the bag's metadata in a
``rosbag2`` metadata record.

``compress=False`` writes the same file with uncompressed chunks (CRCs kept): faster to write,
10-15 times larger (docs/pipeline.md, "Compression").
"""

from __future__ import annotations

from functools import partial
from pathlib import Path
from typing import IO, Literal

from rosbags.interfaces import Connection, ConnectionExtRosbag2, MessageDefinitionFormat
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Rosbag2Writer
from rosbags.rosbag2.enums import CompressionFormat, CompressionMode


class McapStorage:
    """A rosbags storage plugin (``StorageWriter``) writing ``NAME/NAME.mcap`` with ``mcap``."""

    def __init__(
        self, path: Path, compression: CompressionMode, *, chunk_size: int = 1024 * 1024
    ) -> None:
        from mcap.writer import CompressionType
        from mcap.writer import Writer as McapWriter

        from objsearch import __version__

        self.path = path / f"{path.name}.mcap"
        self._file: IO[bytes] = self.path.open("xb")
        zstd = compression is CompressionMode.STORAGE
        self._writer = McapWriter(
            self._file,
            chunk_size=chunk_size,
            compression=CompressionType.ZSTD if zstd else CompressionType.NONE,
            enable_crcs=True,
        )
        self._writer.start(profile="ros2", library=f"objsearch-{__version__} (mcap-python)")
        self._schemas: dict[str, int] = {}
        self._channels: dict[int, int] = {}

    def add_msgtype(self, connection: Connection) -> None:
        encoding = (
            "ros2msg" if connection.msgdef.format is MessageDefinitionFormat.MSG else "ros2idl"
        )
        self._schemas[connection.msgtype] = self._writer.register_schema(
            name=connection.msgtype, encoding=encoding, data=connection.msgdef.data.encode()
        )

    def add_connection(self, connection: Connection, offered_qos_profiles: str) -> None:
        ext = connection.ext
        assert isinstance(ext, ConnectionExtRosbag2)
        self._channels[connection.id] = self._writer.register_channel(
            topic=connection.topic,
            message_encoding=ext.serialization_format,
            schema_id=self._schemas[connection.msgtype],
            metadata={
                "offered_qos_profiles": offered_qos_profiles,
                "topic_type_hash": connection.digest,
            },
        )

    def write(self, connection: Connection, timestamp: int, data: bytes | memoryview) -> None:
        self._writer.add_message(
            self._channels[connection.id],
            log_time=timestamp,
            data=bytes(data),
            publish_time=timestamp,
        )

    def close(self, version: int, metadata: str) -> None:
        self._writer.add_metadata("rosbag2", {"serialized_metadata": metadata})
        self._writer.finish()  # type: ignore[no-untyped-call]
        self._file.close()

    def abort(self) -> None:
        self._file.close()


class Writer(Rosbag2Writer):
    """rosbags' ROS 2 writer with :class:`McapStorage` for MCAP bags."""

    STORAGE_PLUGINS = {**Rosbag2Writer.STORAGE_PLUGINS, StoragePlugin.MCAP: McapStorage}  # noqa: RUF012


#: The rosbag2 metadata version written. Version 8 (Iron) stores each topic's QoS profiles as a
#: YAML string with rmw's enum values, as the bags in rosbag2's own tests do; Jazzy's version 9
#: names the policies instead, which Humble's rosbag2 cannot parse, while Jazzy reads both.
METADATA_VERSION: Literal[8] = 8


def rosbag2_writer(
    path: Path, plugin: StoragePlugin, *, compress: bool = True, chunk_bytes: int | None = None
) -> Writer:
    """An unopened writer of a rosbag2 bag at ``path`` (a directory); an MCAP one is
    zstd-compressed unless ``compress`` is false (sqlite3 bags are never compressed, as
    ``ros2 bag record`` leaves them), in chunks of ``chunk_bytes`` before compression (1 MiB)."""
    writer = Writer(path, version=METADATA_VERSION, storage_plugin=plugin)
    if chunk_bytes is not None:
        sized = partial(McapStorage, chunk_size=chunk_bytes)
        writer.STORAGE_PLUGINS = {**writer.STORAGE_PLUGINS, StoragePlugin.MCAP: sized}  # type: ignore[dict-item]
    if plugin is StoragePlugin.MCAP and compress:
        writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
    return writer
