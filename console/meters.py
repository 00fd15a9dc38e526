"""The meter panel (thesis II C.2): the ten permanent meters, and two live strip charts.

Each meter is named by its ADC channel (``gyro_x``, DESIGN.md section 5), as the recording,
the spectra and the run files name it, with the kind of signal beside it (``pickoff``)."""

from __future__ import annotations

import math
from typing import ClassVar

from rich.text import Text
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Vertical
from textual.widgets import Sparkline, Static

from console.channels import describe
from console.keyhelp import PanelHelp
from console.meterdata import MeterSnapshot, MeterSpec

#: the bar of a meter spans the ADC's +-10 V, like the needle of a zero-centre panel meter
BAR_HALF = 13
FULL_SCALE_V = 10.0
#: a reading this close to the ADC's rails is flagged: the loop is saturated, the value is not a measurement
RAIL_V = 9.9


def _bar(volts: float) -> str:
    k = max(-BAR_HALF, min(BAR_HALF, round(volts / FULL_SCALE_V * BAR_HALF)))
    left = " " * (BAR_HALF + min(k, 0)) + "█" * (-min(k, 0))
    right = "█" * max(k, 0) + " " * (BAR_HALF - max(k, 0))
    return left + "│" + right


def _num(x: float | None, width: int, digits: int) -> str:
    if x is None or not math.isfinite(x):
        return "—".rjust(width)
    return f"{x:+{width}.{digits}f}" if abs(x) < 10 ** (width - digits - 2) else f"{x:+{width}.3g}"


class MeterTable(Static):
    """Ten rows: meter, engineering value and units, the raw volts, a zero-centre bar."""

    def __init__(self, **kw) -> None:
        super().__init__(**kw)
        self.specs: tuple[MeterSpec, ...] = ()
        self.snap = MeterSnapshot(0)
        self.paints = 0  # how many times the table was drawn (the benchmark counts it)
        self.paused = False
        self.channels: tuple[str, ...] | None = None  # the ADC's channels, once the rig is open

    def show(self, specs: tuple[MeterSpec, ...], snap: MeterSnapshot) -> None:
        self.specs, self.snap = specs, snap
        self.refresh()

    def render(self) -> Text:
        self.paints += 1
        t = Text(no_wrap=True, overflow="crop")
        t.append(
            f"{'channel':<18}{'value':>10} {'units':<7}{'volts':>9}  {'-10 V':<{BAR_HALF}}0{'+10 V':>{BAR_HALF}}",
            style="bold",
        )
        if self.paused:
            t.append("  PAUSED", style="bold black on yellow")
        t.append("\n")
        if not self.specs:
            t.append("waiting for the rig…")
            return t
        for i, s in enumerate(self.specs):
            v = self.snap.volts.get(s.channel)
            eng = None if v is None else s.eng(v)
            t.append(f"{s.channel:<9}")
            t.append(f"{s.what:<9}", style="dim")
            if v is None or not math.isfinite(v):  # say why there is no number
                why = (
                    "not on this ADC"
                    if self.channels is not None and s.channel not in self.channels
                    else "no reading (stream stopped)"
                    if self.snap.seq
                    else "waiting for the rig"
                )
                t.append(f"{'—':>10} {s.units:<7}  {why}", style="dim")
            else:
                t.append(_num(eng, 10, 2), style="bold")
                t.append(f" {s.units:<7}{_num(v, 9, 4)}  ")
                t.append(_bar(v), style="cyan")
                if abs(v) >= RAIL_V:
                    t.append(" RAIL", style="bold white on red")
            if i < len(self.specs) - 1:
                t.append("\n")
        return t


class StripChart(Vertical):
    """One live strip chart of a selectable channel (a strip-chart recorder's pen)."""

    DEFAULT_CSS = """
    StripChart { height: 4; }
    StripChart > .chart-title { height: 1; }
    StripChart > Sparkline { height: 3; }
    """

    def __init__(self, name: str, channel: str, point_s: float = 0.2, **kw) -> None:
        super().__init__(**kw)
        self.point_s = point_s
        self.chart_name = name
        self.channel = channel

    def compose(self) -> ComposeResult:
        yield Static(f"chart {self.chart_name}: {describe(self.channel)}", classes="chart-title")
        yield Sparkline([], summary_function=max)

    def on_mount(self) -> None:
        self._title = self.query_one(".chart-title", Static)
        self._spark = self.query_one(Sparkline)

    def show(self, points: tuple[float, ...], paused: bool = False) -> None:
        pts = [p for p in points if math.isfinite(p)]
        title = f"chart {self.chart_name}: {describe(self.channel)}"
        if pts:
            span = f"{len(pts) * self.point_s:.0f} s"
            title += f"   {min(pts):+.4f} .. {max(pts):+.4f} V over " + (
                f"{span} before the pause" if paused else f"the last {span}"
            )
        else:
            title += "   no data yet"
        self._title.update(title, layout=False)
        self._spark.data = pts


class MeterPanel(Vertical, can_focus=True):
    KEY_HELP: ClassVar[PanelHelp] = (
        ("c", "strip chart A: the next channel"),
        ("v", "strip chart B: the next channel"),
        ("p", "pause / resume the meters (the panel says PAUSED while they are frozen)"),
    )
    BINDINGS = [
        Binding("c", "cycle('A')", "chart A"),
        Binding("v", "cycle('B')", "chart B"),
        Binding("p", "pause", "pause"),
    ]

    def __init__(self, **kw) -> None:
        super().__init__(**kw)
        self.channels: tuple[str, ...] = (
            "gyro_x",
            "gyro_y",
            "gyro_z",
            "gyro_xrd",
            "torq_x",
            "torq_y",
            "torq_z",
            "torq_xrd",
            "ac_x_ctl",
            "ac_y_ctl",
        )
        self.paused = False

    def compose(self) -> ComposeResult:
        yield MeterTable(id="meter-table")
        yield StripChart("A", "gyro_x", id="chart-a")
        yield StripChart("B", "torq_x", id="chart-b")

    def set_channels(self, channels: tuple[str, ...]) -> None:
        self.channels = channels
        self._table.channels = channels

    @property
    def chart_channels(self) -> tuple[str, str]:
        return self._charts[0].channel, self._charts[1].channel

    def on_mount(self) -> None:
        self._table = self.query_one(MeterTable)
        self._charts = (
            self.query_one("#chart-a", StripChart),
            self.query_one("#chart-b", StripChart),
        )

    def show(self, specs: tuple[MeterSpec, ...], snap: MeterSnapshot) -> None:
        if self.paused:
            return
        self._table.show(specs, snap)
        for chart in self._charts:
            chart.show(snap.history.get(chart.channel, ()))

    def action_cycle(self, which: str) -> None:
        chart = self.query_one(f"#chart-{which.lower()}", StripChart)
        i = self.channels.index(chart.channel) if chart.channel in self.channels else -1
        chart.channel = self.channels[(i + 1) % len(self.channels)]
        chart.show(())

    def action_pause(self) -> None:
        self.paused = not self.paused
        self._table.paused = self.paused  # the panel says so while it is frozen, not only a toast
        self._table.refresh()
        for chart in self._charts:
            chart.show(self._table.snap.history.get(chart.channel, ()), paused=self.paused)
        self.notify("meters paused (p resumes)" if self.paused else "meters live", timeout=2)
