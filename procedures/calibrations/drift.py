"""``drift``: gyro drift stability from a long Mode-3 record of the torquer and pickoff outputs.

In Mode 3 the caging loops hold every pickoff near null. The float's equation of motion (thesis
II C.1.a(8), III A; docs/simhw.md section 3) gives each channel's input rate from what is recorded:

    Omega_in = sigma' + sigma / (h/k) - K_TO V_T        (urad/s; earth rate + drift)

sigma = V_g / K_g the pickoff angle, h/k the float's restraint time constant. The earth-rate
component is constant on a fixed table, so the wander of Omega_in is the drift's. Per channel the
analysis gives the overlapping Allan deviation, the gyro's angle random walk N and bias
instability B each with its 95 % interval (or, unresolved, the bound the data support), the
caging loop's gain G_p and the null stability; how is ``procedures.analysis.drift`` (its
docstring), usable without a rig. The report's text and plots are ``procedures.reports.drift``.
This module holds the parameters, the steps and the analysis that ties them together.

K_TO and K_g are scales only: earlier ``earth-rate`` and ``stopwatch`` results are used when the
procedure is given them (``prior``), else the rig's nominal data-sheet values, which the report
says; h/k and the floats' viscous coupling h/c are data-sheet constants.

Steps: Mode 3 and a settle (setup, run again on ``--resume``), then the record in
``n_chunks`` data steps, each returning its file and time span, so an aborted overnight record
resumes where it stopped; the analysis pools the chunks' gap-free runs (Allan terms never
straddle a gap or a resume).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import partial
from typing import Annotated, Any

import numpy as np

from drivers.rig_datasheet import GYRO_CHANNELS
from procedures.analysis.drift import (
    ChannelDrift,
    DriftDataError,
    analyze_channels,
    load_record,
    pickoff,
    pickoff_stats,
    torq,
)
from procedures.analysis.intervals import add_figure
from procedures.paramlimits import Range, above, at_least, check_limits, sample_rate
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
from procedures.reports.drift import hours, markdown, plot_allan, plot_null
from procedures.rigsetup import InMode3, bring_to_mode3, wait_settled
from procedures.stepresult import Recorded, Waited

#: the ADC's anti-alias filter is 3-pole at 0.3 fs (DESIGN.md section 5): the first few
#: samples' Allan deviation is shaped by it, so the noise-model fit starts at this many samples
MIN_FIT_SAMPLES = 2.0


@dataclass
class DriftParams:
    #: record length (rig seconds) after the settle
    duration_s: Annotated[float, above(0)] = 7200.0
    rate_hz: Annotated[float, sample_rate()] = 10.0
    #: the record is split into this many data steps (each resumable)
    n_chunks: Annotated[int, Range(1, 1000)] = 10
    #: settle: the torquing rate changes by less than this over ``settle_window_s`` (urad/s)
    settle_tol_urad_per_s: Annotated[float, above(0)] = 0.02
    settle_window_s: Annotated[float, above(0)] = 40.0
    settle_min_s: Annotated[float, at_least(0)] = 120.0
    settle_timeout_s: Annotated[float, above(0)] = 900.0
    #: the shortest averaging time of the noise-model fit (s): the anti-alias filter shapes shorter ones
    fit_tau_lo_s: Annotated[float, above(0)] = 0.4
    #: band (Hz) where G_p is measured, well above the loop's bandwidth: from loop_band_lo_hz to
    #: loop_band_hi_frac x the sample rate (both channels pass the same anti-alias filter)
    loop_band_lo_hz: Annotated[float, above(0)] = 0.2
    loop_band_hi_frac: Annotated[
        float, Range(0.0, 0.5, lo_open=True, note="of the sample rate: 0.5 is Nyquist")
    ] = 0.2
    #: Allan points with fewer equivalent degrees of freedom (Greenhall's, for the term's own noise
    #: type) are not read for N or B (allan.term_estimate)
    min_edf: Annotated[float, at_least(1)] = 10.0
    #: null stability: the means averaged over this long, and the span the estimate is for
    average_s: Annotated[float, above(0)] = 100.0
    null_span_s: Annotated[float, above(0)] = 86400.0
    #: quality limits: the record must cover this much, and lose at most this fraction of samples
    min_record_s: Annotated[float, at_least(0)] = 300.0
    max_lost_fraction: Annotated[float, Range(0.0, 1.0)] = 0.01
    #: how far a unit's K_TO and K_g may lie from the data sheet (relative, 95 %): where the
    #: procedure has no earth-rate or stopwatch result it uses the data sheet's, and the N and B
    #: intervals are widened by this much (``ChannelDrift.figure_tolerance``; issue 38: rigs drawn
    #: with K_TO x0.85-1.15 and K_g x0.8-1.2 put intervals of nominal-scale runs off the truth)
    nominal_kto_tol: Annotated[float, Range(0.0, 0.9)] = 0.15
    nominal_kg_tol: Annotated[float, Range(0.0, 0.9)] = 0.20

    def __post_init__(self) -> None:
        check_limits(self, "drift")
        # what no one field can declare: limits that tie fields together
        if self.fit_tau_lo_s * self.rate_hz < MIN_FIT_SAMPLES - 1e-9:
            raise ValueError(
                f"drift: fit_tau_lo_s = {self.fit_tau_lo_s:g} s is "
                f"{self.fit_tau_lo_s * self.rate_hz:g} samples at rate_hz = {self.rate_hz:g} Hz; it must "
                f"be >= {MIN_FIT_SAMPLES:g} samples (the anti-alias filter shapes shorter averages)"
            )
        if not self.loop_band_lo_hz < self.loop_band_hi_frac * self.rate_hz:
            raise ValueError(
                f"drift: loop-gain band {self.loop_band_lo_hz:g} .. "
                f"{self.loop_band_hi_frac * self.rate_hz:g} Hz is empty: loop_band_lo_hz must be below "
                f"loop_band_hi_frac x rate_hz"
            )
        if not self.null_span_s >= self.average_s:
            raise ValueError(
                f"drift: null_span_s = {self.null_span_s} must be >= average_s = {self.average_s}"
            )


#: the name the module's functions and tests use
Params = DriftParams


class Drift(Procedure[DriftParams]):
    name = "drift"
    demo_order = 70  # with the earth-rate K_TO and the stopwatch K_g
    title = "Gyro drift: Allan analysis of the rate from torquer and pickoff (Mode 3)"
    json_keys = ("bias_instability_urad_per_s", "arw_urad_per_sqrt_s", "file")
    Params = DriftParams
    mode = 3
    block_s = 1.0

    def __init__(self, params: DriftParams | None = None, **kw) -> None:
        super().__init__(params, **kw)
        self.rate_hz = float(self.params.rate_hz)

    def channels(self) -> tuple[str, ...]:
        # the pickoffs ride along as the check that the loops held them at null
        return tuple(torq(c) for c in GYRO_CHANNELS) + tuple(pickoff(c) for c in GYRO_CHANNELS)

    def headline(self) -> dict[str, tuple[str, ...]]:
        """The headline figures and their channels (``Procedure.headline``)."""
        return dict.fromkeys((k for k in self.json_keys if k != "file"), GYRO_CHANNELS)

    def chunk_names(self) -> list[str]:
        n = int(self.params.n_chunks)
        return [f"record {i + 1}/{n}" for i in range(n)]

    def plan(self) -> list[Step[Any]]:
        p = self.params
        chunk_s = p.duration_s / int(p.n_chunks)
        return [
            Step("mode 3", bring_to_mode3, expected_s=300.0, setup=True, result=InMode3),
            Step(
                "settle",
                self.settle,
                expected_s=max(p.settle_min_s, p.settle_window_s) + 20.0,
                setup=True,
                result=Waited,
            ),
            *(
                Step(
                    name, partial(self.record, seconds=chunk_s), expected_s=chunk_s, result=Recorded
                )
                for name in self.chunk_names()
            ),
        ]

    # ------------------------------------------------------------------ steps
    def kto_sources(self, ctx: Context) -> tuple[dict[str, float], dict[str, str]]:
        """K_TO per channel (urad/s/V) and, per channel, where it came from ("nominal" or the prior's)."""
        nominal = ctx.rig.calibration.torquer_scale_urad_per_s_per_V
        return prior_values(
            self.prior, "earth-rate", "K_TO_urad_per_s_per_V", GYRO_CHANNELS, nominal
        )

    def kto(self, ctx: Context) -> tuple[dict[str, float], str]:
        """K_TO per channel (urad/s/V) and where it came from."""
        out, sources = self.kto_sources(ctx)
        used_nominal = [ch for ch, src in sources.items() if src == "nominal"]
        if not used_nominal:
            source = "earth-rate result (prior run)"
        elif len(used_nominal) == len(GYRO_CHANNELS):
            source = "NOMINAL data-sheet values (no earth-rate result given)"
        else:
            source = f"earth-rate result; NOMINAL data-sheet value for {', '.join(used_nominal)}"
        return out, source

    def settle(self, ctx: Context) -> Waited:
        p = self.params
        kto, _ = self.kto(ctx)
        cols = [ctx.column(torq(c)) for c in GYRO_CHANNELS]
        tol_V = np.array([p.settle_tol_urad_per_s / abs(kto[c]) for c in GYRO_CHANNELS])
        s = wait_settled(
            ctx,
            cols,
            tol_V=tol_V,
            window_s=p.settle_window_s,
            min_s=p.settle_min_s,
            timeout_s=p.settle_timeout_s,
        )
        return Waited(seconds=round(s.waited_s, 1))

    def record(self, ctx: Context, seconds: float) -> Recorded:
        ctx.acquire(seconds, keep=False)  # where the samples are is the runner's record (ctx.spans)
        return Recorded(seconds=seconds)

    # ------------------------------------------------------------------ analysis
    def analyze(self, ctx: Context) -> Analysis:
        p = self.params
        spans = ctx.data_spans(self.chunk_names())
        if not spans:
            raise ProcedureError("no record step was done: nothing to analyse")
        kto, kto_source = self.kto(ctx)
        try:
            chunks, total, lost, rate = load_record(
                [(s.file, s.start, s.stop) for s in spans], list(self.channels()), self.rate_hz
            )
        except DriftDataError as exc:
            raise ProcedureError(str(exc)) from None
        record_s = total / rate
        cal = ctx.rig.calibration
        kg, kg_sources = prior_values(
            self.prior, "stopwatch", "K_g_mV_per_urad", GYRO_CHANNELS, cal.pickoff_scale_mV_per_urad
        )
        # the float's restraint and viscous coupling are data-sheet constants (Table 3)
        h_over_c = cal.viscous_coupling_h_over_c
        _, kto_sources = self.kto_sources(ctx)
        tol = {
            ch: (
                p.nominal_kto_tol if kto_sources[ch] == "nominal" else 0.0,
                p.nominal_kg_tol if kg_sources[ch] == "nominal" else 0.0,
            )
            for ch in GYRO_CHANNELS
        }
        try:
            res = analyze_channels(
                chunks,
                rate,
                kto,
                p,
                kg,
                dict(cal.restraint_time_constant_s),
                h_over_c,
                scale_tol=tol,
            )
        except DriftDataError as exc:
            raise ProcedureError(str(exc)) from None
        ms: list[Measurement] = [
            Measurement(
                "record length",
                record_s,
                "s",
                lo=p.min_record_s,
                note=f"{sum(1 for n in self.chunk_names() if n in ctx.spans)} of "
                f"{len(self.chunk_names())} chunks in {len(spans)} continuous stretch(es)",
            ),
            Measurement("samples lost", lost / max(total, 1), "fraction", hi=p.max_lost_fraction),
        ]
        for r in res.values():
            ms += channel_measurements(r)
        values: dict = {}
        add_figure(
            values, "bias_instability_urad_per_s", {ch: r.estimate("bias") for ch, r in res.items()}
        )
        add_figure(values, "arw_urad_per_sqrt_s", {ch: r.estimate("arw") for ch, r in res.items()})
        md = markdown(
            res,
            p,
            kto,
            kto_source,
            record_s,
            lost,
            total,
            pickoff_stats(chunks, kg),
            any(src != "nominal" for src in kg_sources.values()),
        )
        figures = [
            Figure(
                "allan",
                "Overlapping Allan deviation of the gyro's input rate reconstructed from torquer and "
                "pickoff, per channel, with 68 % confidence intervals (Greenhall EDF) and the fitted IEEE 952 "
                "noise model; thin: the torquing rate -K_TO V_T alone (the caging loop's output)",
                partial(plot_allan, res=res, p=p),
            ),
            Figure(
                "null",
                f"Reconstructed input rate, {p.average_s:g}-s means, over the {hours(record_s)} record (mean "
                "removed): the null-stability wander",
                partial(plot_null, res=res, p=p),
            ),
        ]
        return Analysis(values, ms, figures, md)


def channel_measurements(r: ChannelDrift) -> list[Measurement]:
    """A channel's read-offs as measurements, each noting how it was read (or why it was not)."""
    ch = r.channel
    out = []
    for term, name, unit in (
        ("arw", "ARW", "urad/sqrt(s)"),
        ("bias", "bias instability", "urad/s"),
    ):
        e = r.estimate(term)
        t = r.arw if term == "arw" else r.bi
        iv = f"95 % [{e.lo:.3g}, {e.hi:.3g}]"
        if t is not None and math.isfinite(t.tau_s):
            how = f"read at tau {t.tau_s:g} s, {100 * t.share:.0f} % of the modelled Allan variance there"
        else:
            how = "no share in the fitted noise model"
        if e.resolved:
            note = f"{iv}; {how}"
        else:
            note = f"not resolved ({e.why}): {iv}" + (f"; {how}" if t is not None else "")
        # a figure the record cannot give at all (too short) fails; an unresolved one is a result
        out.append(
            Measurement(
                f"{name} {ch}",
                e.value if e.resolved else None,
                unit,
                lo=0.0 if t is None else None,
                note=note,
            )
        )
    if r.loop is not None:
        lg = r.loop
        out.append(
            Measurement(
                f"caging loop gain G_p {ch}",
                lg.gain_per_s,
                "1/s",
                note=f"torquing rate per pickoff angle, "
                f"{lg.band_hz[0]:.3g}..{lg.band_hz[1]:.3g} Hz; "
                f"pickoff output {lg.pickoff_asd:.3g} urad/sqrt(Hz) there, through it: "
                f"N_loop {lg.white_rate:.3g} urad/sqrt(s)",
            )
        )
    if r.null is not None:
        n = r.null
        out.append(
            Measurement(
                f"null stability {ch}, p-p of {n.avg_s:g}-s means over {hours(n.record_s)}",
                n.peak_to_peak,
                "urad/s",
            )
        )
        how = (
            "measured"
            if n.measured_over_span
            else f"estimated: x {n.ratio:.3g} from the Allan deviation, extrapolated beyond tau "
            f"{n.extrapolated_from_tau_s:g} s with slope {n.extrapolation_slope:+.2f}"
        )
        out.append(
            Measurement(
                f"null stability {ch}, {hours(n.span_s)} p-p", n.estimate, "urad/s", note=how
            )
        )
    return out


PROCEDURE = Drift
