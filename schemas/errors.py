"""The one error type every decode raises."""

from __future__ import annotations


class DecodeError(ValueError):
    """A bus payload that could not be decoded or failed validation.

    `reason` is a short, stable, human-readable cause (used as the log-once key).
    """

    def __init__(self, reason: str, detail: str = "") -> None:
        self.reason = reason
        self.detail = detail
        super().__init__(f"{reason}: {detail}" if detail else reason)
