"""A log panel that wraps its entries to its own width, whatever width it is shown at."""

from __future__ import annotations

from collections import deque

from rich.text import Text
from textual import events
from textual.widgets import RichLog


class EventLog(RichLog):
    """A wrapped log that wraps its entries again whenever its width changes. Left to itself a
    RichLog wraps a line once, at a width measured against the app's console, not itself, and
    keeps it so (a line logged while its panel was hidden stays wrapped at 80 columns)."""

    def __init__(self, *, max_lines: int = 500, **kw) -> None:
        super().__init__(max_lines=max_lines, **kw)
        self.entries: deque[Text] = deque(maxlen=max_lines)
        self._wrapped_at = 0

    def add(self, line: Text) -> None:
        self.entries.append(line)
        if self._wrapped_at:  # else kept until the log is shown (on_resize)
            self.write(line, width=self._wrapped_at)

    def clear(self) -> EventLog:
        self.entries.clear()
        return super().clear()

    def on_resize(self, event: events.Resize) -> None:
        width = self.scrollable_content_region.width
        if width and width != self._wrapped_at:
            self._wrapped_at = width
            super().clear()
            for line in self.entries:
                self.write(line, width=width)
