"""The one thread that owns the rig.

Every call that reaches hardware happens here, so the UI thread never waits on a device.
The UI hands over commands (``submit`` puts a closure on a queue) and reads ``LiveState``;
outcomes come back through ``post`` (the app turns them into Textual messages).

Each tick (``tick_s``, 50 ms) the thread

* runs the queued commands (mode switches, set-points, start/stop recording, a procedure);
* reads the ADC up to "now": the idle meter stream (all channels at ``meter_rate_hz``) or
  the recording (``daq.recorder.Acquisition``, the operator's channels and rate). "Now" is
  the wall clock in both time modes, so a virtual-time rig is paced like a real one while
  the console watches it; every block passes the meter tap (``TappedAdc``);
* moves slewing torquer biases one step (``Slew``), and polls the relay status and the
  set-point read-backs.

A procedure runs on this thread too (``run_procedure``, blocking the loop): the UI refuses
other commands meanwhile, and aborts through a ``threading.Event`` that needs no queue. The
procedure shares the rig through this owner rather than stopping it: its rig time passes
through its recording, and after every block the ADC tap hands the thread back to the owner
(``TappedAdc.after_block``), which polls the relay status and the read-backs on rig time
(``status_every_s``, ``readback_every_s``); a command the procedure gives (its rig event: a mode,
a set-point, the safe state) is read back at once. So the header, the Modes and the Set-points
panels follow the rig within a second of rig time, in virtual time too.

Safe-state guarantees: the thread holds the rig inside ``drivers.safety.SafeOnAbort``, the
one piece of code that drives the rig safe on an abort. A recording that ends any way but the
operator's stop (a device fault, a full disk, quit, a crash of the app or of this thread)
goes through it before its file is closed "aborted: <why>"; so does any exception that ends
this thread. A device fault is latched by the drivers too (the rig goes safe by itself), and
stops the thread's commands. ``request_shutdown`` (quit, or the app crashing) aborts a
running procedure (the runner's own guard makes the rig safe), closes a recording "aborted:
ConsoleClosed: <why>", and closes the rig, which leaves it safe.
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

from console.adctap import TappedAdc
from console.feeds import Feed
from console.meterdata import MeterStore
from console.operator import ConsoleOperator
from console.refusals import operator_words
from console.reportfiles import report_plots
from console.slew import Slew
from console.spinup import SpinUpEstimate
from console.state import (
    CommandOutcome,
    LiveState,
    Phase,
    ProcedureEnded,
    ProcedureInfo,
    RecordingEnded,
    RecordingInfo,
    RigEventItem,
    RigFailed,
    RigFault,
    RigReady,
    WorkerStopped,
)
from drivers.canopen_client import ABORT_NOT_HELD
from drivers.errors import DriverError, InterlockError, SampleGap, SetpointRangeError
from drivers.relay import MODES, RelayStatus, interlock_reason
from drivers.rig import Rig, open_rig
from drivers.safety import SafeOnAbort, go_safe
from drivers.setpoints import SetpointKind

if TYPE_CHECKING:  # the analysis stack is imported when a recording or a procedure starts
    from daq.recorder import Acquisition
    from procedures.procedure import Procedure
    from procedures.progress import Progress

log = logging.getLogger(__name__)

#: Refusals change nothing on the rig (drivers/errors.py); anything else is a fault.
REFUSALS = (SetpointRangeError, InterlockError, ValueError, OSError)
#: rig events after which a running procedure's state is read back at once
_STATE_EVENTS = frozenset({"mode", "setpoint", "safe", "alarm"})


class ConsoleClosed(Exception):
    """The console closed a recording it had open (quit, crash): the file's status says why."""


class Refused(Exception):
    """The console itself refuses a command in the present state (nothing was sent)."""


@dataclass
class Command:
    what: str
    run: Callable[[], str]


class RigWorker:
    def __init__(
        self,
        url: str,
        *,
        out_dir: str | Path,
        post: Callable[[object], None],
        meters: MeterStore,
        events: Feed[RigEventItem] | None = None,
        operator: ConsoleOperator | None = None,
        meter_rate_hz: float = 200.0,
        tick_s: float = 0.05,
        status_every_s: float = 0.5,
        readback_every_s: float = 1.0,
    ) -> None:
        self.url = url
        self.out_dir = Path(out_dir)
        self.post_event = post
        self.meters = meters
        self.events: Feed[RigEventItem] = events if events is not None else Feed()
        self.operator = operator
        self.meter_rate_hz = meter_rate_hz
        self.tick_s = tick_s
        self.status_every_s = status_every_s
        self.readback_every_s = readback_every_s
        self.state = LiveState()
        self.rig: Rig | None = None
        self._safety: SafeOnAbort | None = None  # around everything the thread does with the rig
        self._queue: queue.Queue[Command | None] = queue.Queue()
        self._stop = threading.Event()
        self._stop_reason = ""
        self._abort = threading.Event()
        self._thread = threading.Thread(target=self._run, name="console-rig", daemon=True)
        self._acq: Acquisition | None = None  # while recording
        self._streaming = False  # the idle meter stream (or the recording) is running
        self._stream_rate = 0.0
        self._stream_pos = 0
        self._stream_wall0 = 0.0
        self._slews: dict[str, Slew] = {}
        self._next_status = 0.0
        self._next_readback = 0.0
        self._sharing = False  # a procedure runs on this thread: poll on rig time
        self._next_status_rig = 0.0
        self._next_readback_rig = 0.0
        self._quiet_setpoints = False  # a slew's steps: one line in the event log, not one a step
        self._fault_handled = False
        self._alarm_not_held = False  # the lamp is lit by a selection without hold
        self._alarm_mode: int | None = None  # the lamp is lit by this mode's refused release
        self._spin = SpinUpEstimate()
        #: the files the shutdown closed, "path (status)", for the console's exit line
        self.closed_on_stop: list[str] = []
        self.stopped = threading.Event()

    # ================================================================== UI side (any thread)
    def start(self) -> None:
        self._thread.start()

    def submit(self, what: str, run: Callable[[], str]) -> None:
        self._queue.put(Command(what, run))

    def request_shutdown(self, reason: str) -> None:
        """Abort a procedure, close a recording "aborted: <reason>", leave the rig safe, stop."""
        if not self._stop.is_set():
            self._stop_reason = reason
            self._stop.set()
            self._abort.set()
            if self.operator is not None:
                self.operator.close()
            self._queue.put(None)  # wake the thread

    def shutdown(self, reason: str, timeout_s: float = 30.0) -> bool:
        """``request_shutdown`` and wait for the thread; True when it finished."""
        self.request_shutdown(reason)
        if self._thread.is_alive() and threading.current_thread() is not self._thread:
            self._thread.join(timeout_s)
        return not self._thread.is_alive()

    def abort_procedure(self) -> bool:
        snap = self.state.get()
        if snap.procedure is None:
            return False
        self._abort.set()
        self.state.update(procedure=replace(snap.procedure, aborting=True))
        return True

    @property
    def busy(self) -> str | None:
        """Why commands are refused now (a procedure owns the rig, a fault, closed), or None."""
        snap = self.state.get()
        if snap.phase is Phase.PROCEDURE:
            return f"procedure {snap.procedure.name if snap.procedure else ''} is running: abort it first (f8)"
        if snap.phase is Phase.FAULT:
            return f"the rig is faulted and safe ({snap.fault}); quit and reopen the console"
        if snap.phase in (Phase.OPENING, Phase.CLOSED):
            return f"the rig is {snap.phase}"
        return None

    # -- commands (each runs on the rig thread)
    def hold(self) -> None:
        self.submit("hold", self._hold)

    def select(self, mode: int) -> None:
        self.submit(f"select mode {mode}", lambda: self._select(mode))

    def release(self) -> None:
        self.submit("release", self._release)

    def go_safe(self) -> None:
        self.submit("safe state", self._go_safe)

    def set_torquer_bias(self, channel: str, volts: float, slew_V_per_s: float) -> None:
        self.submit(f"torquer bias {channel}", lambda: self._slew_to(channel, volts, slew_V_per_s))

    def set_command_torque(self, axis: str, volts: float) -> None:
        self.submit(
            f"command torque {axis}",
            lambda: self._set_output(SetpointKind.COMMAND_TORQUE, axis, volts),
        )

    def set_ac_bias(self, axis: str, volts: float) -> None:
        self.submit(
            f"autocollimator bias {axis}",
            lambda: self._set_output(SetpointKind.AC_BIAS, axis, volts),
        )

    def set_caging_inhibit(self, channel: str, inhibit: bool) -> None:
        self.submit(f"caging inhibit {channel}", lambda: self._caging(channel, inhibit))

    def start_recording(self, path: Path, rate_hz: float, channels: tuple[str, ...] | None) -> None:
        self.submit("start recording", lambda: self._start_recording(path, rate_hz, channels))

    def stop_recording(self) -> None:
        self.submit("stop recording", self._stop_recording)

    def run_procedure(self, proc: Procedure, resume_from: Path | None = None) -> None:
        """Run a ``Procedure`` instance (parameters already parsed) into ``out_dir``; with
        ``resume_from``, continue that aborted run of it (its parameters, its steps done), as
        ``fbs run NAME --resume FILE`` does."""
        prev = self.state.get().phase
        if prev is Phase.READY:  # the UI refuses other commands from now on (``busy``)
            self.state.update(phase=Phase.PROCEDURE, procedure=ProcedureInfo(proc.name))
        self.submit(f"procedure {proc.name}", lambda: self._run_procedure(proc, prev, resume_from))

    # ================================================================== the rig thread
    @property
    def _rig(self) -> Rig:
        """The open rig: the thread runs commands only once it is open."""
        if self.rig is None:
            raise Refused("the rig is not open")
        return self.rig

    @property
    def _abort_guard(self) -> SafeOnAbort:
        if self._safety is None:
            raise Refused("the rig is not open")
        return self._safety

    def _post(self, item: object) -> None:
        try:
            self.post_event(item)
        except Exception:  # the UI may be gone (shutting down): the rig thread goes on
            log.debug("could not post %r", item, exc_info=True)

    def _note(self, kind: str, text: str) -> None:
        """A console note for the event log, stamped with the rig's time (this is its thread)."""
        try:
            t: float | None = self.rig.now() if self.rig is not None else None
        except Exception:  # a clock that cannot answer: the wall time alone
            t = None
        self.events.put(RigEventItem(t, kind, text))

    def _on_rig_event(self, t: float, kind: str, text: str) -> None:
        if not (self._quiet_setpoints and kind == "setpoint"):
            self.events.put(RigEventItem(t, kind, text))
        # a command a running procedure gave: read it back now (only on this thread, which
        # owns the devices; a fault's event comes from the driver's receive thread)
        if self._sharing and kind in _STATE_EVENTS and threading.current_thread() is self._thread:
            try:
                self._poll_shared(status=kind != "setpoint", readback=True)
            except DriverError as exc:  # the procedure meets a fault on its own next call
                log.debug("reading the rig back after %s: %s", kind, exc)

    def _run(self) -> None:
        reason = ""
        try:
            try:
                rig = open_rig(self.url, operator=self.operator)
            except Exception as exc:  # a bad URL or a missing device: say so, nothing to make safe
                log.error("cannot open the rig %s: %s", self.url, exc)
                self.state.update(
                    phase=Phase.CLOSED, fault=f"cannot open the rig {self.url}: {exc}"
                )
                self._post(RigFailed(f"cannot open the rig {self.url}: {exc}"))
                return
            self.rig = rig
            self._safety = SafeOnAbort(rig, "the console")
            rig.adc = TappedAdc(rig.adc, self.meters, after_block=self._poll_shared)
            rig.subscribe(self._on_rig_event)
            self.state.update(phase=Phase.READY)
            self._note(
                "console",
                f"rig {self.url} open ({'virtual' if rig.clock.virtual else 'paced'} time)",
            )
            self._post(
                RigReady(
                    self.url, rig.calibration, tuple(rig.adc.identity.channels), rig.clock.virtual
                )
            )
            with self._safety:  # whatever ends this thread but a quit, the rig goes safe first
                self._guard(self._start_meter_stream)
                self._guard(lambda: self._poll(force=True))
                while not self._stop.is_set():
                    self._serve(time.monotonic() + self.tick_s)
                    if self._stop.is_set():
                        break
                    self._tick()
        except BaseException as exc:  # noqa: B036 - whatever kills this thread, the rig goes safe below
            log.exception("the console's rig thread failed")
            reason = f"the console's rig thread failed: {type(exc).__name__}: {exc}"
        finally:
            self._close(self._stop_reason or reason or "console closed")

    def _serve(self, until: float) -> None:
        """Run queued commands until ``until`` (monotonic s)."""
        while True:
            left = until - time.monotonic()
            try:
                cmd = (
                    self._queue.get(timeout=max(0.0, left))
                    if left > 0
                    else self._queue.get_nowait()
                )
            except queue.Empty:
                return
            if cmd is None or self._stop.is_set():
                return
            self._execute(cmd)

    def _execute(self, cmd: Command) -> None:
        if self.state.get().phase in (Phase.FAULT, Phase.CLOSED):
            self._post(CommandOutcome(cmd.what, False, self.busy or "the rig is not available"))
            return
        try:
            text = cmd.run()
        except Refused as exc:
            self._post(CommandOutcome(cmd.what, False, str(exc)))
        except REFUSALS as exc:  # the raw text here, the operator's words on the screen
            log.info("%s refused: %s", cmd.what, exc)
            self._post(CommandOutcome(cmd.what, False, operator_words(cmd.what, exc)))
            if isinstance(exc, DriverError):
                self._check_fault()
        except DriverError as exc:
            log.error("%s failed: %s", cmd.what, exc)
            self._post(CommandOutcome(cmd.what, False, operator_words(cmd.what, exc)))
            self._check_fault()
        else:
            self._post(CommandOutcome(cmd.what, True, text))

    def _guard(self, fn: Callable[[], object]) -> None:
        """Run ``fn``; a driver error there is a fault (or logged), never the end of the thread."""
        try:
            fn()
        except DriverError as exc:
            log.error("%s", exc)
            self._check_fault()

    def _tick(self) -> None:
        if self._check_fault():
            return
        try:
            self._stream_due()
        except BaseException as exc:  # noqa: B036 - the recording is closed with its status, then we go on
            if self._acq is not None:
                self._end_recording(exc)
            elif not isinstance(exc, DriverError):
                raise
            else:
                log.error("meter stream: %s", exc)
                self._streaming = False
            self._check_fault()
            return
        self._guard(self._advance_slews)
        self._guard(self._poll)

    # ------------------------------------------------------------------ streaming
    def _start_meter_stream(self) -> None:
        rig = self._rig
        channels = tuple(rig.adc.identity.channels)
        cfg = rig.adc.configure(channels, self.meter_rate_hz)
        rig.adc.start()
        self._begin_stream(cfg.rate_hz)

    def _begin_stream(self, rate_hz: float) -> None:
        self._streaming = True
        self._stream_rate = rate_hz
        self._stream_pos = 0
        self._stream_wall0 = time.monotonic()

    def _stop_meter_stream(self) -> None:
        if self._streaming and self._acq is None:
            self._streaming = False
            try:
                self._rig.adc.stop()
            finally:
                self.meters.clear()

    def _stream_due(self) -> None:
        if not self._streaming:
            return
        # Samples up to a little before now: a paced rig delivers ~10 ms frames, and asking
        # for samples not yet taken would block this thread (and the commands) until they are.
        due = (
            int((time.monotonic() - self._stream_wall0 - 0.03) * self._stream_rate)
            - self._stream_pos
        )
        if due <= 0:
            return
        if due > 2 * self._stream_rate and self._rig.clock.virtual:
            # a virtual rig slower than the wall clock: skip ahead (nothing is lost, the
            # simulation only computes what is read), so the commands are not starved
            self._stream_wall0 += (due - self._stream_rate) / self._stream_rate
            due = int(self._stream_rate)
        due = min(due, int(2 * self._stream_rate))
        if self._acq is not None:
            self._acq.acquire_samples(due, keep=False)
            self._stream_pos = self._acq.pos
            r = self._acq.result
            self.state.update(
                recording=RecordingInfo(
                    r.path,
                    self._acq.rate_hz,
                    self._acq.channels,
                    self._acq.time_s,
                    self._acq.pos,
                    len(r.gaps),
                    r.lost,
                )
            )
            return
        try:
            block = self._rig.adc.read(due)
            self._stream_pos = block.stop_sample
        except SampleGap as gap:  # the meters skip it; only a recording has to account for it
            self._note("gap", f"meter stream: {gap}")
            self._stream_pos = gap.stop

    # ------------------------------------------------------------------ recording
    def _start_recording(self, path: Path, rate_hz: float, channels: tuple[str, ...] | None) -> str:
        from daq.recorder import Acquisition
        from daq.runfile import check_new_path

        if self._acq is not None:
            raise Refused(f"already recording to {self._acq.result.path}; stop it first")
        check_new_path(path)  # a bad name is refused before the meter stream stops
        self._stop_meter_stream()
        try:
            acq = Acquisition(
                self._rig,
                path,
                rate_hz=rate_hz,
                channels=channels,
                block_s=0.05,
                meta={"console": {"rig": self.url}},
            )
            acq.start()
        except BaseException:
            self._guard(self._start_meter_stream)
            raise
        self._acq = acq
        self._begin_stream(acq.rate_hz)
        self.state.update(
            phase=Phase.RECORDING, recording=RecordingInfo(Path(path), acq.rate_hz, acq.channels)
        )
        return f"recording {len(acq.channels)} channels at {acq.rate_hz:g} Hz to {path}"

    def _stop_recording(self) -> str:
        if self._acq is None:
            raise Refused("not recording")
        info = self._end_recording(None)
        self._guard(self._start_meter_stream)
        return f"recording closed: {info.path}, {info.samples} samples, status {info.status}"

    def _end_recording(self, exc: BaseException | None) -> RecordingInfo:
        """Close the recording: "complete" without ``exc``; else the rig safe first (the
        thread's ``SafeOnAbort``, so the file records it), then the file "aborted: <exc>"."""
        acq, self._acq = self._acq, None
        if acq is None:
            raise Refused("not recording")
        self._streaming = False
        if exc is not None:
            self._abort_guard.abort(exc)
        try:
            acq.close(exc)
        except BaseException as late:  # noqa: B036 - closing failed: the file says aborted; safe, go on
            log.error("closing the recording failed: %s", late)
            self._abort_guard.abort(late)
        r = acq.result
        info = RecordingInfo(
            r.path, acq.rate_hz, acq.channels, acq.time_s, acq.pos, len(r.gaps), r.lost, r.status
        )
        phase = self.state.get().phase
        self.state.update(
            phase=Phase.READY if phase is Phase.RECORDING else phase,
            recording=info,
            last_file=r.path,
        )
        self._note("recording", f"{r.path}: {r.status}, {acq.pos} samples, {len(r.gaps)} gap(s)")
        if self._stop.is_set():
            self.closed_on_stop.append(f"recording {r.path} ({r.status})")
        self._post(RecordingEnded(r.path, r.status, acq.pos, len(r.gaps)))
        if exc is not None:
            self._slews.clear()
        return info

    # ------------------------------------------------------------------ procedure
    def _run_procedure(
        self, proc: Procedure, prev: Phase = Phase.READY, resume_from: Path | None = None
    ) -> str:
        from procedures.params import find_prior
        from procedures.procedure import ProcedureError
        from procedures.resume import load_resume
        from procedures.runner import run_procedure

        try:
            if self._acq is not None:
                raise Refused(
                    f"recording to {self._acq.result.path}: stop it before running a procedure"
                )
            resume = None
            if resume_from is not None:
                try:  # the file is read here, not on the UI thread
                    resume = load_resume(resume_from, type(proc))
                    proc = type(proc)(type(proc).params_from(resume.params), prior=proc.prior)
                except (ProcedureError, ValueError, OSError) as exc:
                    raise Refused(str(exc)) from None
            proc.prior = find_prior(self.out_dir) | dict(proc.prior)
            self._stop_meter_stream()
            self._slews.clear()
            self._abort.clear()
            if self._stop.is_set():
                raise Refused("the console is closing")
            from daq.runfile import make_folder
            from procedures.resume import run_file_for
            from procedures.runlog import RunLog

            make_folder(self.out_dir)
            # the file run_procedure will pick (it takes the same next free name), shown while it runs
            run_file = run_file_for(self.out_dir, proc.name, resume)
            self.state.update(procedure=ProcedureInfo(proc.name, file=run_file))
            now = self._rig.now()
            self._next_status_rig = self._next_readback_rig = now
            self._sharing = True
            try:
                # its log beside its file, as ``fbs run`` writes it
                with RunLog() as runlog:
                    runlog.open(run_file.with_suffix(".log"))
                    log.info(
                        "procedure %s %s (parameters %s) from the console on rig %s",
                        proc.name,
                        f"resuming {resume.path}" if resume else "starting",
                        proc.params_json(),
                        self.url,
                    )
                    summary = run_procedure(
                        proc,
                        self._rig,
                        self.out_dir,
                        resume=resume,
                        progress=self._on_progress,
                        abort=self._abort,
                    )
                    runlog.follow(summary.file)
            finally:
                self._sharing = False
        except BaseException:
            self.state.update(
                phase=prev if prev in (Phase.READY, Phase.RECORDING) else Phase.READY,
                procedure=None,
            )
            if not self._stop.is_set() and self._acq is None and not self._streaming:
                self._guard(self._start_meter_stream)
            if not self._stop.is_set() and not self._check_fault():
                self._guard(
                    lambda: self._poll(force=True)
                )  # the panels show the safe state at once
            raise
        self.state.update(phase=Phase.READY, procedure=None, last_file=summary.file)
        if self._stop.is_set() and summary.file is not None:
            self.closed_on_stop.append(
                f"procedure {proc.name}'s file {summary.file} ({summary.status})"
            )
        self._post(ProcedureEnded(summary, report_plots(summary.report)))
        self._note(
            "procedure", f"{proc.name}: {summary.verdict} ({summary.status}); file {summary.file}"
        )
        if not self._check_fault() and not self._stop.is_set():
            self._guard(self._start_meter_stream)
            self._guard(lambda: self._poll(force=True))
        return f"{proc.name}: {summary.verdict}, status {summary.status}"

    def _on_progress(self, p: Progress) -> None:
        cur = self.state.get().procedure
        self.state.update(
            procedure=ProcedureInfo(
                p.procedure,
                p.step,
                p.index,
                p.n_steps,
                p.fraction,
                p.remaining_rig_s,
                p.remaining_wall_s,
                cur.file if cur else None,
                bool(cur and cur.aborting),
                p.phase,
            )
        )

    # ------------------------------------------------------------------ modes
    def _hold(self) -> str:
        self._rig.relays.hold()
        if self._alarm_not_held:  # its cause is gone: the switches are held now
            self._alarm(None)
        self._poll(force=True)
        return "mode switches held: select a mode (1-6), then release"

    def _alarm(self, text: str | None, *, not_held: bool = False) -> None:
        """Light the alarm lamp with ``text`` (in the operator's words), or put it out."""
        self._alarm_not_held = not_held and text is not None
        self._alarm_mode = None
        self.state.update(alarm=text)
        if text is not None:
            self._rig.event("alarm", text)

    def _select(self, mode: int) -> str:
        relays = self._rig.relays
        try:
            relays.select(mode)
        except InterlockError as exc:
            # a disallowed mode (0, 7) lights the alarm, and so does a selection without hold:
            # an operator's slip, said in words with what to do
            if mode not in MODES:
                self._alarm(str(exc))
            else:
                self._alarm(
                    operator_words(f"select mode {mode}", exc),
                    not_held=exc.detail == ABORT_NOT_HELD,
                )
            raise
        relays.alarm = None
        self._alarm(None)
        self._poll(force=True)
        return f"mode {mode} ({MODES[mode]}) selected: release to switch"

    def _release(self) -> str:
        relays = self._rig.relays
        status = relays.status()
        why = interlock_reason(status.selected, status) if status.held else None
        try:
            now = relays.release()
        except InterlockError as exc:
            # a refused mode change lights the alarm with its reason; so does a release unheld
            text = why or operator_words("release", exc)
            if status.held:
                relays.alarm = text
            self._alarm(text, not_held=not status.held)
            if why is not None:
                self._alarm_mode = status.selected  # its words follow the rig (``_refused_alarm``)
            self._poll(force=True)
            log.info("release refused: %s", exc)  # the node's raw refusal, for the log
            raise InterlockError(text) from None
        relays.alarm = None
        self._alarm(None)
        self._rig.event("mode", f"mode {now}")
        self._poll(force=True)
        return f"mode {now} ({MODES.get(now, '?')}) in force"

    def _go_safe(self) -> str:
        self._slews.clear()
        report = go_safe(self._rig, "the operator asked for the safe state")
        self._alarm_mode = None
        self.state.update(alarm=None, slewing={})
        self._poll(force=True)
        if not report.ok:
            raise DriverError("safe state incomplete: " + "; ".join(report.failed))
        return "safe state: mode 1, biases and commands zero, caging released (read back)"

    # ------------------------------------------------------------------ set-points
    def _slew_to(self, channel: str, volts: float, rate: float) -> str:
        rig = self._rig
        rig.torquers.limits.torquer_bias(channel, volts)  # refused here, before the ramp starts
        now = rig.torquers.bias_V(channel)
        self._slews[channel] = Slew(channel, volts, rate, now, rig.now())
        self.state.update(slewing={c: s.target_V for c, s in self._slews.items()})
        return f"torquer bias {channel}: slewing {now:+.4f} -> {volts:+.4f} V at {rate:g} V/s"

    def _advance_slews(self) -> None:
        if not self._slews:
            return
        t = self._rig.now()
        back = dict(self.state.get().readback)
        for ch, s in list(self._slews.items()):
            v = s.step(t)
            self._quiet_setpoints = (
                True  # the steps are in the rig's events (a recording keeps them)
            )
            try:
                back[f"torq {ch}"] = self._rig.set_torquer_bias_V(ch, v)
            finally:
                self._quiet_setpoints = False
            if s.done:
                del self._slews[ch]
                self._note(
                    "setpoint",
                    f"torquer bias {ch} {s.start_V:+.4f} -> {s.target_V:+.4f} V at "
                    f"{s.rate_V_per_s:g} V/s in {s.steps} step(s), {t - s.t0:.2f} s; "
                    f"read back {back[f'torq {ch}']:+.4f} V",
                )
        self.state.update(readback=back, slewing={c: s.target_V for c, s in self._slews.items()})

    def _set_output(self, kind: SetpointKind, axis: str, volts: float) -> str:
        rig = self._rig
        if kind is SetpointKind.COMMAND_TORQUE:
            back, key = rig.set_command_torque_V(axis, volts), f"vtd {axis}"
        else:
            back, key = rig.set_ac_bias_V(axis, volts), f"gc {axis}"
        self.state.update(readback=dict(self.state.get().readback) | {key: back})
        return f"{kind} {axis} = {back:+.4f} V (read back)"

    def _caging(self, channel: str, inhibit: bool) -> str:
        back = self._rig.set_caging_inhibit(channel, inhibit)
        self.state.update(caging=dict(self.state.get().caging) | {channel: back})
        return f"caging {channel} {'inhibited' if back else 'enabled'} (read back)"

    # ------------------------------------------------------------------ polling
    def _poll(self, force: bool = False) -> None:
        """On the thread's tick (idle, recording): on the wall clock."""
        now = time.monotonic()
        status, readback = force or now >= self._next_status, force or now >= self._next_readback
        if status:
            self._next_status = now + self.status_every_s
        if readback:
            self._next_readback = now + self.readback_every_s
        self._read_state(status, readback)

    def _poll_shared(self, *, status: bool = False, readback: bool = False) -> None:
        """While a procedure runs on this thread: on rig time, after each block of its
        recording and at once after its commands (``status``, ``readback`` force them)."""
        if not self._sharing or self.rig is None or self.rig.faults.fault is not None:
            return
        t = self.rig.now()
        # due a quarter interval early: block ends jitter by a frame around the schedule, and a
        # poll just missed would wait a whole block more
        status = status or t >= self._next_status_rig - 0.25 * self.status_every_s
        readback = readback or t >= self._next_readback_rig - 0.25 * self.readback_every_s
        if status:
            self._next_status_rig = t + self.status_every_s
        if readback:
            self._next_readback_rig = t + self.readback_every_s
        self._read_state(status, readback)

    def _read_state(self, status: bool, readback: bool) -> None:
        rig = self._rig
        changes: dict[str, object] = {}
        if status:
            st = rig.relays.status()
            changes["relay"] = st
            # the wheels run in every mode but 1: how long until they are at speed
            changes["spin_left_s"] = self._spin.observe(rig.now(), st.spin_fraction, st.mode >= 2)
            if self._alarm_mode is not None:
                changes["alarm"] = self._refused_alarm(self._alarm_mode, st)
        if readback:
            back = {f"torq {c}": rig.torquers.bias_V(c) for c in rig.torquers.channels}
            for a in rig.commands.axes:
                back[f"vtd {a}"] = rig.commands.command_torque_V(a)
                back[f"gc {a}"] = rig.commands.ac_bias_V(a)
            changes["readback"] = back
            changes["caging"] = {c: rig.caging.inhibited(c) for c in rig.caging.channels}
        if changes:
            changes["rig_time_s"] = rig.now()
            self.state.update(**changes)

    def _refused_alarm(self, mode: int, st: RelayStatus) -> str | None:
        """The lamp of a refused release, in words of the state now, not of the moment it was
        refused: "wheels at 21 %" must not stand beside "wheels 99 %". It goes out when its
        cause is gone - the interlock is met, or the mode is in force (the event log says so)
        - or, as every alarm, with the next mode command or the safe state."""
        reason = None if st.mode == mode else interlock_reason(mode, st)
        if reason is None:
            self._alarm_mode = None
            self._rig.relays.alarm = None
            self._note(
                "alarm",
                f"alarm out: mode {mode}'s interlocks are met now (h {mode} r enters it)"
                if st.mode != mode
                else f"alarm out: mode {mode} is in force",
            )
            return None
        self._rig.relays.alarm = reason
        return reason

    # ------------------------------------------------------------------ faults and the end
    def _check_fault(self) -> bool:
        """True if a device fault is latched; the first time, end everything and tell the UI."""
        rig = self.rig
        if rig is None or rig.faults.fault is None:
            return False
        if self._fault_handled:
            return True
        self._fault_handled = True
        fault = rig.faults.fault
        log.error("rig fault: %s", fault)
        if self._acq is not None:
            self._end_recording(fault)
        self._streaming = False
        self._slews.clear()
        self.meters.clear()
        safe = _safe_text(rig)
        self.state.update(phase=Phase.FAULT, fault=str(fault), slewing={})
        self._note("fault", f"{fault}; safe state: {safe}")
        self._post(RigFault(str(fault), safe))
        return True

    def _close(self, reason: str) -> None:
        rig, safe = self.rig, "no rig"
        try:
            if rig is not None:
                if self._acq is not None:
                    self._end_recording(ConsoleClosed(reason))
                elif self._streaming and rig.faults.fault is None:
                    try:
                        rig.adc.stop()
                    except DriverError as exc:
                        log.warning("stopping the meter stream: %s", exc)
                self._streaming = False
                rig.unsubscribe(self._on_rig_event)
                report = rig.close()
                safe = (
                    "yes (read back)"
                    if report is None or report.ok
                    else "INCOMPLETE: " + "; ".join(report.failed)
                )
                log.info("console closed the rig (%s); safe state: %s", reason, safe)
        except BaseException as exc:  # noqa: B036 - report it; the nodes' watchdogs are the last resort
            log.exception("closing the rig failed")
            safe = f"unknown ({type(exc).__name__}: {exc})"
        finally:
            self.state.update(phase=Phase.CLOSED)
            self.stopped.set()
            self._post(WorkerStopped(reason, safe, tuple(self.closed_on_stop)))


def _safe_text(rig: Rig) -> str:
    try:
        return "yes (read back)" if rig.is_safe() else "NOT confirmed"
    except Exception as exc:  # the device that failed may be the one to ask
        return f"unknown ({exc})"
