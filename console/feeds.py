"""A bounded, thread-safe feed of items from the rig's thread to the UI's.

Rig events and log records can come thousands a second (a procedure sweeping a bias in
virtual time); posting each as a Textual message would flood the UI. The producer appends
here, the UI drains the feed on its refresh timer; the oldest items are dropped, and counted,
when the UI falls behind.
"""

from __future__ import annotations

import threading
from collections import deque
from typing import Generic, TypeVar

T = TypeVar("T")


class Feed(Generic[T]):
    def __init__(self, maxlen: int = 2000) -> None:
        self._items: deque[T] = deque()
        self._maxlen = maxlen
        self._lock = threading.Lock()
        self.dropped = 0

    def put(self, item: T) -> None:
        with self._lock:
            if len(self._items) >= self._maxlen:
                self._items.popleft()
                self.dropped += 1
            self._items.append(item)

    def drain(self) -> list[T]:
        with self._lock:
            items = list(self._items)
            self._items.clear()
        return items
