"""numpy arrays inside pydantic messages: dtype, shape and raw bytes on the wire.

A field annotated `Annotated[np.ndarray, ArraySpec("float32", (None, 3))]` accepts a numpy
array (when building a message) or the wire map `{"dtype", "shape", "data", "z"}` (when
decoding), checks dtype, shape, finiteness and the size cap, and serialises back to the wire
map. `z` marks zstd-compressed bytes; `f` names a lossless filter applied before compression
(`delta`: differences along the last axis, in the array's own wrapping integer type;
`shuffle`: the bytes of each element split into planes), which the decoder undoes. The
decoded array is the encoded one bit for bit either way.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import zstandard
from pydantic import GetCoreSchemaHandler, ValidationInfo
from pydantic_core import PydanticCustomError, core_schema

DEFAULT_MAX_ARRAY_BYTES = 64 * 1024 * 1024
_ZSTD_LEVEL = 3
FILTERS = ("delta", "shuffle")


def _max_bytes(info: ValidationInfo | None) -> int:
    context = (info.context if info is not None else None) or {}
    return int(context.get("max_array_bytes", DEFAULT_MAX_ARRAY_BYTES))


@dataclass(frozen=True)
class ArraySpec:
    """Constraints of one array field: dtype names allowed, shape (None = any length)."""

    dtypes: str | tuple[str, ...]
    shape: tuple[int | None, ...] | None = None
    compress: bool = False
    finite: bool = True
    # before compressing: "delta" for integer arrays whose neighbours along the last axis
    # are alike (sorted coordinates, a colour's channels), "shuffle" for multi-byte values
    # whose high bytes are mostly zero (counts); None = the raw bytes
    filter: str | None = None
    level: int = _ZSTD_LEVEL  # zstd level (the default is cheap enough for camera frames)

    def __post_init__(self) -> None:
        if self.filter is not None and (self.filter not in FILTERS or not self.compress):
            raise ValueError(f"filter {self.filter!r}: one of {FILTERS}, on a compressed array")

    @property
    def allowed(self) -> tuple[str, ...]:
        return (self.dtypes,) if isinstance(self.dtypes, str) else self.dtypes

    def __get_pydantic_core_schema__(
        self, source: Any, handler: GetCoreSchemaHandler
    ) -> core_schema.CoreSchema:
        return core_schema.with_info_plain_validator_function(
            self._validate,
            serialization=core_schema.plain_serializer_function_ser_schema(
                self._serialize, when_used="always"
            ),
        )

    def _fail(self, message: str) -> PydanticCustomError:
        return PydanticCustomError("array", message)

    def _validate(self, value: Any, info: ValidationInfo) -> np.ndarray:
        cap = _max_bytes(info)
        array = value if isinstance(value, np.ndarray) else self._from_wire(value, cap)
        if array.dtype.name not in self.allowed:
            raise self._fail(f"dtype {array.dtype.name} not in {self.allowed}")
        if self.shape is not None:
            ok = array.ndim == len(self.shape) and all(
                want is None or want == got
                for want, got in zip(self.shape, array.shape, strict=True)
            )
            if not ok:
                raise self._fail(f"shape {array.shape} does not match {self.shape}")
        if array.nbytes > cap:
            raise self._fail(f"array of {array.nbytes} bytes exceeds cap {cap}")
        if self.finite and array.dtype.kind == "f" and not np.isfinite(array).all():
            raise self._fail("array holds NaN or infinite values")
        return array

    def _from_wire(self, value: Any, cap: int) -> np.ndarray:
        if not isinstance(value, dict) or not {"dtype", "shape", "data"} <= value.keys():
            raise self._fail("expected an array map with dtype, shape and data")
        dtype_name, shape, data = value["dtype"], value["shape"], value["data"]
        if dtype_name not in self.allowed:
            raise self._fail(f"dtype {dtype_name!r} not in {self.allowed}")
        if not isinstance(shape, list | tuple) or not all(
            isinstance(n, int) and n >= 0 for n in shape
        ):
            raise self._fail("shape must be a list of non-negative integers")
        if not isinstance(data, bytes | bytearray):
            raise self._fail("data must be bytes")
        dtype = np.dtype(dtype_name)
        expected = int(np.prod(shape, dtype=np.int64)) * dtype.itemsize
        if expected > cap:
            raise self._fail(f"array of {expected} bytes exceeds cap {cap}")
        if value.get("z"):
            try:
                data = zstandard.ZstdDecompressor().decompress(data, max_output_size=expected)
            except zstandard.ZstdError as exc:
                raise self._fail(f"zstd: {exc}") from exc
        if len(data) != expected:
            raise self._fail(f"{len(data)} bytes for shape {list(shape)} of {dtype_name}")
        array = np.frombuffer(data, dtype=dtype).reshape(shape)
        kind = value.get("f")
        if kind is None:
            return array
        if kind not in FILTERS or (kind == "delta" and dtype.kind not in "iu"):
            raise self._fail(f"filter {kind!r} on {dtype_name}")
        return _undo(kind, array)

    def _serialize(self, array: np.ndarray) -> dict[str, Any]:
        array = np.ascontiguousarray(array)
        wire: dict[str, Any] = {"dtype": array.dtype.name, "shape": list(array.shape)}
        if not (self.compress and array.size):
            wire["data"] = array.tobytes()
            return wire
        kind = self.filter if self.filter != "delta" or array.dtype.kind in "iu" else None
        if kind == "shuffle" and array.dtype.itemsize == 1:
            kind = None  # one byte per element: nothing to split
        data = _apply(kind, array) if kind is not None else array.tobytes()
        wire["data"] = zstandard.ZstdCompressor(level=self.level).compress(data)
        wire["z"] = True
        if kind is not None:
            wire["f"] = kind
        return wire


def _apply(kind: str, array: np.ndarray) -> bytes:
    if kind == "delta":
        out = array.copy()  # in its own type: differences wrap, and the sums wrap back
        out[..., 1:] -= array[..., :-1]
        return out.tobytes()
    planes = array.reshape(-1).view(np.uint8).reshape(-1, array.dtype.itemsize)
    return np.ascontiguousarray(planes.T).tobytes()


def _undo(kind: str, array: np.ndarray) -> np.ndarray:
    if kind == "delta":
        return np.cumsum(array, axis=-1, dtype=array.dtype) if array.ndim else array
    size = array.dtype.itemsize
    planes = array.reshape(-1).view(np.uint8).reshape(size, -1)
    return np.ascontiguousarray(planes.T).view(array.dtype).reshape(array.shape)
