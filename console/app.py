"""``fbs console``: the operator console (Textual), successor of the thesis's control console.

Panels (F1-F6): meters, modes, set-points, recording, procedures, spectra; the status line
on top shows rig, mode, alarm, recording and procedure on every panel. The rig lives on one
thread of its own (``RigWorker``); this UI thread only queues commands, copies the worker's
``LiveState`` on a timer (``refresh_s``) and handles its posted outcomes, so it never waits
on a device. See docs/console.md.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import TYPE_CHECKING, ClassVar

from textual import events, work
from textual.app import App, ComposeResult
from textual.binding import Binding, BindingType
from textual.geometry import Size
from textual.message import Message
from textual.notifications import SeverityLevel
from textual.widgets import Footer, Static, TabbedContent, TabPane, Tabs

from console.channels import unknown_channels
from console.exitguard import EXIT_SIGNALLED, ExitGuard
from console.feeds import Feed
from console.keyhelp import HelpScreen
from console.limits import Entry
from console.logfeed import FeedHandler
from console.meterdata import MeterSnapshot, MeterSpec, MeterStore, permanent_meters
from console.meters import MeterPanel
from console.modes import ModePanel
from console.operator import ConsoleOperator, OperatorQuestion
from console.operatorscreen import OperatorScreen
from console.procedures import ProcedurePanel, parse_run_text
from console.quitscreen import QuitScreen, what_quit_closes
from console.recording import RecordingPanel, default_path, recording_path
from console.rigworker import RigWorker
from console.setpoint_panel import SetpointPanel, state_key
from console.spectra_view import SpectraPanel
from console.state import (
    CommandOutcome,
    ProcedureEnded,
    RecordingEnded,
    RigEventItem,
    RigFailed,
    RigFault,
    RigReady,
    WorkerStopped,
)
from console.statusbar import StatusBar
from drivers.logrule import PROJECT_PACKAGES, ruled, set_levels
from drivers.rig_datasheet import RigCalibration
from drivers.setpoints import SetpointLimits

if TYPE_CHECKING:
    from procedures.procedure import Procedure
    from procedures.runner import RunSummary

log = logging.getLogger(__name__)

DEFAULT_RIG = "sim?realtime=1"
#: (id, tab title, key); the tab titles carry their keys, for an operator without a footer
PANELS = (
    ("meters", "Meters", "f1"),
    ("modes", "Modes", "f2"),
    ("setpoints", "Set-pts", "f3"),
    ("recording", "Record", "f4"),
    ("procedures", "Procs", "f5"),
    ("spectra", "Spectra", "f6"),
)
PANEL_KEYS = Binding.Group("panel")
#: the smallest terminal the layout fits (columns, rows); below it a notice says what is cut off
MIN_SIZE = (80, 24)


class RigNews(Message):
    """Something the rig thread (or the manual-table operator) posted."""

    def __init__(self, item: object) -> None:
        super().__init__()
        self.item = item


class ConsoleApp(App[int]):
    CSS_PATH = str(Path(__file__).with_name("styles.tcss"))  # absolute: subclasses live elsewhere
    TITLE = "fbs console"
    ENABLE_COMMAND_PALETTE = False
    BINDINGS: ClassVar[list[BindingType]] = [
        *(Binding(key, f"panel('{pid}')", title, group=PANEL_KEYS) for pid, title, key in PANELS),
        Binding("question_mark", "help", "help", key_display="?"),
        Binding("q", "quit", "quit"),
        Binding("ctrl+q", "quit", "quit", show=False, priority=True),
    ]

    def __init__(
        self,
        rig_url: str = DEFAULT_RIG,
        *,
        out_dir: str | Path = "out",
        live_meters: bool = True,
        refresh_s: float = 0.08,
        meter_rate_hz: float = 200.0,
    ) -> None:
        super().__init__()
        self.rig_url = rig_url
        self.out_dir = Path(out_dir)
        self.live_meters = live_meters
        self.refresh_s = refresh_s
        self.meter_store = MeterStore()
        self.log_feed: Feed[str] = Feed(5000)
        self.operator = ConsoleOperator()
        self.worker_ = RigWorker(
            rig_url,
            out_dir=self.out_dir,
            post=self._from_worker,
            meters=self.meter_store,
            operator=self.operator,
            meter_rate_hz=meter_rate_hz,
        )
        # the data sheet's nominal constants until the rig gives its own: the panel is up at once
        self.specs: tuple[MeterSpec, ...] = permanent_meters(RigCalibration())
        self.limits: SetpointLimits | None = None
        self.outcomes: list[CommandOutcome] = []  # every outcome, newest last (tests read it)
        self.stopped: WorkerStopped | None = None
        self.last_summary: RunSummary | None = None
        self._quitting = False
        self._meter_seq = -1
        self._handler = FeedHandler(self.log_feed)
        self.catalogue: dict[str, type[Procedure]] = {}
        self.adc_channels: tuple[str, ...] = ()
        self._saved_levels: dict[str, int] = {}

    # ------------------------------------------------------------------ layout
    def compose(self) -> ComposeResult:
        yield Static(id="too-small")
        yield StatusBar(self.rig_url, id="status")
        with TabbedContent(initial="meters"):
            for pid, title, key in PANELS:
                with TabPane(f"{key.upper()} {title}", id=pid):
                    yield self._panel(pid)
        yield Footer(compact=True)

    def _panel(self, pid: str):
        return {
            "meters": lambda: MeterPanel(id="meters-panel"),
            "modes": lambda: ModePanel(id="modes-panel"),
            "setpoints": lambda: SetpointPanel(id="setpoints-panel"),
            "recording": lambda: RecordingPanel(id="recording-panel"),
            "procedures": lambda: ProcedurePanel(id="procedures-panel"),
            "spectra": lambda: SpectraPanel(id="spectra-panel"),
        }[pid]()

    def on_mount(self) -> None:
        # the panels, looked up once: a modal screen on top hides them from query_one
        self.w_status = self.query_one("#status", StatusBar)
        self.w_meters = self.query_one("#meters-panel", MeterPanel)
        self.w_modes = self.query_one("#modes-panel", ModePanel)
        self.w_setpoints = self.query_one("#setpoints-panel", SetpointPanel)
        self.w_recording = self.query_one("#recording-panel", RecordingPanel)
        self.w_procedures = self.query_one("#procedures-panel", ProcedurePanel)
        self.w_spectra = self.query_one("#spectra-panel", SpectraPanel)
        # Tab moves between a panel's boxes, never onto the tab row: a panel's keys (F7, F8)
        # would not reach it from there
        for tabs in self.query(Tabs):
            tabs.can_focus = False
        logging.getLogger().addHandler(self._handler)
        # the live log shows the procedures' INFO records, whatever the host program configured
        self._saved_levels = {}
        for name in PROJECT_PACKAGES:
            pkg = logging.getLogger(name)
            self._saved_levels[name] = pkg.level
            if pkg.getEffectiveLevel() > logging.INFO:
                pkg.setLevel(logging.INFO)
        self.operator.ask = lambda q: self.post_message(RigNews(q))
        # the rig's start (numba kernels loading, holding the GIL) and the procedures' imports
        # wait for the first frame: the operator sees the panel at once
        self.call_after_refresh(self._start_background)
        self.set_interval(self.refresh_s, self.refresh_live)
        self.w_meters.show(self.specs, MeterSnapshot(0))
        self.w_meters.focus()
        self._check_size()

    def _start_background(self) -> None:
        if not self.worker_.stopped.is_set():
            self.worker_.start()
        self._load_catalogue()

    @work(thread=True, exclusive=True, group="catalogue")
    def _load_catalogue(self) -> None:
        # the procedures import the analysis stack (seconds): off the UI thread, so the meter
        # panel is up at once
        cat = _catalogue()
        self.call_from_thread(self._catalogue_loaded, cat)

    def _catalogue_loaded(self, cat: dict[str, type[Procedure]]) -> None:
        self.catalogue = cat
        self.w_procedures.set_catalogue(cat)
        self._next_recording()

    def _next_recording(self) -> None:
        """The file a recording with a blank name would get, shown in its box (the name shown
        is the name written). The naming rule is the runner's: asked once it is imported."""
        if self.catalogue:
            self.w_recording.set_next_path(default_path(self.out_dir))

    # ------------------------------------------------------------------ terminal size
    def on_resize(self, event: events.Resize) -> None:
        self._check_size(event.size)  # the new size: ``self.size`` follows after this handler

    def _check_size(self, size: Size | None = None) -> None:
        """A terminal smaller than the layout needs cuts lamps and meters off: say so on top."""
        w, h = size or self.size
        notice = self.query_one("#too-small", Static)
        small = w < MIN_SIZE[0] or h < MIN_SIZE[1]
        if small:
            notice.update(
                f"terminal {w}x{h} is too small: the console needs {MIN_SIZE[0]}x{MIN_SIZE[1]}; "
                "lamps, meters and keys are cut off. Enlarge it."
            )
        notice.display = small

    def stop_from_outside(self, why: str) -> None:
        """A signal or a lost terminal (``console.exitguard``, any thread): the rig thread
        stops (procedure aborted, recording closed, rig safe) and the app quits when it has."""
        self.worker_.request_shutdown(why)
        self._quitting = True

    def on_unmount(self) -> None:
        # Every way out (quit key, crash, signal) passes here: the rig goes safe and any
        # recording is closed with its status before the app is gone.
        exc = getattr(self, "_exception", None)
        reason = (
            f"the console crashed: {type(exc).__name__}: {exc}"
            if exc is not None
            else "the operator quit the console"
        )
        self.worker_.shutdown(reason)
        logging.getLogger().removeHandler(self._handler)
        for name, level in self._saved_levels.items():
            logging.getLogger(name).setLevel(level)

    # ------------------------------------------------------------------ keys
    def action_panel(self, pid: str) -> None:
        self.query_one(TabbedContent).active = pid
        self.query_one(f"#{pid}-panel").focus()

    def action_help(self) -> None:
        if isinstance(self.screen, HelpScreen) or len(self.screen_stack) > 1:
            return  # another question is open
        pid = self.query_one(TabbedContent).active
        key, title = next((k, t) for p, t, k in PANELS if p == pid)
        panel = self.query_one(f"#{pid}-panel")
        self.push_screen(HelpScreen(f"{key.upper()} {title}", getattr(panel, "KEY_HELP", ())))

    def on_tabbed_content_tab_activated(self, event: TabbedContent.TabActivated) -> None:
        # a panel shown (by key or by mouse) takes the focus, so its keys work at once
        pane = event.pane
        if pane.id and (self.focused is None or pane not in self.focused.ancestors_with_self):
            self.query_one(f"#{pane.id}-panel").focus()
        if pane.id == "recording":
            self._next_recording()  # another program may have taken the name meanwhile

    async def action_quit(self) -> None:
        if self._quitting or self.worker_.stopped.is_set():
            self.exit(0)
            return
        if isinstance(self.screen, QuitScreen):  # already asking
            return
        closes = what_quit_closes(self.worker_.state.get())
        if closes:  # a live recording or procedure: ask, naming what quitting would close
            self.push_screen(QuitScreen(closes), self._quit_answered)
            return
        self._quit_now()

    def _quit_answered(self, quit_: bool | None) -> None:
        if quit_:
            self._quit_now()
        else:
            self.worker_.events.put(RigEventItem(None, "console", "quit declined: still running"))

    def _quit_now(self) -> None:
        self._quitting = True
        self.w_status.note = "quitting: rig going safe…"
        self.worker_.request_shutdown("the operator quit the console")
        # a rig that never answers must not hold the console open; on_unmount waits once more
        self.set_timer(30.0, lambda: self.exit(0))

    # ------------------------------------------------------------------ from the rig thread
    def _from_worker(self, item: object) -> None:
        self.post_message(RigNews(item))

    def on_rig_news(self, msg: RigNews) -> None:
        item = msg.item
        if isinstance(item, RigReady):
            self.specs = permanent_meters(item.calibration)
            self.limits = SetpointLimits(item.calibration)
            self.w_setpoints.set_limits(self.limits)
            self.w_meters.set_channels(item.channels)
            self.adc_channels = item.channels
        elif isinstance(item, RigFailed):
            self.w_status.note = item.text
            self.notify(item.text, title="rig not open", severity="error", timeout=30)
        elif isinstance(item, CommandOutcome):
            self.outcomes.append(item)
            self._outcome(item)
        elif isinstance(item, RecordingEnded):
            self.w_spectra.offer(item.path, "the last recording")
            self._next_recording()
            self.notify(
                f"{item.path}: {item.status}",
                title="recording closed",
                severity="information" if item.status == "complete" else "error",
                timeout=8,
            )
        elif isinstance(item, ProcedureEnded):
            summary = item.summary
            self.last_summary = summary
            self.w_procedures.log_lines(self.log_feed.drain())
            self.w_procedures.finished(summary, item.plots)
            if summary.file is not None and summary.file.exists():
                self.w_spectra.offer(summary.file, f"the {summary.procedure} run's file")
        elif isinstance(item, RigFault):
            self.notify(
                f"{item.text}\nsafe state: {item.safe}",
                title="DEVICE FAULT",
                severity="error",
                timeout=60,
            )
        elif isinstance(item, WorkerStopped):
            self.stopped = item
            if self._quitting:
                self.exit(0)
        elif isinstance(item, OperatorQuestion):
            self.push_screen(OperatorScreen(item), item.reply)

    def _outcome(self, o: CommandOutcome) -> None:
        if o.what in ("hold", "release", "safe state") or o.what.startswith("select"):
            snap = self.worker_.state.get()
            same = not o.ok and o.text == snap.alarm  # said once, by the lamp
            self.w_modes.last(
                f"{o.what} refused: the alarm above says why" if same else o.text, o.ok, snap
            )
        elif o.what.startswith(("torquer", "command", "autocollimator", "caging")):
            self.w_setpoints.message(
                o.text if o.ok else f"refused: {o.text}", o.ok, state_key(self.worker_.state.get())
            )
        elif o.what.startswith("procedure ") and not o.ok:
            self.w_procedures.refused(o.text)
        elif o.what == "start recording" and o.ok:
            self._next_recording()  # the name just taken is not the next one any more
        if not o.ok:
            self.refuse(o.what, o.text)

    # ------------------------------------------------------------------ notifications
    def notify(
        self,
        message: str,
        *,
        title: str = "",
        severity: SeverityLevel = "information",
        timeout: float | None = None,
        markup: bool = True,
    ) -> None:
        """A toast, and a repaint of the whole screen once it has gone: an expired toast is
        removed from the DOM, but a terminal kept showing its text over the panel below."""
        super().notify(message, title=title, severity=severity, timeout=timeout, markup=markup)
        wait = self.NOTIFICATION_TIMEOUT if timeout is None else timeout
        self.set_timer(wait + 0.25, self._repaint_after_toast)

    def _repaint_after_toast(self) -> None:
        if self.is_running:
            self.screen.refresh(repaint=True, layout=True)

    # ------------------------------------------------------------------ refusals and notes
    def note(self, kind: str, text: str) -> None:
        """A line in the event log from this thread, at the rig time last read (it never asks the rig)."""
        self.worker_.events.put(RigEventItem(self.worker_.state.get().rig_time_s, kind, text))

    def refuse(
        self, what: str, text: str, severity: SeverityLevel = "error", timeout: float = 8
    ) -> None:
        """A refused entry or command: a notification, and a line in the event log. ``text``
        is in the operator's words (``console.refusals``), never the protocol's; plain text, as
        a refusal may quote brackets (``channels=["X"]``) that are no markup."""
        self.note("refused", f"{what}: {text}")
        self.notify(text, title=f"{what} refused", severity=severity, timeout=timeout, markup=False)

    # ------------------------------------------------------------------ the refresh timer
    def refresh_live(self) -> None:
        if not self.is_running:
            return
        snap = self.worker_.state.get()
        self.w_status.show(snap)
        if self.live_meters:
            meters = self.w_meters
            m = self.meter_store.snapshot(meters.chart_channels)
            if m.seq != self._meter_seq:
                self._meter_seq = m.seq
                meters.show(self.specs, m)
        self.w_modes.show(snap)
        self.w_setpoints.show(snap)
        self.w_recording.show(snap)
        events = self.worker_.events.drain()
        if events:
            self.w_recording.log_events(events)
        procs = self.w_procedures
        if procs.running:
            procs.show(snap.procedure)
            procs.log_lines(self.log_feed.drain())
        else:
            self.log_feed.drain()  # only a procedure's log is shown live

    def show_meter_frame(self, snap: MeterSnapshot) -> None:
        """Draw a given meter snapshot (pinned screens in tests: live_meters=False)."""
        self.w_meters.show(self.specs, snap)

    # ------------------------------------------------------------------ panel requests
    def _refuse_if_busy(self) -> bool:
        why = self.worker_.busy
        if why:
            self.refuse("command", why, severity="warning", timeout=6)
            return True
        return False

    def on_mode_panel_command(self, msg: ModePanel.Command) -> None:
        if msg.what == "safe":  # the safe state is never refused (it aborts a procedure first)
            if self.worker_.state.get().phase == "procedure":
                self.worker_.abort_procedure()
                return
            self.worker_.go_safe()
            return
        if self._refuse_if_busy():
            return
        if msg.what == "select":
            assert msg.mode is not None  # the panel's select command always names its mode
            self.worker_.select(msg.mode)
            return
        {"hold": self.worker_.hold, "release": self.worker_.release}[msg.what]()

    def on_setpoint_panel_request(self, msg: SetpointPanel.Request) -> None:
        if self._refuse_if_busy():
            return
        w = self.worker_
        if msg.kind is Entry.TORQUER_BIAS:
            w.set_torquer_bias(msg.key, float(msg.value), msg.slew)
        elif msg.kind is Entry.COMMAND_TORQUE:
            w.set_command_torque(msg.key, float(msg.value))
        elif msg.kind is Entry.AC_BIAS:
            w.set_ac_bias(msg.key, float(msg.value))
        elif msg.kind is Entry.CAGING:
            w.set_caging_inhibit(msg.key, bool(msg.value))

    def on_setpoint_panel_refused(self, msg: SetpointPanel.Refused) -> None:
        self.refuse(msg.what, msg.text, timeout=6)

    def on_recording_panel_start(self, msg: RecordingPanel.Start) -> None:
        if self._refuse_if_busy():
            return
        try:
            rate = float(msg.rate)
            if not rate > 0:
                raise ValueError
        except ValueError:
            self.refuse("recording", f"sample rate {msg.rate!r} is not a positive number of Hz")
            return
        channels = tuple(c.strip() for c in msg.channels.split(",") if c.strip()) or None
        if channels == ("all",):
            channels = None
        why = (
            unknown_channels(channels or (), self.adc_channels, "the ADC")
            if self.adc_channels
            else None
        )
        if why:
            self.refuse("recording", why, timeout=10)
            return
        self.worker_.start_recording(recording_path(msg.path, self.out_dir), rate, channels)

    def on_recording_panel_stop(self, msg: RecordingPanel.Stop) -> None:
        self.worker_.stop_recording()

    def on_procedure_panel_run(self, msg: ProcedurePanel.Run) -> None:
        if self._refuse_if_busy():
            return
        if self.worker_.state.get().phase == "recording":
            self.refuse(
                "procedure",
                "a recording is running: stop it (f4, f8) before a procedure, which records "
                "its own file",
                severity="warning",
                timeout=6,
            )
            return
        cls = self.catalogue.get(msg.name)
        if cls is None:
            self.refuse(
                "procedure",
                f"no procedure {msg.name!r}"
                if self.catalogue
                else "the procedures are still loading",
            )
            return
        try:
            proc, resume_from = parse_run_text(cls, msg.params)
        except (ValueError, TypeError) as exc:  # refused before the rig is touched
            self.refuse(f"procedure {msg.name} parameters", str(exc), timeout=10)
            return
        self.log_feed.drain()
        self.w_procedures.started(proc.name, resume_from)
        self.worker_.run_procedure(proc, resume_from)

    def on_procedure_panel_abort(self, msg: ProcedurePanel.Abort) -> None:
        if not self.worker_.abort_procedure():
            self.notify("no procedure is running", severity="warning", timeout=4)


def _catalogue() -> dict[str, type[Procedure]]:
    from procedures.calibrations import catalogue

    return catalogue()


def run_console(rig_url: str = DEFAULT_RIG, out_dir: str | Path = "out") -> int:
    """Run the console in this terminal; the rig is safe and closed when this returns."""
    out = Path(out_dir)
    # The terminal belongs to the console: log records go to a file and the live log, never
    # to stderr (Textual draws on it).
    root = logging.getLogger()
    saved = root.handlers[:]
    from daq.runfile import make_folder

    make_folder(out)
    # this program's records from INFO, other libraries' from WARNING (drivers.logrule)
    file_handler = ruled(logging.FileHandler(out / "console.log"))
    root.handlers[:] = [file_handler]
    restore_levels = set_levels()
    app = ConsoleApp(rig_url, out_dir=out)
    # SIGHUP (the SSH session or tmux window went), SIGTERM, a hung-up terminal: leave, screen or not
    guard = ExitGuard(app.stop_from_outside, app.worker_.shutdown).install()
    try:
        app.run()
    finally:
        guard.done()
        app.worker_.shutdown("the console exited")  # already done by on_unmount; a no-op then
        root.handlers[:] = saved
        restore_levels()
        file_handler.close()
    if app.stopped is not None:
        print(exit_line(app.stopped))
    return EXIT_SIGNALLED if guard.tripped else (app.return_code or 0)


def exit_line(stopped: WorkerStopped) -> str:
    """The line ``fbs console`` leaves on the terminal: why the rig closed, whether it is safe,
    and every file the shutdown closed, by name, with its status."""
    line = f"fbs console: rig closed ({stopped.reason}); safe state: {stopped.safe}"
    if stopped.closed:
        line += "; closed " + "; ".join(stopped.closed)
    return line
