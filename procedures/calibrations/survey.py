"""``survey``: the closed-loop spectral survey of Ch. V E (Figs. 42-49).

A Mode-3 record (autocollimator stabilization, gyros caged through their pickoffs) of the
primary autocollimator's control and instrumentation channels and the X-Y gyro's pickoffs.
From one Welch cross-spectral matrix of the record the survey gives the dip of each
autocollimator control-channel spectrum (Ch. V E.1, Figs. 42/45) with the bearing stiffness it
implies, the gyro-deduced platform rms (Ch. V E.2, exactly the thesis's method), and the PSDs
and coherences as App. A.8 plots. How each is found is ``procedures.analysis.survey`` (its
docstring), usable without a rig; the report's text and dip plot are
``procedures.reports.survey``. This module holds the parameters, the steps and the analysis
that ties them together.

The pickoff scale ``Kg`` is the stopwatch procedure's measured value when its summary is given
(``prior["stopwatch"]["K_g_mV_per_urad"]``), else the rig's nominal data sheet value, and the
report says so (``pickoff_scales``).

The pickoff noise the thesis method credits to the platform is taken out with the open-loop
baseline's spectrum of the same pickoff (Ch. V B, Fig. 33; ``platform_rms_baseline_net_urad``):
the baseline run file is the ``baseline_file`` parameter (checked when the parameters are made,
before anything is recorded), else the file of the prior baseline summary
(``prior["baseline"]["_file"]``, which ``find_prior`` and ``fbs demo`` fill), else there is none
and the figure is unresolved. The clamp holds the whole platform, so every gyro channel of the
clamped record is that pickoff's noise alone: a baseline of either axis serves both survey axes.

The measurement uses no thesis result. The thesis's numbers (1.6 / 3.6 urad, the 3.5 Hz
X dip) appear only in the report, as a reference column (``procedures.reports.thesis.SURVEY``, or whatever
the caller passes as ``reference``).

The record is taken in steps of ``piece_s`` so an aborted survey can be resumed: each step
returns the file and sample span it recorded; ``analyze`` merges adjacent spans of one file
and averages the Welch segments of all spans (a resumed piece lives in the earlier file).
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Mapping
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Annotated, Any, Protocol

from daq.plots import plot_coherence, plot_psd
from daq.spectral import band_rms
from drivers.rig_datasheet import VISCOUS_COUPLING_TOLERANCE
from procedures.analysis.intervals import Estimate, add_figure
from procedures.analysis.survey import (
    AXES,
    CHANNELS,
    COHERENCE_PAIRS,
    BaselineMismatch,
    BaselineNet,
    SpanError,
    ac_ctl,
    ac_inst,
    baseline_net_rms,
    coherent_platform_rms,
    cross_axis_coherence,
    decoupled_gyro,
    gyro,
    platform_gyro,
    spans_csd,
    survey_spectra,
    with_coupling_allowance,
)
from procedures.analysis.transfer import BlockCsd, TransferError, block_csd
from procedures.calibrations.baseline import BaselineFileError, ClampedRecord, clamped_record
from procedures.paramlimits import (
    ExistingFile,
    OneOf,
    Range,
    above,
    at_least,
    check_limits,
    sample_rate,
)
from procedures.params import prior_values
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
from procedures.reports.survey import markdown, plot_dips
from procedures.rigsetup import InMode3, ModeSet, back_to_mode3, bring_to_mode3, enter_gyro_mode
from procedures.stepresult import Recorded, Waited

log = logging.getLogger(__name__)


@dataclass
class SurveyParams:
    #: 3 autocollimator stabilization (the thesis's survey, Ch. V E); 4 and 5 gyro stabilization
    mode: Annotated[
        int, OneOf(3, 4, 5, note="the stabilized modes; the gyro modes need the gyros caged")
    ] = 3
    duration_s: Annotated[float, above(0)] = 300.0
    rate_hz: Annotated[float, sample_rate()] = 1000.0
    #: record in steps of this length (the unit an aborted run can be resumed by)
    piece_s: Annotated[float, at_least(1.0)] = 60.0
    #: wait after reaching mode 3 (a rig already caged in mode 3 waits at most 5 s)
    settle_s: Annotated[float, at_least(0)] = 30.0
    #: after the switch to Mode 4 or 5: the network's and the caging loop's transients (14 s)
    mode_settle_s: Annotated[float, at_least(0)] = 90.0
    #: Welch segment length (Hann, 50 % overlap): bin spacing 1/seg_s
    seg_s: Annotated[float, above(0)] = 16.0
    #: band of the gyro-deduced platform rms (the thesis's method: 0.4-15 Hz)
    band_lo_hz: Annotated[float, above(0)] = 0.4
    band_hi_hz: Annotated[float, above(0)] = 15.0
    #: where to look for the control-channel dip, and the smoothing of the dB spectrum
    dip_lo_hz: Annotated[float, above(0)] = 0.5
    dip_hi_hz: Annotated[float, above(0)] = 30.0
    dip_smooth_hz: Annotated[float, at_least(0)] = 0.5
    #: quality limits: the dip's prominence, the fraction of Welch segments usable (no lost samples)
    min_dip_depth_db: Annotated[float, at_least(0, units="dB")] = 6.0
    min_segments_used: Annotated[float, Range(0.0, 1.0)] = 0.9
    #: the platform's own rms (gyro coherent with the autocollimator): Welch segment, jackknife blocks
    coherent_seg_s: Annotated[float, above(0)] = 8.0
    coherent_blocks: Annotated[int, at_least(3)] = 8
    #: a baseline run file (``fbs run baseline``) whose clamped pickoff spectrum is taken out of the
    #: gyro's (Ch. V B, Fig. 33); None: the prior baseline summary's file, if any
    baseline_file: Annotated[str | None, ExistingFile()] = None
    #: jackknife blocks of the baseline's clamped record (its segments are ``coherent_seg_s``)
    baseline_blocks: Annotated[int, at_least(3)] = 8

    def __post_init__(self) -> None:
        check_limits(self, "survey")
        if self.baseline_file is not None:
            # before anything is recorded: a bad file named now, not after a 5-minute record
            usable_baseline(clamped_record(self.baseline_file, "survey: baseline_file"), self)
        # what no one field can declare: limits that tie fields together
        if self.coherent_seg_s * self.coherent_blocks > self.duration_s:
            raise ValueError(
                f"survey: coherent_blocks = {self.coherent_blocks} segments of coherent_seg_s = "
                f"{self.coherent_seg_s:g} s must fit in duration_s = {self.duration_s:g} s"
            )
        if self.seg_s > self.duration_s:
            raise ValueError(
                f"survey: seg_s = {self.seg_s:g} s must be at most duration_s = {self.duration_s:g} s"
            )
        nyq = self.rate_hz / 2
        if not 0 < self.band_lo_hz < self.band_hi_hz <= nyq:
            raise ValueError(
                f"survey: band_lo_hz..band_hi_hz = {self.band_lo_hz:g}..{self.band_hi_hz:g} Hz must "
                f"lie in 0..{nyq:g} Hz (rate_hz / 2), low below high"
            )
        if not 0 < self.dip_lo_hz < self.dip_hi_hz <= nyq:
            raise ValueError(
                f"survey: dip_lo_hz..dip_hi_hz = {self.dip_lo_hz:g}..{self.dip_hi_hz:g} Hz must lie in "
                f"0..{nyq:g} Hz (rate_hz / 2), low below high"
            )


def pickoff_scales(
    prior: Mapping[str, Mapping[str, Any]], nominal: Mapping[str, float]
) -> tuple[dict[str, float], dict[str, str]]:
    """Kg (mV/urad) per axis and where it came from: the stopwatch summary if given, else nominal."""
    return prior_values(prior, "stopwatch", "K_g_mV_per_urad", AXES, nominal)


class BaselineSettings(Protocol):
    coherent_seg_s: float
    baseline_blocks: int


def usable_baseline(
    rec: ClampedRecord, p: BaselineSettings, what: str = "survey: baseline_file"
) -> ClampedRecord:
    """``rec`` if the survey can set its pickoff spectrum against its own: a gyro channel of a
    survey axis, Welch bins on the survey's grid (whole samples per segment), enough record for
    the jackknife blocks. Raises ``BaselineFileError`` naming the file and what is wrong."""
    name = f"{what} {str(rec.source)!r}"
    if not any(gyro(a) in rec.channels for a in AXES):
        raise BaselineFileError(
            f"{name}: holds neither {gyro('X')} nor {gyro('Y')} (has: {', '.join(rec.channels)})"
        )
    nperseg = p.coherent_seg_s * rec.rate_hz
    if abs(nperseg - round(nperseg)) > 1e-6:
        raise BaselineFileError(
            f"{name}: {p.coherent_seg_s:g} s segments at its {rec.rate_hz:g} Hz are not whole "
            f"samples, so its bins are not the survey's"
        )
    if rec.seconds < p.coherent_seg_s * p.baseline_blocks:
        raise BaselineFileError(
            f"{name}: its clamped record of {rec.seconds:.1f} s holds fewer than "
            f"baseline_blocks = {p.baseline_blocks} segments of {p.coherent_seg_s:g} s"
        )
    return rec


# ---------------------------------------------------------------------------- the procedure
#: the name the module's functions and tests use
Params = SurveyParams


class Survey(Procedure[SurveyParams]):
    name = "survey"
    demo_order = 50  # it reads the baseline's record
    title = "Closed-loop spectral survey in Mode 3, 4 or 5 (Ch. V E)"
    json_keys = ("platform_rms_urad", "platform_rms_baseline_net_urad", "dip_hz", "file")
    Params = SurveyParams
    mode = 3
    block_s = 1.0

    def __init__(
        self,
        params: SurveyParams | None = None,
        *,
        reference: Mapping[str, Any] | None = None,
        **kw,
    ) -> None:
        super().__init__(params, **kw)
        self.rate_hz = self.params.rate_hz
        self.mode = self.params.mode
        #: the report's reference column (never used by the measurement)
        self.reference = dict(thesis.SURVEY if reference is None else reference)
        #: the baseline's clamped record and where it came from, fixed when the plan is made
        self.baseline: ClampedRecord | None = None
        self.baseline_note = "no baseline run given"

    def find_baseline(self) -> tuple[ClampedRecord | None, str]:
        """The baseline's clamped record: the ``baseline_file`` parameter's (its errors raise), else
        the prior baseline summary's file (an unusable one is logged and left out), else none."""
        p = self.params
        if p.baseline_file is not None:
            rec = usable_baseline(clamped_record(p.baseline_file, "survey: baseline_file"), p)
            return rec, f"baseline_file parameter `{rec.source}`"
        prior = self.prior.get("baseline") or {}
        path = prior.get("_file")
        if not path:
            return None, (
                "no baseline run given (`--param baseline_file=...`, or run `baseline` first)"
                if not prior
                else "the prior baseline summary names no run file"
            )
        try:
            what = "survey: the prior baseline's file"
            rec = usable_baseline(clamped_record(path, what), p, what)
        except BaselineFileError as exc:
            log.warning("the prior baseline is left out: %s", exc)
            return None, f"the prior baseline was left out: {exc}"
        return rec, f"prior baseline summary's file `{rec.source}`"

    def channels(self) -> tuple[str, ...]:
        return CHANNELS

    def headline(self) -> dict[str, tuple[str, ...]]:
        """The headline figures and their channels (``Procedure.headline``); the platform rms
        and the dip carry no interval (``K_ci95`` None)."""
        return dict.fromkeys((k for k in self.json_keys if k != "file"), AXES)

    def pieces(self) -> list[tuple[str, float]]:
        """(step name, seconds) of the record pieces."""
        p = self.params
        n = max(1, math.ceil(p.duration_s / p.piece_s - 1e-9))
        lengths = [p.piece_s] * (n - 1) + [p.duration_s - p.piece_s * (n - 1)]
        return [(f"record {i + 1}/{n}", seconds) for i, seconds in enumerate(lengths)]

    def plan(self) -> list[Step[Any]]:
        # the baseline is chosen before the first step records (and again on a resume)
        self.baseline, self.baseline_note = self.find_baseline()
        p = self.params
        gyro_mode = [
            Step(
                f"mode {p.mode}",
                partial(enter_gyro_mode, mode=p.mode, settle_s=p.mode_settle_s),
                expected_s=p.mode_settle_s,
                setup=True,
                result=ModeSet,
            )
        ]
        back = [Step("back to mode 3", back_to_mode3, expected_s=1.0, setup=True, result=ModeSet)]
        return [
            Step("mode 3", bring_to_mode3, expected_s=300.0, setup=True, result=InMode3),
            Step("settle", self._settle, expected_s=p.settle_s, setup=True, result=Waited),
            *(gyro_mode if p.mode != 3 else []),
            *(
                Step(
                    name,
                    partial(self._record, seconds=seconds),
                    expected_s=seconds,
                    result=Recorded,
                )
                for name, seconds in self.pieces()
            ),
            *(back if p.mode != 3 else []),
        ]

    def _settle(self, ctx: Context) -> Waited:
        already = ctx.result("mode 3", InMode3).already
        seconds = min(5.0, self.params.settle_s) if already else self.params.settle_s
        ctx.acquire(seconds, keep=False)
        return Waited(seconds=seconds)

    def _record(self, ctx: Context, seconds: float) -> Recorded:
        ctx.acquire(seconds, keep=False)  # where the samples are is the runner's record (ctx.spans)
        return Recorded(seconds=seconds)

    # ------------------------------------------------------------------ analysis
    def analyze(self, ctx: Context) -> Analysis:
        p = self.params
        cal = ctx.rig.calibration
        try:
            spans = ctx.data_spans(name for name, _ in self.pieces())
            csd = spans_csd([(s.file, s.start, s.stop) for s in spans], self.channels(), p.seg_s)
        except SpanError as exc:
            raise ProcedureError(str(exc)) from None
        kg_mv, kg_src = pickoff_scales(self.prior, cal.pickoff_scale_mV_per_urad)
        sp = survey_spectra(csd, cal, kg_mv, p)
        f, psd_urad, dips = sp.f, sp.psd_urad, sp.dips
        used = csd.segments_used / max(1, csd.segments_total)

        values: dict[str, Any] = {
            "mode": p.mode,
            "platform_rms_urad": {a: sp.platform_rms_urad[a] for a in AXES},
            "dip_hz": {a: (d.freq_hz if (d := dips[a]) is not None else None) for a in AXES},
            "dip_depth_db": {a: (d.depth_db if (d := dips[a]) is not None else None) for a in AXES},
            "stiffness_from_dip_Nm_per_rad": sp.stiffness_Nm_per_rad,
            "ac_ctl_rms_urad": sp.ac_ctl_rms_urad,
            "pickoff_scale_mV_per_urad": kg_mv,
            "pickoff_scale_source": kg_src,
            "band_hz": [p.band_lo_hz, p.band_hi_hz],
            "record_s": csd.seconds,
        }
        # the platform's own motion, net of pickoff noise: the gyro's part coherent with the
        # autocollimator (procedures.analysis.survey.coherent_platform_rms)
        try:
            blocks = block_csd(
                [(s.file, s.start, s.stop) for s in spans],
                self.channels(),
                p.coherent_seg_s,
                p.coherent_blocks,
            )
            # every axis's autocollimator an input: an axis moves with the other's noise too;
            # the gyro's reading of each axis alone (the float's viscous coupling undone), with
            # the data sheet's h/c and at the ends of its tolerance
            inputs = [ac_inst(b) for b in AXES]
            kg = {a: kg_mv[a] * 1e-3 for a in AXES}
            h_c = cal.viscous_coupling_h_over_c

            # the band's bins alone: each h/c scale combines the gyros afresh
            in_band = blocks.subset(
                blocks.channels, (blocks.f >= p.band_lo_hz) & (blocks.f <= p.band_hi_hz)
            )

            def coherent(scale: float) -> dict[str, Estimate]:
                dec = in_band.combined(decoupled_gyro(kg, h_c, scale))
                return {
                    a: coherent_platform_rms(
                        dec, platform_gyro(a), inputs, 1.0, p.band_lo_hz, p.band_hi_hz
                    )
                    for a in AXES
                }

            net = with_coupling_allowance(
                coherent(1.0),
                lambda s: {a: e.value for a, e in coherent(s).items()},
                VISCOUS_COUPLING_TOLERANCE,
            )
        except TransferError as exc:
            raise ProcedureError(f"survey: {exc}") from None
        base = self._baseline_net(blocks, kg_mv, cal.viscous_coupling_h_over_c)
        if p.mode != 3:
            # the pickoff is in the loop: the platform follows its noise, so neither its part
            # coherent with the autocollimator nor its spectrum less the clamped one is the
            # platform's; the out-of-loop autocollimator is (platform_rms_autocollimator_urad)
            why = (
                f"in Mode {p.mode} the pickoff is in the loop and the platform follows its noise; see "
                f"platform_rms_autocollimator_urad"
            )
            net = {a: Estimate(e.value, e.lo, e.hi, False, why) for a, e in net.items()}
            base = {
                a: dataclasses.replace(
                    b, estimate=Estimate(b.estimate.value, b.estimate.lo, b.estimate.hi, False, why)
                )
                for a, b in base.items()
            }
            # in 4 and 5 the autocollimator is out of the loop: its band rms is the platform's,
            # with its own NEA (0.45 urad, Table 1) in quadrature
            values["platform_rms_autocollimator_urad"] = {
                a: _r(band_rms(f, psd_urad[ac_inst(a)], p.band_lo_hz, p.band_hi_hz)) for a in AXES
            }
        add_figure(values, "platform_rms_net_urad", net, digits=4)
        # Ch. V E.2 less the clamped platform's pickoff spectrum (Ch. V B, Fig. 33), bin by bin
        add_figure(
            values,
            "platform_rms_baseline_net_urad",
            {a: b.estimate for a, b in base.items()},
            digits=4,
        )
        values["baseline_pickoff_band_rms_urad"] = {
            a: _r(b.baseline_rms_urad) for a, b in base.items()
        }
        values["gyro_band_rms_urad"] = {a: _r(b.survey_rms_urad) for a, b in base.items()}
        rec = self.baseline
        values["baseline"] = (
            {
                "file": str(rec.source),
                "record_file": str(rec.file),
                "axis": rec.axis,
                "record_s": round(rec.seconds, 3),
                "from": self.baseline_note,
            }
            if rec is not None
            else {"file": None, "from": self.baseline_note}
        )
        # Fig. 48: a noise common to the two autocollimator axes shows as coherence where the
        # sensors' own noise dominates; independent channels give about 1/n
        cross = cross_axis_coherence(csd, ac_ctl("X"), ac_ctl("Y"))
        values["cross_axis_coherence"] = cross.values()
        ms: list[Measurement] = []
        for a in AXES:
            d = dips[a]
            ms.append(
                Measurement(
                    f"dip {a} ({ac_ctl(a)})",
                    d.freq_hz if d else None,
                    "Hz",
                    note=f"searched {p.dip_lo_hz:g}-{p.dip_hi_hz:g} Hz",
                )
            )
            ms.append(
                Measurement(
                    f"dip {a} depth (prominence)",
                    d.depth_db if d else None,
                    "dB",
                    lo=p.min_dip_depth_db,
                    note="no notch: the dip frequency is meaningless"
                    if d is None or d.depth_db < p.min_dip_depth_db
                    else "",
                )
            )
            ms.append(
                Measurement(
                    f"platform rms {a}, gyro-deduced {p.band_lo_hz:g}-{p.band_hi_hz:g} Hz",
                    sp.platform_rms_urad[a],
                    "urad",
                    note=f"Kg {kg_mv[a]:.4g} mV/urad ({kg_src[a]})",
                )
            )
        for a in AXES:
            e = net[a]
            ms.append(
                Measurement(
                    f"platform rms {a} net of pickoff noise (gyro coherent with {ac_inst(a)})",
                    e.value if e.resolved else None,
                    "urad",
                    note=f"95 % [{e.lo:.3g}, {e.hi:.3g}]"
                    + ("" if e.resolved else f"; not resolved: {e.why}"),
                )
            )
        for a in AXES:
            e = base[a].estimate
            ms.append(
                Measurement(
                    f"platform rms {a} net of the baseline's pickoff noise ({gyro(a)} clamped, "
                    f"{p.band_lo_hz:g}-{p.band_hi_hz:g} Hz)",
                    e.value if e.resolved else None,
                    "urad",
                    note=(f"95 % [{e.lo:.3g}, {e.hi:.3g}]" if math.isfinite(e.lo) else "")
                    + (
                        ""
                        if e.resolved
                        else f"{'; ' if math.isfinite(e.lo) else ''}not resolved: {e.why}"
                    ),
                )
            )
        for a, v in (values.get("platform_rms_autocollimator_urad") or {}).items():
            ms.append(
                Measurement(
                    f"platform rms {a}, out-of-loop autocollimator ({ac_inst(a)}) "
                    f"{p.band_lo_hz:g}-{p.band_hi_hz:g} Hz, Mode {p.mode}",
                    v,
                    "urad",
                    note="the pickoff is in the loop here: the gyro-deduced figure is not the platform's",
                )
            )
        ms.append(
            Measurement(
                f"coherence {cross.pair[0]} - {cross.pair[1]}, mean {cross.band_hz[0]:g}-"
                f"{cross.band_hz[1]:g} Hz",
                cross.mean,
                "",
                note=f"{'significant' if cross.significant else 'not significant'}: {cross.z:.1f} "
                f"standard deviations above independent channels' {cross.null_mean:.3g}",
            )
        )
        ms.append(
            Measurement(
                "Welch segments usable (no lost samples)",
                used,
                "",
                lo=p.min_segments_used,
                note=f"{csd.segments_used} of {csd.segments_total}",
            )
        )

        title = (
            f"{Path(ctx.path).name}, Mode {p.mode}, {csd.seconds:.0f} s at {csd.fs:g} Hz, "
            f"{csd.segments_used} segments"
        )
        figures = [
            Figure(
                "dip",
                "Autocollimator control-channel spectra (smoothed dB) over the dip search band, "
                "with the dips found",
                partial(plot_dips, f=f, psd_urad=psd_urad, dips=dips, p=p),
            )
        ]
        dof_bin = csd.dof
        for c in self.channels():
            figures.append(
                Figure(
                    f"psd-{c}",
                    f"PSD of {c} in urad²/Hz (App. A.8 display)",
                    partial(
                        plot_psd,
                        f=f[1:-1],
                        p=psd_urad[c][1:-1],
                        channel=c,
                        units="urad",
                        dof=dof_bin,
                        nperseg=csd.nperseg,
                        nfft=csd.nfft,
                        title=title,
                    ),
                )
            )
        idx = {c: i for i, c in enumerate(csd.channels)}
        for x, y in COHERENCE_PAIRS:
            figures.append(
                Figure(
                    f"coherence-{x}-{y}",
                    f"Coherence {x} – {y}",
                    partial(
                        plot_coherence,
                        f=f[1:-1],
                        coh=sp.coh[1:-1, idx[x], idx[y]],
                        pair=(x, y),
                        n_segments=csd.segments_used,
                        title=title,
                    ),
                )
            )
        md = markdown(
            values,
            dips,
            kg_src,
            csd,
            sp.peak_coherence,
            p,
            self.reference,
            (self.prior.get("stopwatch") or {}).get("_from"),
        )
        return Analysis(values, ms, figures, md)

    def _baseline_net(
        self, blocks: BlockCsd, kg_mv: Mapping[str, float], h_c: Mapping[str, float]
    ) -> dict[str, BaselineNet]:
        """Per axis, the platform rms net of the baseline's pickoff noise; unresolved (with why)
        where there is no baseline, or its record cannot be read or set against the survey's."""
        p, rec = self.params, self.baseline

        def none(why: str) -> BaselineNet:
            nan = float("nan")
            return BaselineNet(Estimate(nan, nan, nan, False, why), nan, nan, nan)

        if rec is None:
            return {a: none(self.baseline_note) for a in AXES}
        missing = [gyro(a) for a in AXES if gyro(a) not in rec.channels]
        if missing:
            # each axis's reading takes both of the X-Y gyro's pickoffs (decoupled_gyro)
            return {a: none(f"the baseline holds no {', '.join(missing)}") for a in AXES}
        kg = {a: kg_mv[a] * 1e-3 for a in AXES}
        try:
            bb = block_csd(
                [(rec.file, rec.start, rec.stop)],
                [gyro(a) for a in AXES],
                p.coherent_seg_s,
                p.baseline_blocks,
            )

            def net(scale: float) -> dict[str, BaselineNet]:
                dec = decoupled_gyro(kg, h_c, scale)
                sb, bb_ = blocks.combined(dec), bb.combined(dec)
                return {
                    a: baseline_net_rms(
                        sb, platform_gyro(a), bb_, platform_gyro(a), 1.0, p.band_lo_hz, p.band_hi_hz
                    )
                    for a in AXES
                }

            nominal = net(1.0)
            allowed = with_coupling_allowance(
                {a: b.estimate for a, b in nominal.items()},
                lambda s: {a: b.estimate.value for a, b in net(s).items()},
                VISCOUS_COUPLING_TOLERANCE,
            )
            return {a: dataclasses.replace(b, estimate=allowed[a]) for a, b in nominal.items()}
        except (TransferError, BaselineMismatch, OSError) as exc:
            log.warning("survey: the baseline %s cannot be used: %s", rec.source, exc)
            return {a: none(f"the baseline's record cannot be used: {exc}") for a in AXES}


def _r(v: float) -> float | None:
    return round(v, 5) if math.isfinite(v) else None


PROCEDURE = Survey
