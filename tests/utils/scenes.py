"""Reading a ``.viser`` scene recording in tests (msgspec and zstandard come with viser)."""

from __future__ import annotations

from typing import Any

__all__ = ["decode_scene"]


#: Largest decompressed recording :func:`decode_scene` accepts, bytes.
MAX_DECODED_BYTES = 256 * 1024 * 1024


def decode_scene(data: bytes) -> dict[str, Any]:
    """The metadata of a ``.viser`` recording: ``durationSeconds``, ``messages`` (``(t, dict)``
    pairs), ``viserVersion`` (format of ``viser.infra.StateSerializer.serialize``: an 8-byte
    size, then zstd of an 8-byte msgpack length, the msgpack and the binary buffers)."""
    import msgspec
    import zstandard

    if len(data) < 16:
        raise ValueError(f"a .viser recording has at least 16 bytes, got {len(data)}")
    size = int.from_bytes(data[:8], "little")
    if not 8 < size <= MAX_DECODED_BYTES:
        raise ValueError(
            f"recording of {size} bytes decompressed is outside 9..{MAX_DECODED_BYTES}"
        )
    inner = zstandard.ZstdDecompressor().decompress(data[8:], max_output_size=size)
    n = int.from_bytes(inner[:8], "little")
    meta: dict[str, Any] = msgspec.msgpack.decode(inner[8 : 8 + n])
    return meta
