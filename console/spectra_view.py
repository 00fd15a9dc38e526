"""The spectra view: PSD and coherence of chosen channels of a run file, drawn on log axes.

The numbers are ``daq.filespectra.run_csd_matrix`` (Welch in bounded memory, lost samples
never spliced over), the segment length ``fbs spectra``'s rule, computed on a Textual thread
worker. The plots are textual-plotext's: the PSDs of both channels on log-log axes (V^2/Hz
against Hz, decade ticks), their coherence on a log frequency axis (0..1). Which file is shown
is said in words: the last recording, a procedure's run file, or one typed in.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np
from rich.text import Text
from textual import work
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from textual.widgets import Input, Static
from textual_plotext import PlotextPlot

from console.channels import unknown_channels
from console.keyhelp import PanelHelp
from console.keyorder import OrderedInput

#: display points per curve: the Welch bins averaged over log-spaced bands (a terminal's
#: braille cells resolve a few hundred columns at most)
POINTS = 256
#: one colour per channel, the same in the plot and in the title that names it
COLOURS = ((80, 200, 255), (255, 190, 60))


@dataclass(frozen=True)
class SpectraView:
    """What the panel draws, computed off the UI thread."""

    path: Path
    channels: tuple[str, ...]
    f_hz: tuple[float, ...]  # log-spaced band centres, first nonzero bin .. Nyquist
    psd: dict[str, tuple[float, ...]]  # per channel, V^2/Hz in each band
    coherence: tuple[float, ...]  # first pair, 0..1 in each band (empty for one channel)
    segments: str
    f_lo: float  # the first nonzero Welch bin (Hz)
    f_hi: float  # the last (Nyquist)


def log_bands(f: np.ndarray, y: np.ndarray, n: int = POINTS) -> tuple[np.ndarray, np.ndarray]:
    """``y`` averaged over up to ``n`` log-spaced frequency bands from the first nonzero bin to
    Nyquist; each band's centre frequency (geometric mean of its bins). Empty bands (fewer FFT
    bins than bands at the low end) are left out, not invented."""
    keep = f > 0
    f, y = f[keep], y[keep]
    edges = np.geomspace(f[0], f[-1] * (1 + 1e-9), n + 1)
    idx = np.clip(np.searchsorted(edges, f, side="right") - 1, 0, n - 1)
    counts = np.bincount(idx, minlength=n)
    filled = counts > 0
    centre = np.exp(np.bincount(idx, weights=np.log(f), minlength=n)[filled] / counts[filled])
    mean = np.bincount(idx, weights=y, minlength=n)[filled] / counts[filled]
    return centre, mean


def compute_view(path: Path, channels: tuple[str, ...]) -> SpectraView:
    from daq.filespectra import run_csd_matrix
    from daq.reader import RunFile
    from procedures.analysis.channel_spectra import choose_nperseg

    with RunFile(path) as rf:
        why = unknown_channels(channels, rf.channels, str(path))
        if why:
            raise ValueError(why)
        nperseg = min(choose_nperseg(rf.n_samples, rf.rate_hz), rf.n_samples)
        csd = run_csd_matrix(rf, channels, nperseg=nperseg)
    f_hz: np.ndarray = np.empty(0)
    psd: dict[str, tuple[float, ...]] = {}
    for c in channels:
        f_hz, p = log_bands(csd.f, csd.psd(c))
        psd[c] = tuple(float(v) for v in p)
    coh: tuple[float, ...] = ()
    if len(channels) >= 2:
        _, cb = log_bands(csd.f, np.nan_to_num(csd.coherence()[:, 0, 1]))
        coh = tuple(float(v) for v in np.clip(cb, 0.0, 1.0))
    seg = (
        f"{csd.segments_used} segments of {csd.segment_s:g} s ({csd.segments_skipped} skipped), "
        f"resolution {csd.resolution_hz:.3g} Hz"
    )
    f_pos = csd.f[csd.f > 0]
    return SpectraView(
        Path(path),
        tuple(channels),
        tuple(float(v) for v in f_hz),
        psd,
        coh,
        seg,
        float(f_pos[0]),
        float(f_pos[-1]),
    )


def decade_ticks(lo: float, hi: float, unit: str = "") -> tuple[list[float], list[str]]:
    """Ticks for a log axis from ``lo`` to ``hi``: the decades inside it (1, 2, 5 steps when
    fewer than two decades fit), labelled as numbers a reader knows (0.1, 1, 10, 1e-06), the
    last with ``unit``."""
    if not (lo > 0 and hi > lo):
        return [], []
    ticks: list[float] = []
    for steps in ((1.0,), (1.0, 2.0, 5.0), (1.0, 1.5, 2.0, 3.0, 5.0, 7.0)):
        ticks = [
            m * 10.0**e
            for e in range(math.floor(math.log10(lo)), math.ceil(math.log10(hi)) + 1)
            for m in steps
            if lo <= m * 10.0**e <= hi
        ]
        if len(ticks) >= 2:
            break
    labels = [f"{v:g}" for v in ticks]
    if labels and unit:
        labels[-1] += f" {unit}"
    return ticks, labels


def _log10(values) -> list[float]:
    return [math.log10(v) for v in values]


def _log_frequency_axis(plt, view: SpectraView) -> None:
    """The frequency axis, in decades, from the first Welch bin to Nyquist with decade ticks (the
    band centres stop short of both ends, and a tick outside the data would not be drawn).

    The axes are log10 of the values on plotext's linear scale, ticks labelled with the values:
    plotext's own log scale takes the log of its stored data in place at every build, so the
    second repaint of the widget would take the log of the log."""
    plt.xlim(math.log10(view.f_lo), math.log10(view.f_hi))
    ticks, labels = decade_ticks(view.f_lo, view.f_hi, "Hz")
    plt.xticks(_log10(ticks), labels)


def _rgb(c: tuple[int, int, int]) -> str:
    return f"rgb({c[0]},{c[1]},{c[2]})"


class SpectraPanel(Vertical, can_focus=True):
    KEY_HELP: ClassVar[PanelHelp] = (
        (
            "F7",
            "PSD and coherence of the named channels (gyro_x, torq_y, ...) of the file "
            "(blank: the newest run file, said which)",
        ),
        ("Tab / shift+Tab", "between the file and channels boxes"),
        ("Enter", "in a box: compute"),
    )
    BINDINGS = [Binding("f7", "compute", "compute")]

    DEFAULT_CSS = """
    SpectraPanel #spec-info { height: auto; }
    SpectraPanel .sp-title { height: 1; }
    SpectraPanel #spec-psd { height: 3fr; min-height: 6; }
    SpectraPanel #spec-coh { height: 2fr; min-height: 5; }
    """

    def __init__(self, **kw) -> None:
        super().__init__(**kw)
        self.last_file: Path | None = None
        #: what ``last_file`` is, in words: "the last recording", "the stopwatch run's file"
        self.last_what = ""
        self.view: SpectraView | None = None

    def compose(self) -> ComposeResult:
        with Horizontal(classes="spec-row"):
            yield Static("file", classes="rec-label")
            yield OrderedInput(
                placeholder="blank: the newest run file (none yet)", id="spec-path", compact=True
            )
        with Horizontal(classes="spec-row"):
            yield Static("channels", classes="rec-label")
            yield OrderedInput("gyro_x,gyro_y", id="spec-channels", compact=True)
        yield Static("f7: PSD and coherence (record one first, f4, or type a file)", id="spec-info")
        yield Static("", id="spec-t0", classes="sp-title")
        yield PlotextPlot(id="spec-psd")
        yield Static("", id="spec-tc", classes="sp-title")
        yield PlotextPlot(id="spec-coh")

    def offer(self, path: Path, what: str) -> None:
        """The newest run file, used when the file box is blank; ``what`` says whose it is."""
        self.last_file, self.last_what = Path(path), what
        self.query_one("#spec-path", Input).placeholder = f"blank: {path} ({what})"
        if self.view is None:
            self.query_one("#spec-info", Static).update(f"f7: PSD and coherence of {path} ({what})")

    def on_input_submitted(self, event: Input.Submitted) -> None:
        event.stop()
        self.action_compute()

    def action_compute(self) -> None:
        typed = self.query_one("#spec-path", Input).value.strip()
        path, what = (Path(typed), "typed") if typed else (self.last_file, self.last_what)
        if path is None:
            self._failed("no run file yet: record one (f4), run a procedure (f5) or type a file")
            return
        channels = tuple(
            c.strip() for c in self.query_one("#spec-channels", Input).value.split(",") if c.strip()
        )
        if not channels or len(channels) > 2:
            self._failed(f"name one or two channels, e.g. gyro_x,gyro_y ({len(channels)} given)")
            return
        self.query_one("#spec-info", Static).update(
            f"computing {', '.join(channels)} of {path} ({what}) …"
        )
        self._compute(path, channels, what)

    @work(thread=True, exclusive=True, group="spectra")
    def _compute(self, path: Path, channels: tuple[str, ...], what: str) -> None:
        # file I/O and FFTs off the UI thread (a Textual thread worker); the rig is not involved
        try:
            view = compute_view(path, channels)
        except Exception as exc:  # a missing file, an unknown channel: tell the operator
            self.app.call_from_thread(
                self._failed,
                str(exc) if isinstance(exc, ValueError) else f"{type(exc).__name__}: {exc}",
            )
            return
        self.app.call_from_thread(self.draw, view, what)

    def _failed(self, text: str) -> None:
        self.query_one("#spec-info", Static).update(Text(text, style="bold red"))

    def draw(self, view: SpectraView, what: str = "") -> None:
        self.view = view
        info = Text(
            f"{view.path}"
            + (f" ({what})" if what and what != "typed" else "")
            + f": {view.segments}"
        )
        self.query_one("#spec-info", Static).update(info)
        title = Text("PSD (V^2/Hz, log-log): ")
        for c, colour in zip(view.channels, COLOURS, strict=False):
            title.append(f"{c} ", style=f"bold {_rgb(colour)}")
        self.query_one("#spec-t0", Static).update(title)
        psd = self.query_one("#spec-psd", PlotextPlot)
        plt = psd.plt
        plt.clear_figure()
        f = _log10(view.f_hz)
        positive = [v for p in view.psd.values() for v in p if v > 0]
        lo, hi = min(positive, default=1e-30), max(positive, default=1.0)
        for c, colour in zip(view.channels, COLOURS, strict=False):
            # a band of exact zeros (a dead channel) has no place on a log axis: drawn at the floor
            plt.plot(f, _log10(max(v, lo) for v in view.psd[c]), marker="braille", color=colour)
        _log_frequency_axis(plt, view)
        plt.ylim(math.log10(lo), math.log10(hi))
        ticks, labels = decade_ticks(lo, hi)
        plt.yticks(_log10(ticks), labels)
        psd.refresh()
        coh = self.query_one("#spec-coh", PlotextPlot)
        plt = coh.plt
        plt.clear_figure()
        tc = self.query_one("#spec-tc", Static)
        if view.coherence:
            tc.update(
                f"coherence {view.channels[0]} / {view.channels[1]} (0..1, log frequency; "
                f"max {max(view.coherence):.2f})"
            )
            plt.plot(f, list(view.coherence), marker="braille", color=COLOURS[0])
            _log_frequency_axis(plt, view)
            plt.ylim(0.0, 1.0)
            plt.yticks([0.0, 0.5, 1.0], ["0", "0.5", "1"])
        else:
            tc.update("coherence: name two channels")
        coh.refresh()
