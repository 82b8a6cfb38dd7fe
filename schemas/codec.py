"""msgpack codec: `encode` a message to bytes, `decode` bytes to a validated message."""

from __future__ import annotations

from typing import TypeVar, overload

import msgpack
from pydantic import ValidationError

from schemas.arrays import DEFAULT_MAX_ARRAY_BYTES
from schemas.errors import DecodeError
from schemas.messages import MESSAGE_TYPES, SCHEMA_VERSION, Message

M = TypeVar("M", bound=Message)


def encode(message: Message) -> bytes:
    """Serialise a message; arrays become {dtype, shape, data[, z]} maps."""
    return msgpack.packb(message.model_dump(), use_bin_type=True)


@overload
def decode(payload: bytes, expected: type[M], max_array_bytes: int = ...) -> M: ...
@overload
def decode(payload: bytes, expected: None = None, max_array_bytes: int = ...) -> Message: ...


def decode(
    payload: bytes,
    expected: type[Message] | None = None,
    max_array_bytes: int = DEFAULT_MAX_ARRAY_BYTES,
) -> Message:
    """Decode and validate; raise `DecodeError` for any bad input, never anything else."""
    try:
        obj = msgpack.unpackb(payload, raw=False, strict_map_key=False)
    except (ValueError, msgpack.ExtraData, msgpack.FormatError, msgpack.StackError) as exc:
        raise DecodeError("malformed msgpack", str(exc)) from exc
    if not isinstance(obj, dict):
        raise DecodeError("not a map", type(obj).__name__)
    kind = obj.get("kind")
    model = MESSAGE_TYPES.get(kind) if isinstance(kind, str) else None
    if model is None:
        raise DecodeError("unknown kind", repr(kind)[:64])
    if expected is not None and model is not expected:
        raise DecodeError("unexpected kind", f"{kind!r}, expected {expected.KIND!r}")
    if obj.get("v") != SCHEMA_VERSION:
        raise DecodeError("wrong schema version", f"{obj.get('v')!r} != {SCHEMA_VERSION}")
    try:
        return model.model_validate(obj, context={"max_array_bytes": max_array_bytes})
    except ValidationError as exc:
        first = exc.errors()[0]
        where = ".".join(str(p) for p in first["loc"])
        raise DecodeError(f"invalid {kind}", f"{where}: {first['msg']}") from exc


def peek_tick(payload: bytes) -> int | None:
    """The `tick` field of an encoded message without validating the rest (traffic
    accounting); None when the payload is no msgpack map with a non-negative integer tick."""
    try:
        obj = msgpack.unpackb(payload, raw=False, strict_map_key=False)
    except (ValueError, msgpack.ExtraData, msgpack.FormatError, msgpack.StackError):
        return None
    tick = obj.get("tick") if isinstance(obj, dict) else None
    return tick if isinstance(tick, int) and not isinstance(tick, bool) and tick >= 0 else None
