"""Bus contract of spacemap: messages, codec and keys (SPEC §2)."""

from schemas.codec import decode, encode
from schemas.errors import DecodeError
from schemas.keys import Keys

__all__ = ["DecodeError", "Keys", "decode", "encode"]
