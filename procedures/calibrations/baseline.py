"""``baseline``: the open-loop sensor spectra of Ch. V B (Figs. 32-34, Table 1).

The rig is brought to mode 3 (the gyros spinning and caged), the platform is clamped to the
table with the stabilization loops open (the relay node's CLAMP, docs/protocol.md 2.5a), and
after a settle every sensor channel is recorded: what each reads is then its own noise. From
the record (``procedures.analysis.baseline``):

* the primary autocollimator's noise-equivalent angle in 0.1-100 Hz on the axis's control and
  instrumentation channels (Table 1), its white level and 1/f corner (Fig. 32);
* the azimuth autocollimator's NEA (Fig. 34);
* the axis gyro's pickoff rms in bands and its discrete lines (Fig. 33).

Volts become urad with the rig's data sheet (the autocollimator scales, Table 1; the pickoff
scale Kg from a stopwatch summary when given, else nominal, as the survey does).

The clamp is released on every way out: the clamped record is one step whose release runs on
its normal end, on an abort, on Ctrl-C and on any error (then before the runner drives the rig
safe; the safe state itself never moves the clamp). If the rig cannot be told (a device
fault), the failure is logged and the clamp stays: release it with ``fbs clamp off``.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Annotated, Any

import numpy as np

from daq.plots import plot_psd
from daq.reader import RunFile
from procedures.analysis.baseline import (
    NEA_BAND_HZ,
    PICKOFF_BANDS_HZ,
    Line,
    WhiteFlicker,
    baseline_figures,
    pickoff_lines,
    psd_of,
)
from procedures.analysis.intervals import Estimate, add_figure, through_scale
from procedures.analysis.transfer import TransferError, block_csd
from procedures.paramlimits import OneOf, above, at_least, check_limits, sample_rate
from procedures.params import pickoff_scale_rel_half_width, prior_values
from procedures.procedure import (
    Analysis,
    Context,
    Figure,
    Measurement,
    Procedure,
    ProcedureError,
    Step,
)
from procedures.reports import thesis
from procedures.reports.baseline import markdown
from procedures.resume import steps_done
from procedures.rigsetup import InMode3, bring_to_mode3
from procedures.stepresult import StepResult

log = logging.getLogger(__name__)

#: every sensor channel (DESIGN.md section 5); the analysis reads the axis's
CHANNELS = (
    "ac_x_ctl",
    "ac_y_ctl",
    "ac_x_inst",
    "ac_y_inst",
    "ac_z",
    "gyro_x",
    "gyro_y",
    "gyro_z",
    "gyro_xrd",
)
#: ADC ranges (V): the autocollimators read millivolts of noise about a null; the pickoffs tens
#: of millivolts about their caged offsets (XRD's proportional loop stands at ~0.34 V)
RANGES_V = {"ac": 1.0, "gyro": 2.0}
STEP = "clamped record"


@dataclass(frozen=True)
class ClampedRecordDone(StepResult):
    """The clamped record's step: its first ``settle_samples`` are the loops' transient."""

    settle_samples: int
    record_samples: int


@dataclass
class BaselineParams:
    axis: Annotated[str, OneOf("X", "Y", note="Z has no primary autocollimator channel")] = "X"
    rate_hz: Annotated[float, sample_rate()] = 1000.0
    #: after clamping: the caging loops' response to the clamp's stop dies out in a few seconds
    settle_s: Annotated[float, at_least(0)] = 10.0
    record_s: Annotated[float, above(0)] = 480.0
    #: Welch segment (its four lowest bins are unusable: 40 s reaches 0.1 Hz) and jackknife blocks
    seg_s: Annotated[float, above(0)] = 40.0
    n_blocks: Annotated[int, at_least(3)] = 8
    #: a pickoff line stands this far above the running median of the averaged PSD
    line_min_ratio: Annotated[float, above(1)] = 20.0

    def __post_init__(self) -> None:
        self.axis = str(self.axis).upper()
        check_limits(self, "baseline")
        if 4.0 / self.seg_s > NEA_BAND_HZ[0] + 1e-12:
            raise ValueError(
                f"baseline: Welch segments of {self.seg_s:g} s do not resolve the NEA band's "
                f"{NEA_BAND_HZ[0]:g} Hz (four bins above zero): use seg_s >= {4 / NEA_BAND_HZ[0]:g}"
            )
        if self.record_s < self.seg_s * self.n_blocks:
            raise ValueError(
                f"baseline: record_s = {self.record_s:g} s holds fewer than n_blocks = {self.n_blocks} "
                f"segments of {self.seg_s:g} s"
            )
        if NEA_BAND_HZ[1] > 0.3 * self.rate_hz:
            raise ValueError(
                f"baseline: the NEA band reaches {NEA_BAND_HZ[1]:g} Hz, above the anti-alias filter "
                f"(0.3 fs = {0.3 * self.rate_hz:g} Hz): use rate_hz >= {NEA_BAND_HZ[1] / 0.3:g}"
            )


Params = BaselineParams


def pickoff_scales(
    prior: Mapping[str, Mapping[str, Any]], nominal: Mapping[str, float]
) -> tuple[dict[str, float], dict[str, str]]:
    """Kg (mV/urad) per gyro channel and where it came from: the stopwatch summary, else nominal."""
    return prior_values(prior, "stopwatch", "K_g_mV_per_urad", ("X", "Y", "Z", "XRD"), nominal)


class Baseline(Procedure[BaselineParams]):
    name = "baseline"
    demo_order = 40
    demo_runs = (("X", ()),)
    title = "Open-loop sensor baselines, platform clamped (Ch. V B)"
    json_keys = (
        "nea_urad",
        "white_urad_per_rtHz",
        "flicker_corner_hz",
        "pickoff_rms_urad",
        "pickoff_lines_hz",
        "file",
    )
    Params = BaselineParams
    mode = 3
    block_s = 1.0

    def __init__(
        self,
        params: BaselineParams | None = None,
        *,
        reference: Mapping[str, Any] | None = None,
        **kw,
    ) -> None:
        super().__init__(params, **kw)
        self.rate_hz = self.params.rate_hz
        self.axis = self.params.axis
        self.ranges_V = {c: RANGES_V["gyro" if c.startswith("gyro") else "ac"] for c in CHANNELS}
        #: the report's reference column (never used by the measurement)
        self.reference = dict(thesis.BASELINE if reference is None else reference)

    def channels(self) -> tuple[str, ...]:
        return CHANNELS

    def headline(self) -> dict[str, tuple[str, ...]]:
        """The headline figures and their channels (``Procedure.headline``)."""
        sensors = ("ctl", "inst")
        return {
            "nea_urad": (*sensors, "z"),
            "white_urad_per_rtHz": sensors,
            "flicker_corner_hz": sensors,
            "pickoff_rms_urad": tuple(PICKOFF_BANDS_HZ),
        }

    def names(self) -> dict[str, str]:
        a = self.params.axis.lower()
        return {"ctl": f"ac_{a}_ctl", "inst": f"ac_{a}_inst", "z": "ac_z", "gyro": f"gyro_{a}"}

    def plan(self) -> list[Step[Any]]:
        p = self.params
        return [
            Step(
                "mode 3",
                partial(bring_to_mode3, clamped_ok=True),
                expected_s=300.0,
                setup=True,
                result=InMode3,
            ),
            Step(
                STEP,
                self._clamped_record,
                expected_s=p.settle_s + p.record_s,
                result=ClampedRecordDone,
            ),
        ]

    # ------------------------------------------------------------------ the clamped record
    def _clamped_record(self, ctx: Context) -> ClampedRecordDone:
        """Clamp, settle, record, release: one step, so no abort can fall between the clamp and
        its release (the runner checks for an abort between steps, outside any step's hands)."""
        rig, p = ctx.rig, self.params
        rig.clamp()
        ctx.note("platform clamped, loops open (Ch. V B)")
        try:
            start = ctx.acq.pos
            ctx.acquire(p.settle_s, keep=False)
            settle = ctx.acq.pos - start
            ctx.acquire(p.record_s, keep=False)
        except BaseException as exc:  # noqa: B036 - Ctrl-C too: the clamp is released on every way out
            self._release_after(ctx, exc)
            raise
        rig.unclamp()
        ctx.note("platform released, loops closed")
        return ClampedRecordDone(
            settle_samples=int(settle), record_samples=int(round(p.record_s * ctx.acq.rate_hz))
        )

    @staticmethod
    def _release_after(ctx: Context, exc: BaseException) -> None:
        try:
            ctx.rig.unclamp()
            log.warning("baseline stopped (%s): platform released", type(exc).__name__)
        except Exception as why:  # the rig may be gone: say so, and let the first exception go on
            log.error(
                "baseline stopped (%s) and the platform could NOT be released: %s; release it with "
                "`fbs clamp off --rig URL`",
                type(exc).__name__,
                why,
            )

    # ------------------------------------------------------------------ analysis
    def record_span(self, ctx: Context) -> tuple[Path, int, int]:
        spans = ctx.data_spans([STEP])
        if not spans:
            raise ProcedureError("baseline: the clamped record was not taken")
        s = spans[0]
        settle = ctx.result(STEP, ClampedRecordDone).settle_samples
        return s.file, s.start + settle, s.stop

    def analyze(self, ctx: Context) -> Analysis:
        p = self.params
        cal = ctx.rig.calibration
        ac = cal.autocollimator[p.axis]
        n = self.names()
        kg_mv, kg_src = pickoff_scales(self.prior, cal.pickoff_scale_mV_per_urad)
        kg = kg_mv[p.axis] * 1e-3  # V/urad
        scale = {
            "ctl": ac.control_mV_per_urad * 1e-3,
            "inst": ac.inst_mV_per_urad * 1e-3,
            "z": cal.azimuth_mV_per_urad * 1e-3,
        }
        file, start, stop = self.record_span(ctx)
        channels = tuple(n.values())
        try:
            blocks = block_csd([(file, start, stop)], channels, p.seg_s, p.n_blocks)
        except TransferError as exc:
            raise ProcedureError(f"baseline: {exc}") from None
        f = blocks.f

        figs = baseline_figures(blocks, ac, n, {**scale, "gyro": kg})
        nea = {k: figs[f"nea_urad.{k}"] for k in ("ctl", "inst", "z")}
        fits = {
            k: WhiteFlicker(figs[f"white_urad_per_rtHz.{k}"], figs[f"flicker_corner_hz.{k}"])
            for k in ("ctl", "inst")
        }
        # the rms in urad is the volts' over K_g: as good as K_g is (the stopwatch's interval,
        # else the data sheet's tolerance)
        kg_u = pickoff_scale_rel_half_width(self.prior, kg_src[p.axis], p.axis, kg_mv[p.axis])
        pick = {
            band: through_scale(figs[f"pickoff_rms_urad.{band}"], kg_u) for band in PICKOFF_BANDS_HZ
        }
        with RunFile(file) as rf:
            x = rf.read([n["gyro"]], start, stop)[0]
        lines = pickoff_lines(
            x,
            blocks.fs,
            f,
            psd_of(blocks, n["gyro"]),
            kg,
            1.0,
            0.4 * blocks.fs,
            min_ratio=p.line_min_ratio,
        )

        values: dict[str, Any] = {}
        add_figure(values, "nea_urad", nea, digits=5)
        add_figure(
            values,
            "white_urad_per_rtHz",
            {k: w.white_urad_per_rtHz for k, w in fits.items()},
            digits=5,
        )
        add_figure(values, "flicker_corner_hz", {k: w.corner_hz for k, w in fits.items()}, digits=4)
        add_figure(values, "pickoff_rms_urad", pick, digits=5)
        values["pickoff_lines_hz"] = [round(ln.freq_hz, 4) for ln in lines]
        values["pickoff_lines_hz_ci95"] = [[round(v, 4) for v in ln.ci95_hz] for ln in lines]
        values["pickoff_line_amplitude_urad"] = [round(ln.amplitude_urad, 4) for ln in lines]
        values |= {
            "axis": p.axis,
            "channels": n,
            "pickoff_scale_mV_per_urad": kg_mv[p.axis],
            "pickoff_scale_source": kg_src[p.axis],
            "nea_band_hz": list(NEA_BAND_HZ),
            "record_s": round((stop - start) / blocks.fs, 3),
        }

        ms = [
            _measurement(f"NEA {n[k]} {NEA_BAND_HZ[0]:g}-{NEA_BAND_HZ[1]:g} Hz", nea[k], "urad")
            for k in nea
        ]
        ms += [
            _measurement(f"white level {n[k]}", fits[k].white_urad_per_rtHz, "urad/sqrt(Hz)")
            for k in fits
        ]
        ms += [_measurement(f"1/f corner {n[k]}", fits[k].corner_hz, "Hz") for k in fits]
        ms += [
            _measurement(f"pickoff rms {n['gyro']} {band}", e, "urad") for band, e in pick.items()
        ]
        ms += [
            Measurement(
                f"pickoff line {i + 1} ({n['gyro']})",
                ln.freq_hz,
                "Hz",
                stderr=ln.freq_sigma_hz,
                note=f"{ln.amplitude_urad:.3g} urad, {ln.ratio:.0f}x the local median",
            )
            for i, ln in enumerate(lines)
        ]

        title = f"{Path(ctx.path).name}, clamped, {blocks.seconds:.0f} s at {blocks.fs:g} Hz"
        nperseg = int(round(p.seg_s * blocks.fs))
        dof = 2.0 * blocks.averages()
        figures = []
        for k, c in n.items():
            sc = kg if k == "gyro" else scale[k]
            figures.append(
                Figure(
                    f"psd-{c}",
                    f"Open-loop PSD of {c} in urad²/Hz (Ch. V B, Figs. 32-34)",
                    partial(
                        _plot,
                        f=f[1:-1],
                        p=psd_of(blocks, c)[1:-1] / sc**2,
                        channel=c,
                        dof=dof,
                        nperseg=nperseg,
                        title=title,
                    ),
                )
            )
        md = markdown(
            values,
            p.axis,
            lines,
            self.reference.get("pickoff_lines_hz") or [],
            self.reference,
            blocks.seconds,
            blocks.fs,
            p.seg_s,
            blocks.n_blocks,
        )
        return Analysis(values, ms, figures, md)


# ---------------------------------------------------------------------------- a finished run's record
class BaselineFileError(ValueError):
    """A file that is not a usable baseline run; the message names the file and what is wrong."""


@dataclass(frozen=True)
class ClampedRecord:
    """Where a baseline run's clamped record lies: samples ``start <= i < stop`` of ``file`` (the
    run file named, or the one it resumed), the settle after the clamp left out."""

    source: Path
    file: Path
    start: int
    stop: int
    rate_hz: float
    axis: str
    channels: tuple[str, ...]

    @property
    def seconds(self) -> float:
        return (self.stop - self.start) / self.rate_hz


def clamped_record(path: str | Path, what: str = "baseline file") -> ClampedRecord:
    """The clamped record of the baseline run file ``path`` (its ``step-done`` events say where),
    read from metadata and events only. Raises ``BaselineFileError`` naming ``what`` and the path
    when the file is missing, is not an fbs-run file, is not a baseline run, or holds no completed
    clamped record."""
    path = Path(path)
    name = f"{what} {str(path)!r}"
    if not path.is_file():
        raise BaselineFileError(
            f"{name}: no such file" if not path.exists() else f"{name}: not a regular file"
        )
    try:
        with RunFile(path) as rf:
            attrs, events = rf.attrs, rf.events
    except OSError as exc:  # RunFileError (an OSError) included: the contract broken, not HDF5
        raise BaselineFileError(f"{name}: not a readable fbs-run file ({exc})") from None
    proc = attrs.get("procedure")
    if proc != "baseline":
        raise BaselineFileError(
            f"{name}: a {proc!r} run, not a 'baseline' run"
            if proc
            else f"{name}: names no procedure (root attribute 'procedure'); a baseline run is "
            f"written by `fbs run baseline`"
        )
    try:
        results, spans = steps_done(path, events, {STEP: ClampedRecordDone})
    except ProcedureError as exc:
        raise BaselineFileError(f"{name}: {exc}") from None
    if STEP not in spans:
        raise BaselineFileError(
            f"{name}: holds no completed {STEP!r} step (status {attrs.get('status', '?')!r})"
        )
    span = spans[STEP]
    done = results.get(STEP)
    settle = done.settle_samples if isinstance(done, ClampedRecordDone) else 0
    try:
        with RunFile(span.file) as rf:
            channels, rate, n = rf.channels, float(rf.rate_hz), rf.n_samples
    except OSError as exc:
        raise BaselineFileError(
            f"{name}: its clamped record's file {str(span.file)!r} cannot be read ({exc})"
        ) from None
    start, stop = span.start + settle, min(span.stop, n)
    if stop <= start:
        raise BaselineFileError(f"{name}: the clamped record in {str(span.file)!r} is empty")
    return ClampedRecord(
        path, span.file, start, stop, rate, str(attrs.get("axis", "")), tuple(channels)
    )


def _plot(
    path: Path, *, f: np.ndarray, p: np.ndarray, channel: str, dof: float, nperseg: int, title: str
) -> Path:
    return plot_psd(
        path,
        f,
        p,
        channel=channel,
        units="urad",
        dof=dof,
        nperseg=nperseg,
        nfft=nperseg,
        title=title,
    )


def _measurement(name: str, e: Estimate, units: str) -> Measurement:
    note = f"95 % [{e.lo:.4g}, {e.hi:.4g}]" + ("" if e.resolved else f"; not resolved: {e.why}")
    return Measurement(name, e.value if e.resolved else None, units, note=note)


__all__ = [
    "Baseline",
    "BaselineFileError",
    "BaselineParams",
    "ClampedRecord",
    "Line",
    "Params",
    "clamped_record",
]

PROCEDURE = Baseline
