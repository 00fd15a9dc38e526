"""Log records into a ``Feed`` for the console's live log (logging never writes to the
terminal while the console owns it)."""

from __future__ import annotations

import logging

from console.feeds import Feed
from drivers.logrule import ProjectFilter


class FeedHandler(logging.Handler):
    def __init__(self, feed: Feed[str], level: int = logging.INFO) -> None:
        super().__init__(level)
        self.feed = feed
        self.setFormatter(logging.Formatter("%(levelname).1s %(name)s: %(message)s"))
        self.addFilter(ProjectFilter())  # other libraries' from WARNING (drivers.logrule)

    def emit(self, record: logging.LogRecord) -> None:
        try:
            self.feed.put(self.format(record))
        except Exception:  # logging must never raise into the rig thread
            self.handleError(record)
