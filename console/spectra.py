"""The spectra view: PSD and coherence of chosen channels of the last recording.

The numbers are ``daq.filespectra.run_csd_matrix`` (Welch in bounded memory, lost samples
never spliced over), the segment length ``fbs spectra``'s rule. A terminal has no log axes,
so the PSD is drawn in decibels over log-spaced frequency bins (a sparkline per channel):
the shape a thesis plot shows, with the numbers beside it.
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
from textual.widgets import Input, Sparkline, Static

from console.keyhelp import PanelHelp

BINS = 64


@dataclass(frozen=True)
class SpectraView:
    """What the panel draws, computed off the UI thread."""

    path: Path
    channels: tuple[str, ...]
    f_lo: float
    f_hi: float
    psd_db: dict[str, list[float]]        # per channel, BINS values (dB re 1 V^2/Hz)
    coherence: list[float]                # first pair, BINS values 0..1
    segments: str


def log_bins(f: np.ndarray, y: np.ndarray, n: int = BINS) -> tuple[float, float, np.ndarray]:
    """Mean of ``y`` in ``n`` log-spaced frequency bins from the first nonzero bin to Nyquist."""
    keep = f > 0
    f, y = f[keep], y[keep]
    edges = np.geomspace(f[0], f[-1] * (1 + 1e-9), n + 1)
    idx = np.clip(np.searchsorted(edges, f, side="right") - 1, 0, n - 1)
    sums = np.bincount(idx, weights=y, minlength=n)
    counts = np.bincount(idx, minlength=n)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = sums / counts
    # empty low bins (fewer FFT bins than display bins there) take the nearest filled one
    filled = np.flatnonzero(counts)
    out = np.interp(np.arange(n), filled, out[filled])
    return float(f[0]), float(f[-1]), out


def compute_view(path: Path, channels: tuple[str, ...]) -> SpectraView:
    from daq.filespectra import run_csd_matrix
    from daq.reader import RunFile
    from procedures.analysis.spectra import choose_nperseg

    with RunFile(path) as rf:
        nperseg = choose_nperseg(rf.n_samples, rf.rate_hz)
        nperseg = min(nperseg, rf.n_samples)
        csd = run_csd_matrix(rf, channels, nperseg=nperseg)
    psd_db: dict[str, list[float]] = {}
    f_lo = f_hi = 0.0
    for c in channels:
        f_lo, f_hi, p = log_bins(csd.f, csd.psd(c))
        psd_db[c] = [10 * math.log10(v) if v > 0 else -300.0 for v in p]
    coh: list[float] = []
    if len(channels) >= 2:
        _, _, cb = log_bins(csd.f, np.nan_to_num(csd.coherence()[:, 0, 1]))
        coh = [float(v) for v in cb]
    seg = (f"{csd.segments_used} segments of {csd.segment_s:g} s ({csd.segments_skipped} skipped), "
           f"resolution {csd.resolution_hz:.3g} Hz")
    return SpectraView(Path(path), tuple(channels), f_lo, f_hi, psd_db, coh, seg)


class SpectraPanel(Vertical, can_focus=True):
    KEY_HELP: ClassVar[PanelHelp] = (
        ("F7", "PSD and coherence of the named channels of the file (blank: the last recording)"),
        ("Tab / shift+Tab", "between the file and channels boxes"),
        ("Enter", "in a box: compute"),
    )
    BINDINGS = [Binding("f7", "compute", "compute")]

    DEFAULT_CSS = """
    SpectraPanel Sparkline { height: 2; }
    SpectraPanel .sp-title { height: 1; }
    """

    def __init__(self, **kw) -> None:
        super().__init__(**kw)
        self.last_file: Path | None = None
        self.view: SpectraView | None = None

    def compose(self) -> ComposeResult:
        with Horizontal(classes="spec-row"):
            yield Static("file", classes="rec-label")
            yield Input(placeholder="the last recording", id="spec-path", compact=True)
        with Horizontal(classes="spec-row"):
            yield Static("channels", classes="rec-label")
            yield Input("gyro_x,gyro_y", id="spec-channels", compact=True)
        yield Static("f7: PSD and coherence of the last recording", id="spec-info")
        yield Static("", id="spec-t0", classes="sp-title")
        yield Sparkline([], id="spec-p0")
        yield Static("", id="spec-t1", classes="sp-title")
        yield Sparkline([], id="spec-p1")
        yield Static("", id="spec-tc", classes="sp-title")
        yield Sparkline([], id="spec-coh")
        yield Static("", id="spec-axis")

    def on_input_submitted(self, event: Input.Submitted) -> None:
        event.stop()
        self.action_compute()

    def action_compute(self) -> None:
        typed = self.query_one("#spec-path", Input).value.strip()
        path = Path(typed) if typed else self.last_file
        if path is None:
            self.query_one("#spec-info", Static).update(Text("no recording yet: record one (f4) or type a file",
                                                             style="bold red"))
            return
        channels = tuple(c.strip() for c in self.query_one("#spec-channels", Input).value.split(",") if c.strip())
        if not channels:
            self.query_one("#spec-info", Static).update(Text("name one or two channels", style="bold red"))
            return
        self.query_one("#spec-info", Static).update(f"computing {', '.join(channels)} of {path} …")
        self._compute(path, channels[:2])

    @work(thread=True, exclusive=True, group="spectra")
    def _compute(self, path: Path, channels: tuple[str, ...]) -> None:
        # file I/O and FFTs off the UI thread (a Textual thread worker); the rig is not involved
        try:
            view = compute_view(path, channels)
        except Exception as exc:  # a missing file, an unknown channel: tell the operator
            self.app.call_from_thread(self._failed, f"{type(exc).__name__}: {exc}")
            return
        self.app.call_from_thread(self.draw, view)

    def _failed(self, text: str) -> None:
        self.query_one("#spec-info", Static).update(Text(text, style="bold red"))

    def draw(self, view: SpectraView) -> None:
        self.view = view
        self.query_one("#spec-info", Static).update(Text(f"{view.path}: {view.segments}", no_wrap=True,
                                                         overflow="ellipsis"))
        for i in range(2):
            title = self.query_one(f"#spec-t{i}", Static)
            spark = self.query_one(f"#spec-p{i}", Sparkline)
            if i < len(view.channels):
                c = view.channels[i]
                db = view.psd_db[c]
                title.update(f"PSD {c}: {min(db):.0f} .. {max(db):.0f} dB re 1 V^2/Hz")
                spark.data = [v - min(db) for v in db]
            else:
                title.update("")
                spark.data = []
        tc = self.query_one("#spec-tc", Static)
        if view.coherence:
            tc.update(f"coherence {view.channels[0]} / {view.channels[1]}: 0 .. 1 "
                      f"(max {max(view.coherence):.2f})")
            self.query_one("#spec-coh", Sparkline).data = view.coherence
        else:
            tc.update("coherence: name two channels")
            self.query_one("#spec-coh", Sparkline).data = []
        width = max(20, self.size.width - 2) if self.size.width else 78
        lo, hi = f"{view.f_lo:.3g} Hz", f"{view.f_hi:.3g} Hz (log axis)"
        self.query_one("#spec-axis", Static).update(lo + " " * max(1, width - len(lo) - len(hi)) + hi)
