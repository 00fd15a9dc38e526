"""``stopwatch``: the pickoff scale factor K_g by the stopwatch method (thesis II C.1.a(6)).

With one channel's caging inhibited and its precession nulled by the torquer bias, a bias
step dV_T makes the float precess at K_TO dV_T, and the pickoff ramps at K_g K_TO dV_T.
The time dt for the pickoff to change by a set amount dV_g gives

    K_g = dV_g / (dt dV_T K_TO)                                             (II C.1.a(6))

Per channel, all decided from the data and read back from the ADC:

1. Caged reference: once every caging loop has been closed ``min_caged_s`` since mode 3 (a
   step resumed just after mode 3 waits as an uninterrupted one has), the settled torquer
   output V_T0 is exactly the null torquer voltage.
2. Caging inhibited; the bias-to-torquer-output gain g is measured with one small bias step
   (the output follows the bias at once with the loop open), then the bias set so the output
   equals V_T0, and the residual precession checked from the pickoff slope and trimmed until it
   is below ``null_tolerance_urad_per_s``.
3. Ramps: bias steps of +-dV_T (rate ``ramp_rate_urad_per_s`` with the K_TO in use) drive the
   pickoff back and forth between levels ``V_g0 +- dV_g/2`` (``V_g0`` the null position); each
   ramp's time between the two level crossings (of a ``smooth_s`` moving average) is one
   stopwatch reading. A repetition is a ramp down and a ramp up; their mean cancels a
   residual rate (the spread is that of the repetitions).
4. Elastic restraint (h/k): the float's restraint pulls it back toward the null at
   (sigma - sigma_0)/(h/k). For a ramp from -D to +D about the null, u' = r - u/tau gives
   r = (D/tau) coth(dt / 2 tau), so the corrected value is the naive one times
   x coth x, x = dt / (2 tau): the symmetric ramps keep the correction to second order.
   tau comes from a least-squares fit of the pickoff's increments over the open-loop record
   (``restraint_fit``):

       dV_g = a int (V_T - V_T0) dt + c dt - k int (V_g - V_g0) dt + b int V_T,partner dt

   (a = K_g K_TO, c the residual null rate, k = 1/tau; the partner is the channel sharing the
   float, whose caging loop pushes it through the viscous coupling, II C.4.d). The holds between
   ramps, where only the restraint moves the pickoff, determine k. The fit also carries
   (1 + (c/h)_a (c/h)_b) and the random drift, so h/k is shown with its interval but never
   reported as a figure (``h_over_k_s`` is ``resolved: false``); the x coth x correction it
   feeds is a few 0.01 %.
4b. Float partner: while the channel ramps, its float partner's caging loop answers the viscous
   cross-coupling (II C.4.d) over 30-40 s, first slowing the ramp (by up to (c/h)_a (c/h)_b,
   2.4 % on the X-Y float) and then, overshooting, speeding it; a crossing window reads low or
   high (-0.3 .. +0.3 %) by where it sits in that transient, alike in both directions. The step
   integrates the coupled pair driven by the recorded torquer (``partner_factors``: Table 3's
   h/c, the partner's caging design) and each reading is divided by its window's factor; K_g's
   interval carries a bound on what the model may leave.
5. Restore: caging released with the bias still holding the null, the bias slewed to zero
   while the loop takes over, settled.

K_TO is taken from ``Params.kto_urad_per_s_per_V``, else an earlier earth-rate result
(``prior``), else the rig's nominal data-sheet value, and the report says which. K_g's 95 %
interval is Student's t over the repetitions combined with that K_TO's interval (none for a
given value; with the nominal value K_g is not resolved).

This module holds the parameters, the steps and the analysis that ties them together; the
numerics (crossing times, the restraint fit, the corrected readings) are
``procedures.analysis.stopwatch`` and the report's table and plots ``procedures.reports.stopwatch``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Annotated, Any

import numpy as np

from drivers.rig_datasheet import FLOAT_PARTNER, GYRO_CHANNELS
from procedures.analysis.intervals import add_figure
from procedures.analysis.stopwatch import (
    PROPORTIONAL_ONLY,
    ChannelRun,
    NoCrossing,
    channel_result,
    crossing_times,
    partner_factors,
    restraint_fit,
    slope,
)
from procedures.paramlimits import Each, OneOf, Range, above, check_limits, fraction, sample_rate
from procedures.params import prior_rel_half_width, prior_value
from procedures.procedure import (
    Analysis,
    Context,
    Figure,
    Measurement,
    Procedure,
    ProcedureError,
    Step,
)
from procedures.reports.stopwatch import markdown, plot_channel
from procedures.rigsetup import InMode3, bring_to_mode3, wait_settled

#: the parameters' limits too long to read inline
_CHANNEL = OneOf(*GYRO_CHANNELS)
_KTO = Range(
    0, 1e3, lo_open=True, hi_open=True, units="urad/s/V", note="the data sheet's are 31-34"
)


@dataclass
class StopwatchParams:
    channels: Annotated[list[str], Each(_CHANNEL, nonempty=True)] = field(
        default_factory=lambda: list(GYRO_CHANNELS)
    )
    #: K_TO per channel (urad/s/V); empty: the earth-rate result, else the data sheet's nominal
    kto_urad_per_s_per_V: Annotated[dict[str, float], Each(_KTO, keys=_CHANNEL)] = field(
        default_factory=dict
    )
    delta_pickoff_V: Annotated[
        float, Range(0.05, 8.0, units="V", note="the pickoff's linear range is about +-6 V")
    ] = 2.0
    #: fast enough that the gyro's random drift (a few tenths of urad/s over minutes on Z) is a
    #: small part of the ramp rate; a down-up pair cancels what is left
    ramp_rate_urad_per_s: Annotated[float, Range(0.1, 100.0)] = 20.0
    #: a repetition is a ramp down and a ramp up: their mean cancels any residual rate. At most 4:
    #: a channel's step result (every ramp's time and factor) is one 1 KiB event of the run file,
    #: and 5 no longer fit with room to spare - refused here, not after the channel's 20 minutes
    repetitions: Annotated[int, Range(1, 4, note="a channel's result is one 1 KiB event")] = 3
    hold_s: Annotated[float, above(0)] = 20.0
    null_s: Annotated[float, above(0)] = 20.0
    null_tolerance_urad_per_s: Annotated[float, above(0)] = 0.1
    #: limit on the residual: a few % of the ramp rate (the down-up pairs cancel it; Z's random
    #: drift wanders by a few tenths of urad/s over minutes, so a tighter null does not hold)
    max_null_rate_urad_per_s: Annotated[float, above(0)] = 0.5
    smooth_s: Annotated[float, above(0)] = 1.0
    restore_s: Annotated[float, above(0)] = 100.0
    #: a channel's loop is opened only after every caging loop has been closed this long: the
    #: loops' transients (0.1 rad/s, and the float partner's through the viscous coupling) gone,
    #: so a step resumed just after mode 3 starts from the state an uninterrupted run gives it
    min_caged_s: Annotated[float, above(0)] = 300.0
    rate_hz: Annotated[float, sample_rate()] = 200.0
    #: limits: K_g within this fraction of the data sheet's nominal; repetition spread
    kg_tolerance: Annotated[float, fraction(note="of the nominal K_g")] = 0.25
    max_spread: Annotated[float, above(0)] = 0.02

    def __post_init__(self) -> None:
        # every check is a declared limit (procedures.paramlimits): none ties fields together
        check_limits(self, "stopwatch")


#: the name the module's functions and tests use
Params = StopwatchParams


class Stopwatch(Procedure[StopwatchParams]):
    name = "stopwatch"
    demo_order = 20  # with the earth-rate K_TO
    title = "Pickoff scale factor by the stopwatch method (II C.1.a(6))"
    json_keys = ("K_g_mV_per_urad", "h_over_k_s", "file")
    Params = StopwatchParams
    mode = 3
    block_s = 0.5

    def __init__(self, params: StopwatchParams | None = None, **kw) -> None:
        super().__init__(params, **kw)
        self.rate_hz = self.params.rate_hz
        if len(self.params.channels) == 1:
            self.axis = self.params.channels[0]

    def channels(self) -> tuple[str, ...]:
        return tuple(f"gyro_{c.lower()}" for c in GYRO_CHANNELS) + tuple(
            f"torq_{c.lower()}" for c in GYRO_CHANNELS
        )

    def headline(self) -> dict[str, tuple[str, ...]]:
        """The headline figures and their channels (``Procedure.headline``)."""
        channels = tuple(self.params.channels)
        return dict.fromkeys((k for k in self.json_keys if k != "file"), channels)

    def kto(self, ctx: Context, ch: str) -> tuple[float, str]:
        if ch in self.params.kto_urad_per_s_per_V:
            return float(self.params.kto_urad_per_s_per_V[ch]), "given"
        return prior_value(
            self.prior,
            "earth-rate",
            "K_TO_urad_per_s_per_V",
            ch,
            ctx.rig.calibration.torquer_scale_urad_per_s_per_V[ch],
        )

    def kto_rel_half_width(self, ch: str, source: str, kto: float) -> float | None:
        """The relative 95 % half-width of the K_TO in use: 0 for a value given as a parameter
        (the user vouches for it), the earth-rate result's own interval, ``None`` for the data
        sheet's nominal value (no measurement: K_g is then not resolved)."""
        if source == "given":
            return 0.0
        # an earth-rate summary without intervals (an older run): not a judged K_TO
        return prior_rel_half_width(self.prior, source, "K_TO_urad_per_s_per_V", ch, kto)

    def plan(self) -> list[Step[Any]]:
        p = self.params
        per = 200.0 + p.null_s * 2 + (2 * p.repetitions + 1) * (p.hold_s + 45.0) + p.restore_s
        return [
            Step("mode 3", bring_to_mode3, expected_s=300.0, setup=True, result=InMode3),
            *(
                Step(
                    f"channel {ch}", partial(self.channel, ch=ch), expected_s=per, result=ChannelRun
                )
                for ch in p.channels
            ),
        ]

    # ------------------------------------------------------------------ one channel
    def channel(self, ctx: Context, ch: str) -> ChannelRun:
        p, rig = self.params, ctx.rig
        kto, source = self.kto(ctx, ch)
        kg_nom = (
            rig.calibration.pickoff_scale_mV_per_urad[ch] * 1e-3
        )  # V/urad, only to trim the null
        gcol, tcol = ctx.column(f"gyro_{ch.lower()}"), ctx.column(f"torq_{ch.lower()}")
        rec = _Record(gcol, tcol, ctx.column(f"torq_{FLOAT_PARTNER[ch].lower()}"))

        # 1. caged reference, once the loops have been closed min_caged_s (resumed or not)
        if rig.caging.inhibited(ch):
            rig.set_caging_inhibit(ch, False)
        rig.set_torquer_bias_V(ch, 0.0)
        t_caged = ctx.result("mode 3", InMode3).t_caged_s
        if ctx.time_s - t_caged < p.min_caged_s:
            ctx.acquire(p.min_caged_s - (ctx.time_s - t_caged), keep=False)
        caged_for = ctx.time_s - t_caged
        wait_settled(ctx, [tcol], tol_V=3e-4, min_s=60.0, window_s=40.0)
        vt0 = float(np.nanmean(ctx.acquire(p.null_s)[:, tcol]))

        # 2. open the loop, measure the bias gain, null the precession
        t_open = ctx.time_s
        rig.set_caging_inhibit(ch, True)
        skip = max(10, int(0.05 * p.rate_hz))  # the ADC's anti-alias filter settling after a step
        m0 = float(np.nanmean(rec.take(ctx, 0.5)[skip:, 1]))
        probe = 0.5 if vt0 <= 0 else -0.5
        rig.set_torquer_bias_V(ch, probe)
        m1 = float(np.nanmean(rec.take(ctx, 0.5)[skip:, 1]))
        gain = (m1 - m0) / probe
        if not abs(gain) > 1e-3:
            raise ProcedureError(
                f"stopwatch {ch}: the torquer output did not follow the bias (gain {gain:.3g} V/V); "
                f"check the torquer bias wiring and the caging-inhibit switch"
            )
        bias = rig.set_torquer_bias_V(ch, (vt0 - m0) / gain)
        tol = p.null_tolerance_urad_per_s * kg_nom
        for trim in range(5):
            data = rec.take(ctx, p.null_s)
            null_slope = slope(data[:, 0], 1.0 / p.rate_hz)
            if abs(null_slope) < tol or trim == 4:
                break  # a residual beyond the tolerance fails its measurement; the down-up pairs cancel it
            bias = rig.set_torquer_bias_V(ch, bias - null_slope / (kg_nom * kto * gain))
        vt_null = float(np.nanmean(data[:, 1]))
        vg0 = float(np.nanmean(data[-int(p.smooth_s * p.rate_hz) :, 0]))
        t_null = ctx.time_s

        # 3. ramps between vg0 -+ dV_g/2
        step_bias = p.ramp_rate_urad_per_s / (kto * abs(gain))
        half = p.delta_pickoff_V / 2
        lo, hi = vg0 - half, vg0 + half
        margin = 0.15 * half
        expected = p.delta_pickoff_V / (kg_nom * p.ramp_rate_urad_per_s)
        ramps: list[tuple[int, float, float]] = []
        windows: list[tuple[float, float]] = []
        direction = +1
        self._ramp(
            ctx,
            rec,
            ch,
            bias,
            step_bias * direction * np.sign(gain),
            hi + margin,
            direction,
            expected,
        )
        rec.hold(ctx, ch, bias, p.hold_s)
        for _ in range(2 * p.repetitions):
            direction = -direction
            target = (lo - margin) if direction < 0 else (hi + margin)
            i0 = rec.n
            self._ramp(
                ctx,
                rec,
                ch,
                bias,
                step_bias * direction * np.sign(gain),
                target,
                direction,
                2 * expected,
            )
            t, vg, vt = rec.arrays(i0)
            try:
                t1, t2 = crossing_times(t, vg, lo, hi, direction, p.smooth_s, p.rate_hz)
            except NoCrossing as exc:
                raise ProcedureError(str(exc)) from None
            # the torquer step between the crossings: not the ADC filter's settling after the bias step
            dvt = float(np.nanmean(vt[(t >= t1) & (t <= t2)]) - vt_null)
            ramps.append((int(direction), round(t2 - t1, 5), round(float(dvt), 7)))
            windows.append((t1, t2))
            rec.hold(ctx, ch, bias, p.hold_s)
        # back to the null position
        back = -1 if rec.last_vg() > vg0 else +1
        self._ramp(ctx, rec, ch, bias, step_bias * back * np.sign(gain), vg0, back, 2 * expected)
        rig.set_torquer_bias_V(ch, bias)
        t_end = ctx.time_s
        t_fit, vg_fit, vt_fit = rec.arrays(rec.index_at(t_null))
        fit = restraint_fit(
            t_fit,
            vg_fit,
            vt_fit,
            vt_null=vt_null,
            vg0=vg0,
            dt_s=0.5,
            partner=rec.partner(rec.index_at(t_null)),
        )
        # the ramp slope without the partner term, whose 1 / (1 + (c/h)_a (c/h)_b) it would carry
        slope_fit = restraint_fit(t_fit, vg_fit, vt_fit, vt_null=vt_null, vg0=vg0, dt_s=0.5)
        # the float partner's caging transient over each window (II C.4.d): the data sheet's h/c
        # and caging design, driven by this channel's torquer as recorded
        partner, cal = FLOAT_PARTNER[ch], rig.calibration
        factors = partner_factors(
            t_fit,
            (vt_fit - vt_null) * kto,
            windows,
            h_over_c=cal.viscous_coupling_h_over_c[ch],
            partner_h_over_c=cal.viscous_coupling_h_over_c[partner],
            partner_wn=cal.caging_natural_rad_per_s[partner],
            partner_zeta=cal.caging_zeta[partner],
            partner_proportional=partner in PROPORTIONAL_ONLY,
        )

        # 5. restore: the loop takes over from the bias
        rig.set_caging_inhibit(ch, False)
        n_steps = max(1, int(p.restore_s))
        for i in range(n_steps):
            rig.set_torquer_bias_V(ch, bias * (1 - (i + 1) / n_steps))
            ctx.acquire(p.restore_s / n_steps, keep=False)
        wait_settled(ctx, [tcol], tol_V=1e-3, min_s=30.0, window_s=30.0)
        # a step result is one event of the run file (at most 1 KiB): ``ChannelRun.digits``
        return ChannelRun(
            ch=ch,
            kto=kto,
            kto_from=source,
            kto_rel_ci95=self.kto_rel_half_width(ch, source, kto),
            gain=round(gain, 6),
            vt_null=round(vt_null, 6),
            vg0=round(vg0, 5),
            null_slope=float(null_slope),
            caged_for_s=round(caged_for, 1),
            t=(round(t_open, 2), round(t_null, 2), round(t_end, 2)),
            dVg=p.delta_pickoff_V,
            ramps=tuple(ramps),
            fit={k: float(v) for k, v in fit.items()},
            slope_fit={k: float(v) for k, v in slope_fit.items()},
            partner_factor=tuple(round(f, 7) for f in factors),
        )

    def _ramp(
        self,
        ctx: Context,
        rec: _Record,
        ch: str,
        bias: float,
        step: float,
        target: float,
        direction: int,
        expected_s: float,
    ) -> None:
        """Bias step until the smoothed pickoff passes ``target`` in ``direction``."""
        ctx.rig.set_torquer_bias_V(ch, bias + step)
        t_end = ctx.time_s + 4 * expected_s + 10.0
        while (rec.last_vg() - target) * direction < 0:
            if ctx.time_s > t_end:
                raise ProcedureError(
                    f"stopwatch {ch}: the pickoff did not reach {target:+.3f} V within "
                    f"{4 * expected_s + 10:.0f} s of the bias step (now {rec.last_vg():+.3f} V); "
                    f"is the channel's caging inhibited and the gyro at speed?"
                )
            rec.take(ctx, 0.5)

    # ------------------------------------------------------------------ analysis
    @staticmethod
    def _file_of(ctx: Context, ch: str) -> Path:
        """The file channel ``ch``'s step recorded into (an earlier one for a resumed step): its
        result's times are on that file's time base."""
        span = ctx.spans.get(f"channel {ch}")
        return span.file if span is not None else Path(ctx.path)

    def analyze(self, ctx: Context) -> Analysis:
        p = self.params
        results = {ch: ctx.result(f"channel {ch}", ChannelRun) for ch in p.channels}
        cal = ctx.rig.calibration
        per = {ch: channel_result(r, cal.viscous_coupling_h_over_c) for ch, r in results.items()}
        ms: list[Measurement] = []
        kg_est = {ch: r.kg_estimate(results[ch].kto_rel_ci95) for ch, r in per.items()}
        tau_est = {ch: r.tau_estimate() for ch, r in per.items()}
        for ch, r in per.items():
            nom = cal.pickoff_scale_mV_per_urad[ch]
            kg, tau = kg_est[ch], tau_est[ch]
            ms.append(
                Measurement(
                    f"K_g {ch} (stopwatch, mean of {len(r.repetitions)} repetitions)",
                    r.kg,
                    "mV/urad",
                    nom * (1 - p.kg_tolerance),
                    nom * (1 + p.kg_tolerance),
                    r.kg_se,
                    note=f"95 % [{kg.lo:.4f}, {kg.hi:.4f}]"
                    + ("" if kg.resolved else f"; not resolved: {kg.why}"),
                )
            )
            ms.append(
                Measurement(f"K_g {ch} repetition spread (std/mean)", r.spread, "", hi=p.max_spread)
            )
            ms.append(
                Measurement(
                    f"K_g {ch} least-squares ramp slope", r.kg_ls, "mV/urad", stderr=r.kg_ls_se
                )
            )
            ms.append(
                Measurement(
                    f"h/k {ch} (fitted)",
                    tau.value if tau.resolved else None,
                    "s",
                    note=f"95 % [{tau.lo:.0f}, {tau.hi:.0f}]"
                    + ("" if tau.resolved else f"; {tau.why}"),
                )
            )
            ms.append(Measurement(f"restraint correction {ch}", r.correction * 100, "%"))
            ms.append(
                Measurement(
                    f"float partner transient correction {ch}",
                    r.partner_correction * 100,
                    "%",
                    note=f"bound left +-{100 * r.partner_bound:.3f} % (II C.4.d)",
                )
            )
            ms.append(
                Measurement(
                    f"residual null rate {ch}",
                    r.null_rate_urad_per_s,
                    "urad/s",
                    -p.max_null_rate_urad_per_s,
                    p.max_null_rate_urad_per_s,
                )
            )
        values: dict = {}
        add_figure(values, "K_g_mV_per_urad", kg_est)
        add_figure(values, "h_over_k_s", tau_est, digits=4)
        figs = [
            Figure(
                f"ramps-{ch.lower()}",
                f"Channel {ch}: pickoff and torquer output during the stopwatch ramps",
                partial(plot_channel, run=self._file_of(ctx, ch), ch=ch, r=results[ch]),
            )
            for ch in p.channels
        ]
        return Analysis(values, ms, figs, markdown=markdown(per, kg_est, tau_est))


# ---------------------------------------------------------------------------- data kept by a channel step
class _Record:
    """The channel's pickoff and torquer samples and its float partner's torquer, with their
    file times, kept in memory."""

    def __init__(self, gcol: int, tcol: int, partner_col: int) -> None:
        self.cols = [gcol, tcol, partner_col]
        self.t: list[np.ndarray] = []
        self.x: list[np.ndarray] = []
        self.n = 0

    def take(self, ctx: Context, seconds: float) -> np.ndarray:
        t0 = ctx.time_s
        data = ctx.acquire(seconds)[:, self.cols]
        self.t.append(t0 + np.arange(len(data)) / ctx.acq.rate_hz)
        self.x.append(data)
        self.n += len(data)
        return data

    def hold(self, ctx: Context, ch: str, bias: float, seconds: float) -> None:
        ctx.rig.set_torquer_bias_V(ch, bias)
        self.take(ctx, seconds)

    def last_vg(self) -> float:
        """Mean pickoff over the last chunk taken (a 0.5 s average while ramping)."""
        return float(np.nanmean(self.x[-1][:, 0]))

    def arrays(self, start: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        t, x = np.concatenate(self.t)[start:], np.concatenate(self.x)[start:]
        return t, x[:, 0], x[:, 1]

    def partner(self, start: int = 0) -> np.ndarray:
        """The float partner's pickoff over the same samples."""
        return np.concatenate(self.x)[start:, 2]

    def index_at(self, time_s: float) -> int:
        return int(np.searchsorted(np.concatenate(self.t), time_s))


PROCEDURE = Stopwatch
