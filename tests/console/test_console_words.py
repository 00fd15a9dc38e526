"""Issue 37 item 8 (and item 6's last clause): a refusal in the operator's words with the alarm
lit, never the protocol's text; a typed recording name in ``--out``; no "loading…" entry left
in the procedure list; "not resolved" kept in the result; the mode's whole name in the header.
The wording, the path rule, the result text and the header are tested without a rig; the
procedure list in a bare app; the slip and the recording once against the loopback rig."""

from __future__ import annotations

import dataclasses
import logging
from pathlib import Path

import pytest
from textual.app import App, ComposeResult
from textual.widgets import Input, Select, Static
from textual.widgets._select import SelectOverlay

from console.app import ConsoleApp
from console.procedures import LOADING, ProcedurePanel, result_text
from console.recording import recording_path
from console.refusals import operator_words
from console.state import Phase, ProcedureInfo, Snapshot
from console.statusbar import StatusBar, status_text
from drivers.canopen_client import ABORT_INTERLOCK, ABORT_NOT_HELD
from drivers.errors import InterlockError, ModeNotAllowed, SetpointRangeError
from drivers.relay import MODES, RelayStatus

from .conftest import COLD, outcome, rig_ready, run_async, wait_for

CHANNELS = ("X", "Y", "Z", "XRD")
#: the node's refusal as the driver words it (``CanopenClient._refusal``), from the issue
RAW_NOT_HELD = (
    "CAN node 'relay' (id 3) object 0x2002:0 refused SELECT mode 2: Code "
    "0x08000021, Data can not be transferred or stored to the application because "
    "of local control (mode switches not held)"
)


def _protocol_free(text: str) -> bool:
    return "0x" not in text and "Code" not in text and "object" not in text


# ---------------------------------------------------------------------------- no rig needed
def test_a_refusal_reads_in_operator_words():
    slip = InterlockError(RAW_NOT_HELD, detail=ABORT_NOT_HELD)
    words = operator_words("select mode 2", slip)
    assert words == (
        "mode 2 not selected: the mode switches are not held; press h (hold), "
        "then 2, then r (release)"
    )
    raw_release = RAW_NOT_HELD.replace("0x2002:0 refused SELECT mode 2", "0x2001:0 refused RELEASE")
    unheld = InterlockError(raw_release, detail=ABORT_NOT_HELD)
    assert operator_words("release", unheld).startswith(
        "nothing to release: the mode switches are not held"
    )
    # the node's interlock refusal, its reasons decoded (``CanopenRelayDriver._refined``)
    raw = (
        "CAN node 'relay' (id 3) object 0x2001:0 refused RELEASE: Code 0x08000020, Data can "
        "not be transferred (interlock) (gyros not at speed; gyros not caged)"
    )
    interlock = InterlockError(raw, reasons=("gyros not at speed", "gyros not caged"), detail=3)
    words = operator_words("release", interlock)
    assert (
        words.startswith(
            "release refused by the interlocks: gyros not at speed; gyros not "
            "caged; spin them up in mode 2"
        )
        and "cage them in mode 3" in words
    )
    bare = InterlockError(raw, detail=ABORT_INTERLOCK)
    assert "see Modes (F2)" in operator_words("release", bare)
    rng = SetpointRangeError(
        "CAN node 'torquer' (id 4) object 0x6411:1 refused write: Code "
        "0x06090030, Value range of parameter exceeded",
        limit=(0, 65535),
    )
    assert "the torquer node does not take that value" in operator_words("torquer bias X", rng)
    for w in (
        operator_words("select mode 2", slip),
        operator_words("release", unheld),
        operator_words("release", interlock),
        operator_words("torquer bias X", rng),
    ):
        assert _protocol_free(w), w
    # what the drivers already say in words passes unchanged
    seven = ModeNotAllowed(7)
    assert operator_words("select mode 7", seven) == str(seven)
    reason = InterlockError("mode 4 refused: gyros not at speed (X; spin up in mode 2)")
    assert operator_words("release", reason) == str(reason)


def test_a_typed_recording_name_goes_into_out(tmp_path):
    out = tmp_path / "out"
    assert recording_path("mine.h5", out) == out / "mine.h5"
    assert recording_path(" day2/mine.h5 ", out) == out / "day2" / "mine.h5"
    assert recording_path(str(tmp_path / "else.h5"), out) == tmp_path / "else.h5"  # as typed
    assert recording_path("~/x.h5", out) == Path.home() / "x.h5"


def test_the_result_keeps_not_resolved():
    from procedures.procedure import Measurement, Verdict
    from procedures.runner import RunSummary

    ms = [
        Measurement(
            "bias instability X",
            None,
            "urad/s",
            note="not resolved (too short): 95 % [-0.01, 0.03]; no share in the model",
        ),
        Measurement("g-drift along Z X", None, "urad/s/g", note="not resolved: not varied"),
        Measurement("drift Y", None, "urad/s", note="not resolved: too wide; 95 % [-1, 2]"),
        Measurement(
            "K_g X",
            6.02,
            "mV/urad",
            stderr=0.4,
            note="95 % [5.2, 6.8]; not resolved: the interval spans zero",
        ),
        Measurement("plain", None, "V"),
    ]
    text = str(result_text(RunSummary("drift", None, "complete", Verdict.PASS, measurements=ms)))
    assert "bias instability X: not resolved 95 % [-0.01, 0.03] urad/s" in text
    assert "g-drift along Z X: not resolved\n" in text
    assert "drift Y: not resolved 95 % [-1, 2] urad/s" in text
    assert "K_g X: 6.02 ± 0.4 mV/urad (not resolved)" in text
    assert "plain: - V" in text  # no value and no note: nothing to say


def _relay(mode: int, held: bool = False) -> RelayStatus:
    return RelayStatus(
        mode=mode,
        selected=mode,
        held=held,
        alarm=False,
        at_speed=dict.fromkeys(CHANNELS, True),
        caged=dict.fromkeys(CHANNELS, True),
        spin_fraction=1.0,
    )


def test_the_header_shows_the_whole_mode_name():
    busy = Snapshot(
        phase=Phase.PROCEDURE,
        relay=_relay(4, held=True),
        alarm="mode 5 refused: ...",
        procedure=ProcedureInfo("stopwatch", fraction=0.55),
    )
    note = "quitting: rig going safe…"
    lines = status_text(busy, "sim?realtime=1", note, width=80).plain.splitlines()
    assert MODES[4] == "gyro control, 4-channel caging"
    assert MODES[4] in lines[0] and len(lines[0]) <= 80
    assert len(lines) == 2 and "ALARM" in lines[1] and "stopwatch 55 %" in lines[1]  # no lamp cut
    assert len(status_text(busy, "sim", width=80).plain.splitlines()) == 1  # fits: one line
    calm = Snapshot(phase=Phase.READY, relay=_relay(3))
    assert status_text(calm, "sim", width=80).plain == f" MODE 3  {MODES[3]}   sim"


class _Bare(App[None]):
    def __init__(self, widget) -> None:
        super().__init__()
        self.widget = widget

    def compose(self) -> ComposeResult:
        yield self.widget


@run_async
async def test_the_header_widget_is_not_cut_at_22_characters():
    bar = StatusBar("sim?realtime=1", id="status")
    async with _Bare(bar).run_test(size=(80, 6)) as pilot:
        bar.show(Snapshot(phase=Phase.READY, relay=_relay(5), alarm="mode 4 refused: ..."))
        await pilot.pause()
        shown = str(bar.render())
        assert MODES[5] in shown and "ALARM" in shown


@dataclasses.dataclass
class _Params:
    repetitions: int = 1


class _Proc:
    title = "a procedure"
    Params = _Params


@run_async
async def test_the_procedure_list_never_offers_the_loading_entry():
    panel = ProcedurePanel(id="procedures-panel")
    async with _Bare(panel).run_test(size=(80, 24)) as pilot:
        select = panel.query_one("#proc-name", Select)
        assert select.disabled and select.value == LOADING  # loading: nothing to choose
        catalogue = {"first": _Proc, "second": _Proc}
        panel.set_catalogue(catalogue)  # type: ignore[arg-type]
        await pilot.pause()
        assert not select.disabled and select.value == "first"
        # open the list and go to its top: the old list had the "loading…" prompt there, whose
        # choice named no procedure ("Select.NULL")
        select.focus()
        await pilot.press("enter", "up", "enter")
        await pilot.pause()
        assert select.value in catalogue
        overlay = select.query_one(SelectOverlay)
        prompts = [str(overlay.get_option_at_index(i).prompt) for i in range(overlay.option_count)]
        assert prompts == ["first", "second"]


# ---------------------------------------------------------------------------- against the rig
def text_of(app, selector: str) -> str:
    return str(app.query_one(selector, Static).render())


@pytest.mark.slow
@run_async
async def test_a_slip_lights_the_alarm_in_words_and_a_typed_name_records_into_out(
    out_dir, tmp_path, monkeypatch, caplog
):
    monkeypatch.chdir(tmp_path)  # the old console wrote a typed name here
    caplog.set_level(logging.INFO, logger="console")
    app = ConsoleApp(COLD, out_dir=out_dir)
    async with app.run_test(size=(80, 24)) as pilot:
        await rig_ready(pilot)
        state = app.worker_.state
        await pilot.press("f2", "2")  # a mode's digit without the hold
        await wait_for(pilot, lambda: outcome(app, "select mode 2") is not None, what="the refusal")
        refused = outcome(app, "select mode 2")
        assert not refused.ok and refused.text.startswith(
            "mode 2 not selected: the mode switches are not held; press h (hold), then 2, then r"
        )
        await pilot.pause(0.2)
        alarm = text_of(app, "#mode-alarm")
        assert "ALARM" in alarm and "not held" in alarm and _protocol_free(alarm)
        assert "ALARM" in text_of(app, "#status")
        assert "the alarm above says why" in text_of(app, "#mode-last")
        toasts = [(n.title, n.message) for n in app._notifications]
        assert ("select mode 2 refused", refused.text) in toasts
        # the node's own words go to the log
        assert any("Code 0x08000021" in r.getMessage() for r in caplog.records)
        await pilot.press("h")  # its cause gone, the lamp goes out
        await wait_for(
            pilot, lambda: state.get().alarm is None and state.get().relay.held, what="the hold"
        )
        # a typed name goes into --out, not the shell's working directory
        await pilot.press("f4")
        app.query_one("#rec-path", Input).value = "mine.h5"
        app.query_one("#rec-rate", Input).value = "200"
        await pilot.press("f7")
        await wait_for(
            pilot,
            lambda: (r := state.get().recording) is not None and r.samples >= 200,
            what="a second of samples",
        )
        assert state.get().recording.path == out_dir / "mine.h5"
        await pilot.press("f8")
        await wait_for(pilot, lambda: state.get().phase == "ready", what="the recording closed")
    assert (out_dir / "mine.h5").exists() and not (tmp_path / "mine.h5").exists()
