"""Issue 37 item 5: one logging rule everywhere (``drivers.logrule``): this program's records
from INFO, other libraries' from WARNING, each line with its UTC offset - on the command
line's stderr and run log, in ``console.log`` and in the console's live log (F5). The console
set the root logger to INFO: its log was 98 % canopen's "Expedited upload for 0x6411:02"."""

from __future__ import annotations

import io
import logging
import re
import sys

import pytest

from console.feeds import Feed
from console.logfeed import FeedHandler
from drivers.logrule import ProjectFilter, ruled, set_levels
from fbs.logsetup import command_logging

#: a line's time: local, milliseconds, UTC offset
STAMP = re.compile(r"^\d{4}-\d\d-\d\d \d\d:\d\d:\d\d\.\d{3}[+-]\d{4} ")


def _record(name: str, level: int, msg: str) -> logging.LogRecord:
    return logging.LogRecord(name, level, __file__, 1, msg, None, None)


def test_the_filter_keeps_ours_from_info_and_others_from_warning():
    f = ProjectFilter()
    upload = "Expedited upload for 0x6411:02"
    assert not f.filter(_record("canopen.sdo.client", logging.INFO, upload))
    assert f.filter(_record("canopen.sdo.client", logging.WARNING, "timeout"))
    assert f.filter(_record("drivers.rig", logging.INFO, "rig open"))
    assert f.filter(_record("console.app", logging.DEBUG, "x"))  # ours: the levels decide
    assert not f.filter(_record("driversx", logging.INFO, "not ours"))


@pytest.fixture
def levels_restored():
    names = ["", "canopen", "drivers", "console"]
    saved = {n: logging.getLogger(n).level for n in names}
    handlers = logging.getLogger().handlers[:]
    yield
    logging.getLogger().handlers[:] = handlers
    for n, level in saved.items():
        logging.getLogger(n).setLevel(level)


#: what ``_emit_three`` leaves, as "LEVEL name: message"
KEPT = ["INFO drivers.rig: rig sim open", "WARNING canopen.network: no answer from node 5"]


def _emit_three() -> None:
    logging.getLogger("canopen.sdo.client").info("Expedited upload for 0x6411:02")
    logging.getLogger("drivers.rig").info("rig sim open")
    logging.getLogger("canopen.network").warning("no answer from node 5")


def test_a_file_handler_like_console_log_gets_no_third_party_info(levels_restored):
    """What ``run_console`` sets up, even with a library's logger at INFO of its own."""
    stream = io.StringIO()
    logging.getLogger().addHandler(ruled(logging.StreamHandler(stream)))
    restore = set_levels()
    logging.getLogger("canopen").setLevel(logging.INFO)  # a library (or a host) asked for INFO
    try:
        _emit_three()
    finally:
        restore()
    lines = stream.getvalue().splitlines()
    assert [ln.split(" ", 2)[2] for ln in lines] == KEPT, lines
    assert all(STAMP.match(ln) for ln in lines), lines


def test_the_consoles_live_log_gets_no_third_party_info(levels_restored):
    feed: Feed[str] = Feed()
    logging.getLogger().addHandler(FeedHandler(feed))
    logging.getLogger().setLevel(logging.DEBUG)  # the old console's root level, or lower
    _emit_three()
    assert feed.drain() == [f"{k[0]} {rest}" for k, rest in (ln.split(" ", 1) for ln in KEPT)]


def test_the_command_lines_stderr_gets_no_third_party_info(levels_restored, monkeypatch):
    err = io.StringIO()
    monkeypatch.setattr(sys, "stderr", err)
    with command_logging(verbose=True):
        logging.getLogger("canopen").setLevel(logging.DEBUG)
        _emit_three()
    lines = err.getvalue().splitlines()
    assert [ln.split(" ", 2)[2] for ln in lines] == KEPT, lines
    assert all(STAMP.match(ln) for ln in lines), lines
