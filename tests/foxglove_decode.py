"""Foxglove messages decoded the way the app decodes them: by the schema the server gives
(a protobuf FileDescriptorSet), not by classes compiled into the test."""

from __future__ import annotations

from google.protobuf import descriptor_pb2, descriptor_pool, message_factory


def message_class(schema_name: str, file_descriptor_set: bytes) -> type:
    files = descriptor_pb2.FileDescriptorSet.FromString(file_descriptor_set)
    pool = descriptor_pool.DescriptorPool()
    for f in files.file:  # dependencies come first
        pool.Add(f)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(schema_name))
