"""numpy arrays inside pydantic messages: dtype, shape and raw bytes on the wire.

A field annotated `Annotated[np.ndarray, ArraySpec("float32", (None, 3))]` accepts a numpy
array (when building a message) or the wire map `{"dtype", "shape", "data", "z"}` (when
decoding), checks dtype, shape, finiteness and the size cap, and serialises back to the wire
map. `z` marks zstd-compressed bytes.
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
        return np.frombuffer(data, dtype=dtype).reshape(shape)

    def _serialize(self, array: np.ndarray) -> dict[str, Any]:
        data = np.ascontiguousarray(array).tobytes()
        wire: dict[str, Any] = {"dtype": array.dtype.name, "shape": list(array.shape)}
        if self.compress and data:
            wire["data"] = zstandard.ZstdCompressor(level=_ZSTD_LEVEL).compress(data)
            wire["z"] = True
        else:
            wire["data"] = data
        return wire
