"""The manual rotary table's operator, asked in the console (``drivers.table.Operator``).

``open_rig(url, operator=...)`` with ``table=manual`` calls the operator on the thread that
moves the table (the rig thread, inside a procedure) and waits for the answer. This one posts
the question to the UI (a modal screen), then blocks the rig thread, never the UI, until the
operator answers; a console that shuts down answers 'abort' (``OperatorAbort``: the procedure
ends and the rig goes safe).
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from dataclasses import dataclass, field

log = logging.getLogger(__name__)


@dataclass
class OperatorQuestion:
    prompt: str
    answer: str | None = None
    done: threading.Event = field(default_factory=threading.Event)

    def reply(self, answer: str | None) -> None:
        self.answer = answer
        self.done.set()


class ConsoleOperator:
    """Callable as an ``Operator``: prompt -> answer, asked through ``ask`` (the UI)."""

    def __init__(self) -> None:
        self.ask: Callable[[OperatorQuestion], object] | None = None  # its result is ignored
        self._open: list[OperatorQuestion] = []
        self._closed = False
        self._lock = threading.Lock()

    def __call__(self, prompt: str) -> str:
        q = OperatorQuestion(prompt)
        with self._lock:
            if self._closed or self.ask is None:
                return "abort"
            self._open.append(q)
        log.info("asking the operator: %s", prompt)
        self.ask(q)
        q.done.wait()
        with self._lock:
            if q in self._open:
                self._open.remove(q)
        log.info("operator answered %r", q.answer)
        return q.answer or ""

    def close(self) -> None:
        """Answer every open question 'abort' and every later one too."""
        with self._lock:
            self._closed = True
            open_, self._open = self._open, []
        for q in open_:
            q.reply("abort")
