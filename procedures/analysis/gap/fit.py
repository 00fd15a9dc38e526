"""Maximum-likelihood fits of catalogue effects to measured band spectra.

Each band estimate ``P_b`` of a channel is ``S_b chi^2_nu / nu`` under a model spectrum
``S_b``; its negative log-likelihood, up to terms free of the model, is the Whittle form
([Whittle 1953]; band-averaged, as in [BP] 9.4)

    -l = sum_b nu_b / 2 (ln S_b + P_b / S_b).

Channels are summed as independent; their correlation (the two autocollimator channels see
the same angle) makes the likelihood sharper than it is, which the ranking's margin absorbs.
The axis's autocollimator and pickoff noise levels are nuisance parameters, fitted for every
candidate (including ``none``) by profiling: the effect's own parameters are searched (prior
grid plus the effect's own guesses, then Nelder-Mead on the prior interval, log where the prior
is), and at every trial the two noise scales are re-fitted.

Candidates are ranked by the Bayesian information criterion's improvement over ``none``,
``2 (l_e - l_none) - k ln n`` ([Schwarz 1978]), ``k`` the effect's fitted parameters and ``n``
the number of band estimates.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from itertools import product
from typing import Any

import numpy as np
import scipy.optimize

from procedures.analysis.gap.model import PARTS, ModelSpectrum, SpectralModel, knee, knee_gradient
from simhw.config import SimConfig
from simhw.effects import Effect, Param

log = logging.getLogger(__name__)

#: The nominal unit (DESIGN.md section 8): what a unit may differ from the data sheet by, and
#: no more. Power scales of the autocollimator's white noise (amplitude x0.6 .. x1.6), of the
#: gyro pickoff's white noise (x0.5 .. x2) and of each pickoff line (x0.5 .. x2); the 1/f knee's
#: corner (1.5 .. 5 Hz about the data sheet's 3: x1/2 .. x5/3 of the configuration's), its form
#: (any between max(1, fc/f) and 1 + fc/f) and its slope (-0.8 .. -1.2: +-0.2 about the
#: configuration's). Beyond these is an effect.
AC_WHITE_RANGE = (0.6**2, 1.6**2)
PICKOFF_RANGE = (0.5**2, 2.0**2)
LINE_RANGE = (0.5**2, 2.0**2)
CORNER_RANGE = (0.5, 5.0 / 3.0)
SLOPE_SPAN = 0.2
#: the azimuth autocollimator's pure 1/f level (its data sheet gives only one NEA)
AZIMUTH_RANGE = (0.25, 4.0)


def whittle_nll(P: np.ndarray, S: np.ndarray, dof: np.ndarray) -> float:
    """sum nu/2 (ln S + P/S) over channels and bands (Whittle, band form)."""
    return float(np.sum(0.5 * dof * (np.log(S) + P / S)))


@dataclass
class NuisanceFit:
    scales: dict[str, float]
    nll: float
    S: np.ndarray


def fit_nuisance(
    P: np.ndarray,
    dof: np.ndarray,
    ms: ModelSpectrum,
    hold: frozenset[str] = frozenset(),
    start: dict[str, float] | None = None,
    pinned: dict[str, float] | None = None,
) -> NuisanceFit:
    """The nominal unit's noise that minimizes the Whittle likelihood (analytic gradient).

    Free within the nominal unit's envelope (DESIGN.md section 8): the power scale of the
    autocollimator's white ("ac"), its 1/f knee (corner ``ac_corner_hz``, form ``ac_knee``,
    slope ``ac_slope``; ``model.knee``), the pickoff's white ("pickoff") and each pickoff line
    ("line0", ...). A part in ``hold`` (one an effect in the model describes itself) is held at
    the configuration's: "ac_flicker" in ``hold`` holds the knee's corner (the ``flicker_noise``
    effect sets it; the form and slope stay the unit's). The knee's form makes the likelihood
    kinked, so the search starts from both forms and between them, or only from ``start`` (the
    scales of a fit nearby: an effect's trials barely move the unit's noise). ``pinned`` holds
    named knee parameters (``ac_knee``, ``ac_slope``) at given values (``Fitter.held_envelope``).
    """
    parts = {p: v for p, v in ms.parts.items() if p != "fixed" and np.any(v > 0)}
    fixed = ms.parts["fixed"]
    names: list[str] = []  # free parameters, in the vector's order
    bounds: list[tuple[float, float]] = []
    x0: list[float] = []

    def free(name: str, lo: float, hi: float, start: float) -> None:
        names.append(name)
        bounds.append((lo, hi))
        x0.append(min(max(start, lo), hi))

    shaped = "ac" in parts and ms.shape is not None and ms.f is not None
    for p in parts:
        if p in hold or p == "ac_excess":
            continue
        if p == "ac":
            free("ac", *_log_range(AC_WHITE_RANGE), 0.0)
        elif p == "pickoff":
            free(p, *_log_range(PICKOFF_RANGE), 0.0)
        elif p == "ac_flicker":
            free(p, *_log_range(AZIMUTH_RANGE), 0.0)
        elif p not in PARTS:
            free(p, *_log_range(LINE_RANGE), 0.0)
    if shaped:
        assert ms.shape is not None
        fc0, form0, slope0 = ms.shape
        if "ac_flicker" not in hold and fc0 > 0:
            free(
                "ac_corner_hz",
                math.log(fc0 * CORNER_RANGE[0]),
                math.log(fc0 * CORNER_RANGE[1]),
                math.log(fc0),
            )
        knee_params = (
            ("ac_knee", 0.0, 1.0, 0.5),
            ("ac_slope", slope0 - SLOPE_SPAN, slope0 + SLOPE_SPAN, slope0),
        )
        for key, lo, hi, x_start in knee_params:
            if pinned and key in pinned:
                lo = hi = x_start = pinned[key]
            free(key, lo, hi, x_start)
    f_band = ms.f if ms.f is not None else np.ones(fixed.shape[1])
    shape0 = ms.shape or (0.0, 1.0, 1.0)

    def unpack(x: np.ndarray) -> dict[str, float]:
        v = dict(zip(names, x.tolist()))
        sc = {p: 1.0 for p in parts}
        for p in parts:
            if p in v:
                sc[p] = math.exp(v[p])
        if "ac_excess" in parts:
            sc["ac_excess"] = sc.get("ac", 1.0)
        if shaped:
            sc["ac_corner_hz"] = math.exp(v["ac_corner_hz"]) if "ac_corner_hz" in v else shape0[0]
            sc["ac_knee"] = v.get("ac_knee", shape0[1])
            sc["ac_slope"] = v.get("ac_slope", shape0[2])
        return sc

    lo_b, hi_b = np.array([b[0] for b in bounds]), np.array([b[1] for b in bounds])
    half_dof = 0.5 * np.broadcast_to(dof, fixed.shape).ravel()

    def spectrum_and_jacobian(x: np.ndarray) -> tuple[np.ndarray, list[np.ndarray]]:
        """S and dS/dx_i of every free parameter."""
        sc = unpack(x)
        K = knee(f_band, sc["ac_corner_hz"], sc["ac_knee"], sc["ac_slope"]) if shaped else 1.0
        S = np.array(fixed, float)
        terms: dict[str, np.ndarray] = {}
        for p, part in parts.items():
            t = part * sc[p] * (K if p == "ac" else 1.0)
            terms[p] = t
            S = S + t
        jac: dict[str, np.ndarray] = {n: terms[n] for n in names if n in terms}
        if "ac" in jac:
            jac["ac"] = terms["ac"] + terms.get("ac_excess", 0.0)
        if shaped:
            d_fc, d_form, d_slope = knee_gradient(
                f_band, sc["ac_corner_hz"], sc["ac_knee"], sc["ac_slope"]
            )
            base = parts["ac"] * sc["ac"]
            for key, d in (("ac_corner_hz", d_fc), ("ac_knee", d_form), ("ac_slope", d_slope)):
                if key in names:
                    jac[key] = base * d
        return np.maximum(S, 1e-300), [jac[n] for n in names]

    def scoring(x: np.ndarray) -> tuple[np.ndarray, float]:
        """Bounded Fisher scoring (Levenberg-Marquardt damped): the Whittle likelihood's
        expected curvature sum nu/2 J_i J_j / S^2 is its exact Hessian at the optimum and
        positive definite everywhere, so a few steps converge (L-BFGS-B took ~30 evaluations
        and most of the analysis's time in its own bookkeeping)."""
        S, J = spectrum_and_jacobian(x)
        nll = whittle_nll(P, S, dof)
        lam = 1e-3
        for _ in range(60):
            Jm = np.array(J).reshape(len(J), -1)
            w = (0.5 * dof * (1.0 / S - P / S**2)).ravel()
            g = Jm @ w
            JS = Jm / S.ravel()
            H = (JS * half_dof) @ JS.T
            # parameters at a bound the gradient pushes against stay there
            stuck = ((x <= lo_b + 1e-12) & (g > 0)) | ((x >= hi_b - 1e-12) & (g < 0))
            act = ~stuck
            if not act.any():
                break
            improved = False
            while lam < 1e8:
                Ha = H[np.ix_(act, act)]
                step = np.zeros_like(x)
                try:
                    step[act] = -np.linalg.solve(Ha + lam * np.diag(np.diag(Ha) + 1e-12), g[act])
                except np.linalg.LinAlgError:
                    lam *= 10.0
                    continue
                xn = np.clip(x + step, lo_b, hi_b)
                Sn, Jn = spectrum_and_jacobian(xn)
                nll_n = whittle_nll(P, Sn, dof)
                if nll_n <= nll:
                    improved = True
                    lam = max(lam / 10.0, 1e-6)
                    done = nll - nll_n < 1e-9 * (1.0 + abs(nll)) or np.max(np.abs(xn - x)) < 1e-7
                    x, S, J, nll = xn, Sn, Jn, nll_n
                    break
                lam *= 10.0
            if not improved or done:
                break
        return x, nll

    x = np.array(x0, float)
    if names:
        starts = [x]
        if "ac_knee" in names:
            starts += [_with(x, names, "ac_knee", v) for v in (0.0, 1.0)]
        if start is not None:
            starts = [np.clip([_coordinate(n, start) for n in names], lo_b, hi_b)]
        x = min((scoring(s0) for s0 in starts), key=lambda r: r[1])[0]
    scales = unpack(x)
    S = ms.total(scales)
    return NuisanceFit(scales, whittle_nll(P, S, dof), S)


def _coordinate(name: str, scales: dict[str, float]) -> float:
    """A nuisance parameter's search coordinate from a fit's scales (log for scales, corner)."""
    if name in ("ac_knee", "ac_slope"):
        return scales.get(name, 0.5 if name == "ac_knee" else 1.0)
    return math.log(max(scales.get(name, 1.0), 1e-300))


def _log_range(r: tuple[float, float]) -> tuple[float, float]:
    return math.log(r[0]), math.log(r[1])


def _with(x: np.ndarray, names: list[str], key: str, value: float) -> np.ndarray:
    y = x.copy()
    y[names.index(key)] = value
    return y


@dataclass
class EffectFit:
    """The best fit of one candidate effect on top of the base model."""

    effect: str
    params: dict[str, float]  # every parameter of the effect (fitted or held)
    errors: dict[
        str, float
    ]  # 1-sigma of the fitted ones (``Fitter._errors``) and of held ones the data gave
    nll: float
    scales: dict[str, float]
    n_fitted: int
    cfg: SimConfig = field(repr=False)
    S: np.ndarray = field(repr=False)
    score: float = 0.0  # BIC improvement over the base model
    #: 95 % intervals of the parameters with an error: (lo, hi), in the parameter's units
    intervals: dict[str, tuple[float, float]] = field(default_factory=dict)

    @property
    def summary(self) -> dict[str, Any]:
        return {"effect": self.effect, "score": round(self.score, 2)}


def to_unit(p: Param, v: float) -> float:
    """A parameter's value in its search coordinate: 0..1 over its prior (log where the prior is)."""
    if p.log:
        return math.log(v / p.lo) / math.log(p.hi / p.lo)
    return (v - p.lo) / (p.hi - p.lo)


def _from_unit(p: Param, t: float) -> float:
    t = min(max(t, 0.0), 1.0)
    if p.log:
        return p.lo * (p.hi / p.lo) ** t
    return p.lo + t * (p.hi - p.lo)


#: The score contributions of this many adjacent bands form one cluster of the robust
#: ("sandwich") covariance: a model error is smooth across neighbouring 1/24-octave bands, so
#: their scores are not independent.
CLUSTER_BANDS = 4
#: added to the negative log-likelihood of a model whose closed loop is unstable
UNSTABLE_PENALTY = 1e12
Z95 = 1.959964


class Fitter:
    """Profile-likelihood fits of catalogue effects on one measured spectrum."""

    def __init__(
        self, model: SpectralModel, P: np.ndarray, dof: np.ndarray, axis: str, grid_points: int = 9
    ) -> None:
        self.model, self.P, self.dof, self.axis = model, P, np.broadcast_to(dof, P.shape), axis
        self.grid_points = grid_points
        self.evaluations = 0
        #: nuisance parts held because an effect already in the model describes them
        self.hold: frozenset[str] = frozenset()
        #: the last base model's noise: where an effect's trials start their noise fit
        self.near: dict[str, float] | None = None
        #: knee parameters of the unit held at given values (``held_envelope``)
        self.pinned: dict[str, float] | None = None

    def base(self, cfg: SimConfig) -> NuisanceFit:
        nf = fit_nuisance(self.P, self.dof, self.model(cfg), self.hold)
        self.near = nf.scales
        return nf

    def fit(
        self,
        effect: Effect,
        base_cfg: SimConfig,
        evidence: Any,
        *,
        refine: bool = True,
        errors: bool = True,
        start: dict[str, float] | None = None,
    ) -> EffectFit | None:
        """The maximum-likelihood fit of ``effect`` on ``base_cfg``; None if it does not apply.
        Without ``refine``, the best of the starting points (a screening); without ``errors``,
        no curvature (NaN uncertainties). ``start``: begin from these values instead of the
        prior grid and the guesses (and hold what it gives of the parameters the spectra cannot
        see). A guess that gives such a parameter (a line's frequency measured in the time
        series, a jump's size) is a candidate of its own: each is fitted and the best kept."""
        fitted = effect.fit_params
        defaults: dict[str, float] = {p.name: p.default for p in effect.params if p not in fitted}
        guesses = effect.guess(evidence) if effect.guess else []
        if effect.spread is not None and not guesses and start is None:
            # its held parameters come from the evidence (a line's frequency, the steps' size):
            # without evidence it is no candidate, not one at its defaults
            log.debug("%s: no evidence for its held parameters", effect.name)
            return None
        held_sets: list[dict[str, float]] = []
        for g in [start] if start is not None else guesses:
            h = defaults | {k: v for k, v in g.items() if k in defaults}
            if h not in held_sets:
                held_sets.append(h)
        best: EffectFit | None = None
        for held in held_sets or [defaults]:
            f = self._fit_held(
                effect, base_cfg, evidence, held, guesses, refine=refine, errors=errors, start=start
            )
            if f is not None and (best is None or f.nll < best.nll):
                best = f
        return best

    def _fit_held(
        self,
        effect: Effect,
        base_cfg: SimConfig,
        evidence: Any,
        held: dict[str, float],
        guesses: list[dict[str, float]],
        *,
        refine: bool,
        errors: bool,
        start: dict[str, float] | None,
    ) -> EffectFit | None:
        fitted = effect.fit_params
        try:
            effect.inject(base_cfg, self.axis, **{p.name: p.default for p in fitted}, **held)
        except ValueError as e:
            log.debug("%s does not apply: %s", effect.name, e)
            return None

        cache: dict[tuple, tuple[float, NuisanceFit, SimConfig]] = {}
        hold = self.hold | frozenset(effect.owns)

        def key_of(t: np.ndarray) -> tuple:
            return tuple(np.round(np.clip(t, 0, 1), 9))

        def evaluate(t: np.ndarray) -> float:
            key = key_of(t)
            if key not in cache:
                vals = {p.name: _from_unit(p, ti) for p, ti in zip(fitted, key)}
                cfg = effect.inject(base_cfg, self.axis, **vals, **held)
                ms = self.model(cfg)
                nf = fit_nuisance(self.P, self.dof, ms, hold, self.near, self.pinned)
                self.evaluations += 1
                # a loop that diverges could not have made the record: never a candidate
                cache[key] = (nf.nll if ms.stable else nf.nll + UNSTABLE_PENALTY, nf, cfg)
            return cache[key][0]

        def spectrum(t: np.ndarray) -> np.ndarray:
            evaluate(t)
            return cache[key_of(t)][1].S

        d = len(fitted)
        if d == 0:
            evaluate(np.zeros(0))
            best_t = np.zeros(0)
        else:
            n = self.grid_points if d == 1 else max(3, int(round(self.grid_points ** (1 / d) + 1)))
            axes = [np.linspace(0.5 / n, 1 - 0.5 / n, n)] * d
            starts = [np.array(s) for s in product(*axes)] if start is None else []
            for g in guesses if start is None else [start]:
                t = np.array([to_unit(p, g.get(p.name, p.default)) for p in fitted])
                starts.append(np.clip(t, 0.0, 1.0))
            scored = sorted(starts, key=evaluate)
            best_t, best_v = scored[0], evaluate(scored[0])
            # Refine the best start with a small simplex, as it already sits in its basin.
            for t0 in scored[:1] if refine else []:
                simplex = np.vstack([t0] + [t0 + 0.02 * np.eye(d)[i] for i in range(d)])
                res = scipy.optimize.minimize(
                    evaluate,
                    t0,
                    method="Nelder-Mead",
                    bounds=[(0.0, 1.0)] * d,
                    options={
                        "initial_simplex": np.clip(simplex, 0, 1),
                        "xatol": 2e-4,
                        "fatol": 0.02,
                        "maxfev": 40 * d,
                    },
                )
                if res.fun < best_v:
                    best_t, best_v = np.clip(res.x, 0, 1), res.fun
        nll, nf, cfg = cache[key_of(best_t)]
        params = {p.name: _from_unit(p, t) for p, t in zip(fitted, best_t)} | held
        if effect.derive is not None:
            params = effect.derive(params)
        errs = {p.name: float("nan") for p in fitted}
        intervals: dict[str, tuple[float, float]] = {}
        if errors:
            errs, intervals = self._errors(evaluate, spectrum, best_t, fitted)
            if effect.spread is not None:  # what the data say of the held ones
                for k, sd in effect.spread(evidence, params).items():
                    if math.isfinite(sd) and sd > 0:
                        errs[k] = sd
                        intervals[k] = (params[k] - Z95 * sd, params[k] + Z95 * sd)
        return EffectFit(
            effect.name, params, errs, nll, nf.scales, d, cfg, nf.S, intervals=intervals
        )

    def held_envelope(
        self, effect: Effect, base_cfg: SimConfig, evidence: Any, found: EffectFit
    ) -> EffectFit:
        """``found`` with its intervals widened by what the unit's knee leaves open.

        An effect that sets the unit's 1/f corner (``flicker_noise``, which owns "ac_flicker")
        reads its corner against the knee's slope, which the nominal unit may have anywhere in
        -0.8 .. -1.2: over the decade a record resolves, a steeper 1/f with a lower corner and a
        shallower one with a higher corner fit alike. That is a systematic, bounded, not
        averaged: the interval is the union of the statistical intervals refitted with the slope
        held at each end of its range."""
        if "ac_flicker" not in effect.owns or not found.intervals:
            return found
        lo = {k: v[0] for k, v in found.intervals.items()}
        hi = {k: v[1] for k, v in found.intervals.items()}
        slope0 = float(getattr(base_cfg.autocollimator.get(self.axis), "flicker_slope", 1.0))
        saved = self.pinned
        try:
            for slope in (slope0 - SLOPE_SPAN, slope0 + SLOPE_SPAN):
                self.pinned = {"ac_slope": slope}
                alt = self.fit(effect, base_cfg, evidence, start=found.params)
                for k, (a, b) in alt.intervals.items() if alt is not None else ():
                    if k in lo:
                        lo[k], hi[k] = min(lo[k], a), max(hi[k], b)
        finally:
            self.pinned = saved
        found.intervals = {k: (lo[k], hi[k]) for k in lo}
        return found

    def _errors(
        self, evaluate, spectrum, t: np.ndarray, fitted: tuple[Param, ...]
    ) -> tuple[dict[str, float], dict[str, tuple[float, float]]]:
        """1-sigma and 95 % intervals of the fitted parameters, from a robust covariance.

        The model-based covariance is the inverse curvature H^-1 of -l (central differences in
        the unit coordinates). It holds only if the model is right and the bands independent; a
        model that is a little wrong everywhere (another unit's noise shapes) and channels that
        see the same angle make it too small. The robust ("sandwich") covariance
        H^-1 J H^-1 [Huber 1967; White 1982] takes J from the scores themselves, summed over the
        channels of each band and over ``CLUSTER_BANDS`` neighbouring bands (cluster-robust:
        what is correlated enters together); the larger of the two variances is used. Intervals
        are +-1.96 sigma in the unit coordinate, so a log-scaled parameter's is asymmetric, and
        end at its prior's bounds."""
        d = len(fitted)
        if d == 0:
            return {}, {}
        h = 2e-3
        f0 = evaluate(t)
        Hm = np.zeros((d, d))
        for i in range(d):
            for j in range(i, d):
                ei, ej = np.eye(d)[i] * h, np.eye(d)[j] * h
                if i == j:
                    v = (evaluate(t + ei) - 2 * f0 + evaluate(t - ei)) / h**2
                else:
                    v = (
                        evaluate(t + ei + ej)
                        - evaluate(t + ei - ej)
                        - evaluate(t - ei + ej)
                        + evaluate(t - ei - ej)
                    ) / (4 * h * h)
                Hm[i, j] = Hm[j, i] = v
        nb = self.P.shape[1]
        G = np.zeros((nb, d))
        for i in range(d):
            tp, tm = np.clip(t + np.eye(d)[i] * h, 0, 1), np.clip(t - np.eye(d)[i] * h, 0, 1)
            Sp, Sm = spectrum(tp), spectrum(tm)
            lp = 0.5 * self.dof * (np.log(Sp) + self.P / Sp)
            lm = 0.5 * self.dof * (np.log(Sm) + self.P / Sm)
            G[:, i] = np.sum(lp - lm, axis=0) / max(tp[i] - tm[i], 1e-12)
        clusters = np.add.reduceat(G, np.arange(0, nb, CLUSTER_BANDS), axis=0)
        J = clusters.T @ clusters
        try:
            Hinv = np.linalg.inv(Hm)
            var = np.maximum(np.diag(Hinv), np.diag(Hinv @ J @ Hinv))
        except np.linalg.LinAlgError:
            var = np.full(d, np.nan)
        errs, intervals = {}, {}
        for i, p in enumerate(fitted):
            if not (np.isfinite(var[i]) and var[i] > 0):
                errs[p.name] = float("nan")
                continue
            v = _from_unit(p, t[i])
            sd_t = math.sqrt(var[i])
            # d value / d t: log scale -> v ln(hi/lo), linear -> hi - lo
            dv = v * math.log(p.hi / p.lo) if p.log else p.hi - p.lo
            errs[p.name] = float(abs(dv) * sd_t)
            intervals[p.name] = (_from_unit(p, t[i] - Z95 * sd_t), _from_unit(p, t[i] + Z95 * sd_t))
        return errs, intervals


def bic_score(fit: EffectFit, base_nll: float, n_obs: int) -> float:
    """BIC improvement over the base model: 2 (l_e - l_base) - k ln n."""
    return 2.0 * (base_nll - fit.nll) - fit.n_fitted * math.log(n_obs)
