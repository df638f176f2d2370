"""The context-manager protocol every reader and writer of this package follows."""
from __future__ import annotations

from typing import Any


class OpenClose:
    """``with obj:`` calls ``open()`` on entry and ``close()`` on exit.

    Subclasses implement ``open`` (raising ``RecordingError`` when it cannot) and an
    idempotent ``close``.
    """

    def open(self) -> None:
        raise NotImplementedError

    def close(self) -> None:
        raise NotImplementedError

    def __enter__(self) -> Any:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
