"""Noise sources of the simulated rig, generated block by block and deterministic per seed.

Every source owns its own random stream (spawned from one ``SeedSequence``) and consumes it
strictly sequentially, so the samples do not depend on how a run is cut into blocks.

Flicker (1/f) noise follows the thesis's reference [T1] (Ch. V B.5): a sum of first-order
lags driven by independent white noises, with time constants spread evenly in log frequency.
With lags at corner frequencies f_i spaced by d = ln(f_{i+1}/f_i) and white intensities
q_i = 4 pi d A f_i (two-sided), the sum has one-sided PSD A/f well inside the extreme corners
(integrate q(fc)/(4 pi^2 (fc^2 + f^2)) over ln fc: (2/pi) (A/f) [atan(f_top/f) - atan(f_bot/f)],
so only 64 % of A/f at either corner, 77 % at 0.6 f_top; issue 38). The bank therefore reaches
three times beyond the band it claims on either side and its weights are fitted so that its
exact spectrum is A/f across the band (``_one_over_f_bank``: within 0.1 % up to a tenth of the
step rate, 1 % up to a quarter, see ``FlickerNoise``). Slow lags run at a decimated rate and
are held, so a bank spanning 1e-5..50 Hz costs little per sample. Any other spectrum (the autocollimator's knee of
any form and slope, docs/simhw.md section 4) takes non-negative lag weights fitted to it, and
its sharp corner a low-pass on some of the lags (``_fitted_bank``).
"""

from __future__ import annotations

import functools
import math

import numba
import numpy as np
import scipy.optimize
import scipy.signal


def held_psd(s_norm: np.ndarray, dt: float) -> np.ndarray:
    """One-sided PSD (units^2/Hz) of a sequence held over steps ``dt`` from its per-sample
    two-sided spectrum ``s_norm`` = sum_k R[k] e^(-j w k): the plant's exact ZOH model sees the
    held sequence, so its output PSD is |H(e^(j w))|^2 times this. White of variance s^2 gives
    2 s^2 dt, the ``psd`` it was made from."""
    return 2.0 * dt * np.asarray(s_norm)


def _ar1_norm(a: np.ndarray | float, var_in: np.ndarray | float, w: np.ndarray) -> np.ndarray:
    """Per-sample spectrum of x[n] = a x[n-1] + e[n], var(e) = var_in: var_in / |1 - a e^(-jw)|^2."""
    return var_in / np.abs(1.0 - a * np.exp(-1j * w)) ** 2


class WhiteNoise:
    """Band-limited white noise held over each step: one-sided PSD ``psd`` up to Nyquist."""

    def __init__(self, rng: np.random.Generator, psd: float, dt: float) -> None:
        self.rng = rng
        self.sigma = math.sqrt(psd / (2.0 * dt)) if psd > 0 else 0.0

    def take(self, n: int) -> np.ndarray:
        if self.sigma == 0.0:
            return np.zeros(n)
        return self.sigma * self.rng.standard_normal(n)

    def spectrum_key(self) -> tuple:
        """Everything the spectrum depends on (model-gap caches spectra by it)."""
        return ("WhiteNoise", self.sigma)

    def spectrum(self, f: np.ndarray, dt: float) -> np.ndarray:
        """One-sided PSD of the held sequence, 2 dt S(w) (see :func:`held_psd`)."""
        return held_psd(np.full(np.shape(f), self.sigma**2), dt)


@numba.njit(cache=True, nogil=True)
def _gm_bank(state, a, b, xi, out_sum):
    n, m = xi.shape
    for k in range(n):
        acc = 0.0
        for j in range(m):
            state[j] = a[j] * state[j] + b[j] * xi[k, j]
            acc += state[j]
        out_sum[k] = acc


@numba.njit(cache=True, nogil=True)
def _add_held(out, held, pos, dec):
    """out[k] += held[(pos + k) // dec]: slow samples held ``dec`` fine steps each, the first
    already used for ``pos`` (the same additions, in the same order, as the indexed sum, with no
    index array: this was a third of the whole rig's simulation)."""
    n, k, j = out.shape[0], 0, 0
    run = dec - pos  # fine steps left of held[0]
    while k < n:  # run by run, no division per step (a slow group's adds 2-5x faster)
        v, end = held[j], min(n, k + run)
        for i in range(k, end):
            out[i] += v
        k, j, run = end, j + 1, dec


def knee_excess(f: np.ndarray | float, corner_hz: float, knee: float, slope: float) -> np.ndarray:
    """K(f) - 1 of the autocollimator's 1/f knee (``simhw.simulator.ac_knee``): with
    r = (fc/f)^slope, K = knee (1 + r) + (1 - knee) max(1, r), so K - 1 = knee r + (1 - knee)
    max(0, r - 1); zero for a corner of 0."""
    f = np.asarray(f, float)
    if corner_hz <= 0:
        return np.zeros_like(f)
    r = (corner_hz / f) ** slope
    return knee * r + (1.0 - knee) * np.maximum(0.0, r - 1.0)


def _box2(dec: int, w: np.ndarray) -> np.ndarray:
    """|P(w)|^2 of the ``dec``-step box (zero-order-hold upsampling by ``dec``)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(
            np.abs(np.sin(w / 2)) < 1e-300,
            float(dec * dec),
            (np.sin(dec * w / 2) / np.sin(w / 2)) ** 2,
        )


def _decimation(fc: np.ndarray, dt: float, margin: float | None = 40.0) -> np.ndarray:
    """Each lag's decimation (a power of two): it runs at >= ``margin`` x its corner (None:
    every lag at every step)."""
    if margin is None:
        return np.ones(len(fc), np.int64)
    return np.maximum(1, 2 ** np.floor(np.log2(1.0 / (margin * fc * dt)))).astype(np.int64)


def _fit_margin(slope: float) -> float | None:
    """How many times its corner each lag of a fitted bank runs at (None: every step). A lag
    held over ``dec`` steps has nulls in its spectrum from 1/(dec dt) = margin x its corner on.
    At a frequency f the lags near f carry a PSD ~ f^-slope and a lag of corner c far below
    carries (c/f)^(2 - slope) of that; the nulls cost under 0.1 % where (1/margin)^(2 - slope)
    < 1e-3. A 1/f bank needs 1000 (its 40 loses 2.5 %, in its own ripple below a per cent); a
    steep one leans on its slow lags' tails, and from slope 1.75 on runs every lag every step."""
    return 1000.0 ** (1.0 / (2.0 - slope)) if slope < 1.75 else None


def _lag_psd(
    fc: np.ndarray, q: np.ndarray, dt: float, f: np.ndarray, margin: float | None
) -> np.ndarray:
    """One-sided PSD (len(f), len(fc)) of each lag of corner ``fc`` and white intensity ``q`` as
    the bank makes it (an AR(1) at its decimated step, held): as :meth:`FlickerNoise.spectrum`."""
    w = 2 * np.pi * np.asarray(f, float) * dt
    dec = _decimation(fc, dt, margin)
    wc = 2 * np.pi * fc
    a = np.exp(-wc * dt * dec)
    b2 = q / (2 * wc) * (1 - a * a)
    out = np.empty((len(w), len(fc)))
    for d in sorted(set(dec.tolist())):
        sel = dec == d
        sx = _ar1_norm(a[sel][None, :], b2[sel][None, :], d * w[:, None])
        if d > 1:
            sx = sx * (_box2(d, w) / d)[:, None]
        out[:, sel] = held_psd(sx, dt)
    return out


def _minimax_nonneg(M: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Non-negative x minimizing max |M x - t| (a linear program: minimize e subject to
    -e <= M x - t <= e, x >= 0; HiGHS). Falls back to the least-squares ``scipy.optimize.nnls``
    should the solver fail."""
    m, n = M.shape
    c = np.zeros(n + 1)
    c[-1] = 1.0
    ones = np.ones((m, 1))
    A = np.vstack([np.hstack([M, -ones]), np.hstack([-M, -ones])])
    res = scipy.optimize.linprog(
        c, A_ub=A, b_ub=np.concatenate([t, -t]), bounds=[(0, None)] * (n + 1), method="highs"
    )
    if res.status == 0:
        return np.maximum(res.x[:n], 0.0)
    return scipy.optimize.nnls(M, t, maxiter=50 * n)[0]


@functools.lru_cache(maxsize=64)
def _fitted_bank(
    f_lo: float, f_top: float, dt: float, corner_hz: float, knee: float, slope: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
    """Lags for the one-sided PSD K(f) - 1 (white level 1, ``knee_excess``) from 10 f_lo to
    f_top: corners, intensities, whether each passes the knee's low-pass, and that low-pass (SOS).

    First-order lags have f^2 S(f) non-decreasing in f, so a sum of them cannot follow the sharp
    corner of max(1, r): the part max(0, r - 1) falls to zero at fc, and the best the lags alone
    do is 17 % of K (slope 1, knee 0). That part is therefore made by lags that pass a 6th-order
    Butterworth low-pass at 0.8 fc (``FlickerNoise.KNEE_LOWPASS``), which bends them down at the
    corner, and the power law knee r by plain lags, each part fitted on its own: the
    non-negative weights minimize the largest error relative to K (the whole spectrum, white
    included) on a log-frequency grid (``_minimax_nonneg``), with each lag's spectrum as the
    bank makes it (``_lag_psd``). Fitted together, the sharp part's error spread over the white
    band too (up to 1.5 % of K at 20-80 Hz for knee 0.2, where a white level is measured: it
    read 0.8 % high on such a unit); apart, the low-pass keeps it out. At the nominal unit's
    slopes (0.8-1.2) the bank is within 1 % of K - 1 for knee 1, 1.6 % for knee 0.5 and 4.5 % for
    knee 0 (relative to K, from 10 f_lo to f_top), and within 0.5 % above 2.5 fc, where it is
    the power law's own error (the most near f_top at slope 0.8; ``tests/simhw/test_noise.py``)."""
    per_decade = FlickerNoise.FIT_PER_DECADE
    decades = math.log10(f_top / f_lo)
    n = max(2, int(math.ceil(decades * per_decade)) + 1)
    fc = np.geomspace(f_lo, f_top, n)
    d = math.log(fc[1] / fc[0])
    q1 = 4 * math.pi * d * fc  # 1/f at unit level (the closed form): weights near 1
    f = np.geomspace(
        min(10.0 * f_lo, math.sqrt(f_lo * f_top)), f_top, max(50, int(40 * (decades - 1)))
    )
    k = 1.0 + knee_excess(f, corner_hz, knee, slope)
    plain = _lag_psd(fc, q1, dt, f, _fit_margin(slope))
    order, frac = FlickerNoise.KNEE_LOWPASS
    sos = None
    parts = [(plain, k - 1.0, False)]
    if knee < 1.0 and frac * corner_hz < 0.4 / dt and frac * corner_hz > 10.0 * f_lo:
        sos = scipy.signal.butter(order, frac * corner_hz, fs=1.0 / dt, output="sos")
        lp2 = np.abs(scipy.signal.sosfreqz(sos, worN=f, fs=1.0 / dt)[1]) ** 2
        r = (corner_hz / f) ** slope
        parts = [
            (plain, knee * r, False),
            (plain * lp2[:, None], (1.0 - knee) * np.maximum(0.0, r - 1.0), True),
        ]
    corners, intensities, through = [], [], []
    for cols, target, filtered in parts:
        if not np.any(target > 0):
            continue
        M = cols / k[:, None]
        scale = np.max(M, axis=0)  # columns of unit peak: as well conditioned for any slope
        g = _minimax_nonneg(M / scale, target / k)
        keep = g > 1e-9  # a lag below a billionth of the largest error is no lag
        corners.append(fc[keep])
        intensities.append((q1 * g / scale)[keep])
        through.append(np.full(int(keep.sum()), filtered))
    return np.concatenate(corners), np.concatenate(intensities), np.concatenate(through), sos


#: how far beyond its band (a factor, each side) a 1/f bank's lags reach (``_one_over_f_bank``)
ONE_OVER_F_REACH = 3.0
#: the highest frequency a 1/f bank's fit holds, as a fraction of the step rate 1/dt: towards
#: Nyquist the held steps' own spectrum bends it (2 % at 0.4/dt)
ONE_OVER_F_TOP = 0.25


@functools.lru_cache(maxsize=64)
def _one_over_f_bank(f_lo: float, f_hi: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Corners and white intensities of lags whose summed one-sided PSD is 1/f (level 1) from
    ``f_lo`` to ``min(f_hi, ONE_OVER_F_TOP / dt)``.

    The closed form (module docstring) falls to 2/pi of 1/f at its extreme corners, so the lags
    (``FlickerNoise.PER_DECADE`` a decade) run from f_lo / ``ONE_OVER_F_REACH`` to ``ONE_OVER_F_REACH``
    f_hi (at most 0.2 / dt), start at the closed form's intensities q_i = 4 pi d f_i, and take
    non-negative weights minimizing the largest relative error from 1/f on a log grid of the band
    (``_minimax_nonneg``), each lag's spectrum as the bank makes it (``_lag_psd``, decimated at
    ``_fit_margin(1)`` = 1000 x its corner). The error is under 0.1 % for a band up to 0.1 / dt
    (the rig's banks: 1e-4..50 Hz and 1e-4..200 Hz at 2 kHz, 1e-5..1 Hz) and under 1 % up to
    0.25 / dt (``tests/simhw/test_noise.py``)."""
    f_band = min(f_hi, ONE_OVER_F_TOP / dt)
    top = min(ONE_OVER_F_REACH * f_band, 0.2 / dt)
    bot = f_lo / ONE_OVER_F_REACH
    n = max(2, int(math.ceil(math.log10(top / bot) * FlickerNoise.PER_DECADE)) + 1)
    fc = np.geomspace(bot, top, n)
    q1 = 4 * math.pi * math.log(fc[1] / fc[0]) * fc
    f = np.geomspace(f_lo, f_band, max(60, int(30 * math.log10(f_band / f_lo))))
    g = _minimax_nonneg(_lag_psd(fc, q1, dt, f, _fit_margin(1.0)) * f[:, None], np.ones(len(f)))
    keep = g > 1e-9
    return fc[keep], (q1 * g)[keep]


class FlickerNoise:
    """One-sided PSD ``level / f`` between ``f_lo`` and ``f_hi`` (units^2/Hz at 1 Hz = level),
    within 0.1 % of it from ``f_lo`` to ``min(f_hi, 0.1 / dt)`` and 1 % to ``min(f_hi, 0.25 / dt)``
    (the bank's exact spectrum,
    ``spectrum``; a generated record's Welch PSD matches it to its own scatter,
    ``tests/simhw/test_noise.py``). Beyond the band it bends away: it keeps near 1/f for about
    a factor of three, then falls as 1/f^3 (first-order lags above their corners) above, and
    flattens below (issue 38: the bank of 2.5 lags a decade ending at f_hi gave 64-77 % of
    ``level / f`` in the band's top half).

    With a knee (``corner_hz``, ``knee``, ``slope``; docs/simhw.md section 4) the PSD is
    ``level / corner_hz * (K(f) - 1)``, K the autocollimator's knee (``knee_excess``): at
    knee = slope = 1 that is ``level / f`` again (``_one_over_f_bank``); any other knee or slope
    is fitted to the knee (``_fitted_bank``).
    """

    PER_DECADE = 2.5
    #: a fitted bank's candidate lags per decade
    FIT_PER_DECADE = 5.0
    #: (order, corner / fc) of the Butterworth low-pass that bends the sharp knee's lags
    KNEE_LOWPASS = (6, 0.8)
    #: the knee's low-pass starts this many of its time constants 1 / (2 pi f) before t = 0
    PREROLL = 60.0

    def __init__(
        self,
        rng: np.random.Generator,
        level: float,
        f_lo: float,
        f_hi: float,
        dt: float,
        *,
        corner_hz: float = 1.0,
        knee: float = 1.0,
        slope: float = 1.0,
    ) -> None:
        self.level, self.f_lo, self.f_hi, self.dt = level, f_lo, f_hi, dt
        self.corner_hz, self.knee, self.slope = float(corner_hz), float(knee), float(slope)
        self.rng = rng
        self._groups: list[dict] | None = None
        self._zi: np.ndarray | None = None
        self._y0 = 0.0
        self.ahead = np.zeros(0)

    @property
    def fitted(self) -> bool:
        """The bank is fitted to a knee (not the closed form of ``level / f``)."""
        return not (self.knee == 1.0 and self.slope == 1.0)

    def _sos(self) -> np.ndarray | None:
        """The knee's low-pass (second-order sections), or None."""
        if self.level <= 0 or self.corner_hz <= 0 or not self.fitted:
            return None
        return _fitted_bank(
            self.f_lo, min(self.f_hi, 0.2 / self.dt), self.dt, self.corner_hz, self.knee, self.slope
        )[3]

    def _bank(self) -> list[tuple[int, np.ndarray, np.ndarray, np.ndarray, bool]]:
        """The lags, deterministic: (decimation, a, b, stationary variance, through the knee's
        low-pass) per group."""
        if self.level <= 0:
            return []
        dt = self.dt
        f_hi = min(self.f_hi, 0.2 / dt)
        if self.fitted:
            if self.corner_hz <= 0:
                return []
            fc, q, through, _ = _fitted_bank(
                self.f_lo, f_hi, dt, self.corner_hz, self.knee, self.slope
            )
            q = q * (self.level / self.corner_hz)
        else:
            fc, q = _one_over_f_bank(self.f_lo, self.f_hi, dt)
            q = q * self.level
            through = np.zeros(len(fc), bool)
        # Group lags by decimation (power of two) so each runs fast enough for its fit
        # (``_fit_margin``: 1000 x its corner for 1/f).
        decim = _decimation(fc, dt, _fit_margin(self.slope if self.fitted else 1.0))
        out = []
        for lp in (False, True):
            for dec in sorted(set(decim[through == lp].tolist())):
                sel = (decim == dec) & (through == lp)
                w = 2 * math.pi * fc[sel]
                a = np.exp(-w * dt * dec)
                var = q[sel] / (2 * w)  # stationary variance of each lag
                out.append((int(dec), a, np.sqrt(var * (1 - a * a)), var, lp))
        return out

    @property
    def groups(self) -> list[dict]:
        """The running lags, made on first use (the random draws happen then, in a fixed order)."""
        if self._groups is None:
            self._groups = []
            for dec, a, b, var, lp in self._bank():
                x0 = np.sqrt(var) * self.rng.standard_normal(len(a))  # start in steady state
                self._groups.append(
                    {
                        "dec": dec,
                        "a": a,
                        "b": b,
                        "state": x0,
                        "lowpass": lp,
                        "rng": np.random.Generator(np.random.PCG64(self.rng.integers(2**63))),
                        "held": np.zeros(0),
                        "pos": 0,
                    }
                )
            sos = self._sos()
            through = [g for g in self._groups if g["lowpass"]]
            if sos is not None and through:
                # The low-pass starts settled on the lags' value and runs ahead of t = 0 until
                # its start has died away: the sum is stationary from the first sample.
                x0 = float(sum(g["state"].sum() for g in through))
                zi = scipy.signal.sosfilt_zi(sos) * x0
                f_lp = self.KNEE_LOWPASS[1] * self.corner_hz
                n_pre = int(math.ceil(self.PREROLL / (2 * math.pi * f_lp * self.dt)))
                y, self._zi = scipy.signal.sosfilt(sos, self._sum(through, n_pre), zi=zi)
                self._y0 = float(y[-1])
        return self._groups

    def spectrum_key(self) -> tuple:
        key = ("FlickerNoise", self.level, self.f_lo, self.f_hi, self.dt)
        return key + ((self.corner_hz, self.knee, self.slope) if self.fitted else ())

    def initial(self) -> float:
        """The bank's value at the start (its lags' steady-state draws)."""
        groups = self.groups
        return float(sum(g["state"].sum() for g in groups if not g["lowpass"])) + self._y0

    def spectrum(self, f: np.ndarray, dt: float) -> np.ndarray:
        """One-sided PSD of the bank as the plant sees it: each group is a set of AR(1) lags at
        step ``dec dt``, held for ``dec`` steps; a held sequence has per-sample spectrum
        |P(w)|^2 S_x(dec w) / dec with P the ``dec``-step box (zero-order-hold upsampling). The
        knee's lags then pass its low-pass, |L(e^(jw))|^2."""
        f = np.asarray(f, float)
        w = 2 * np.pi * f * dt
        total = np.zeros_like(f)
        bent = np.zeros_like(f)
        for dec, a_all, b_all, _, lp in self._bank():
            sx = sum(_ar1_norm(a, b * b, dec * w) for a, b in zip(a_all, b_all))
            if dec > 1:
                sx = sx * _box2(dec, w) / dec
            if lp:
                bent += sx
            else:
                total += sx
        sos = self._sos()
        if sos is not None and np.any(bent):
            total += bent * np.abs(scipy.signal.sosfreqz(sos, worN=f, fs=1.0 / dt)[1]) ** 2
        return held_psd(total, dt)

    #: Samples are made ahead in chunks of this many steps, always on the same grid from the
    #: run's start, so the output does not depend on how callers cut the run into blocks.
    CHUNK = 16384

    def take(self, n: int) -> np.ndarray:
        if not self.groups:
            return np.zeros(n)
        chunks, have = [self.ahead], len(self.ahead)
        while have < n:
            chunks.append(self._generate(self.CHUNK))
            have += self.CHUNK
        made = np.concatenate(chunks) if len(chunks) > 1 else self.ahead
        out, self.ahead = made[:n], made[n:]
        return out

    def _generate(self, n: int) -> np.ndarray:
        out = self._sum([g for g in self.groups if not g["lowpass"]], n)
        through = [g for g in self.groups if g["lowpass"]]
        if through:
            y, self._zi = scipy.signal.sosfilt(self._sos(), self._sum(through, n), zi=self._zi)
            out += y
        return out

    @staticmethod
    def _sum(groups: list[dict], n: int) -> np.ndarray:
        """The next ``n`` fine steps of the sum of ``groups``."""
        out = np.zeros(n)
        for g in groups:
            # ``held`` are slow samples not yet fully used; ``pos`` fine steps of held[0] used.
            dec, pos = g["dec"], g["pos"]
            need = -(-(pos + n) // dec) - len(g["held"])
            if need > 0:
                xi = g["rng"].standard_normal((need, len(g["a"])))
                s = np.empty(need)
                _gm_bank(g["state"], g["a"], g["b"], xi, s)
                g["held"] = np.concatenate([g["held"], s])
            _add_held(out, g["held"], pos, dec)
            used, g["pos"] = divmod(pos + n, dec)
            g["held"] = g["held"][used:]
        return out


class ExcessFlickerNoise(FlickerNoise):
    """1/f noise beyond a sensor's own (air turbulence in the optical path: the
    ``flicker_noise`` effect, Ch. V B.3). The same process as ``FlickerNoise``, kept a kind of
    its own so an analysis can tell the unit's own 1/f (unit-to-unit variation) from the excess
    (physics the nominal model lacks)."""


class RandomWalk:
    """Integrated white noise: increments of std ``k sqrt(dt)`` (rate random walk)."""

    def __init__(self, rng: np.random.Generator, k: float, dt: float) -> None:
        self.rng, self.step, self.value = rng, k * math.sqrt(dt), 0.0

    def take(self, n: int) -> np.ndarray:
        if self.step == 0.0 or n == 0:
            return np.zeros(n)
        # The carried value starts the sum, so any cut of the run gives the same samples.
        w = np.cumsum(np.concatenate([[self.value], self.step * self.rng.standard_normal(n)]))[1:]
        self.value = float(w[-1])
        return w

    def spectrum_key(self) -> tuple:
        return ("RandomWalk", self.step)

    def spectrum(self, f: np.ndarray, dt: float) -> np.ndarray:
        """step^2 / |1 - e^(-jw)|^2: the random walk's (improper) spectrum, infinite at f = 0."""
        w = 2 * np.pi * np.asarray(f, float) * dt
        with np.errstate(divide="ignore"):
            return held_psd(_ar1_norm(1.0, self.step**2, w), dt)


#: The line rotation restarts from the exact phase every this many steps, counted from the
#: run's start, so rounding never accumulates and no cut of the run changes a sample.
_LINE_RESEED = 4096


@numba.njit(cache=True, nogil=True)
def _lines(k0, freq_dt, amp, phase, out):
    """Sum of amp sin(2 pi f dt k + phase) for k = k0..k0+n-1, by complex rotation."""
    n = out.shape[0]
    for j in range(freq_dt.shape[0]):
        w = 2.0 * np.pi * freq_dt[j]
        cw, sw = np.cos(w), np.sin(w)
        # Resume as if rotating since the last restart point: exact whatever the block cuts.
        kb = (k0 // _LINE_RESEED) * _LINE_RESEED
        start = 2.0 * np.pi * ((kb * freq_dt[j]) % 1.0) + phase[j]
        c, s = np.cos(start), np.sin(start)
        for _ in range(k0 - kb):
            c, s = c * cw - s * sw, s * cw + c * sw
        for k in range(n):
            kk = k0 + k
            if kk % _LINE_RESEED == 0:
                start = 2.0 * np.pi * ((kk * freq_dt[j]) % 1.0) + phase[j]
                c, s = np.cos(start), np.sin(start)
            out[k] += amp[j] * s
            c, s = c * cw - s * sw, s * cw + c * sw


class Lines:
    """Sinusoids of fixed amplitude, phase-continuous across blocks; random phases from
    ``rng``, or all starting at ``phase`` (rad) when it is given."""

    def __init__(
        self,
        rng: np.random.Generator | None,
        lines: list[tuple[float, float]],
        dt: float,
        phase: float | None = None,
    ) -> None:
        self.freq_dt = np.array([f * dt for f, _ in lines], float)
        self.amp = np.array([a for _, a in lines], float)
        if phase is not None:
            self.phase = np.full(len(lines), phase)
        elif rng is not None:
            self.phase = rng.uniform(0, 2 * math.pi, len(lines))
        else:
            raise ValueError("random line phases need an rng; pass one, or a fixed phase")
        self.k = 0

    def take(self, n: int) -> np.ndarray:
        out = np.zeros(n)
        _lines(self.k, self.freq_dt, self.amp, self.phase, out)
        self.k += n
        return out

    def spectrum_key(self) -> tuple:
        return ("Lines",)

    def spectrum(self, f: np.ndarray, dt: float) -> np.ndarray:
        """Deterministic: no continuous spectrum (the sinusoids are given by :meth:`lines`)."""
        return np.zeros(np.shape(f))

    def lines(self, dt: float) -> list[tuple[float, float]]:
        """The sinusoids as (frequency Hz, amplitude)."""
        return [(fd / dt, a) for fd, a in zip(self.freq_dt, self.amp)]


class LagNoise:
    """White noise through w/(s+w), w = 2 pi corner (exact ZOH), scaled to ``rms``.

    The lag passes int_0^inf S/(1 + (f/fc)^2) df = S fc pi/2, so S = 2 rms^2/(pi fc).
    """

    def __init__(self, rng: np.random.Generator, rms: float, corner_hz: float, dt: float) -> None:
        self.white = WhiteNoise(rng, 2 * rms * rms / (math.pi * corner_hz), dt)
        self.a = math.exp(-2 * math.pi * corner_hz * dt)
        self.y = 0.0

    def take(self, n: int) -> np.ndarray:
        if self.white.sigma == 0.0:
            return np.zeros(n)
        y, _ = scipy.signal.lfilter(
            [1 - self.a], [1, -self.a], self.white.take(n), zi=[self.a * self.y]
        )
        self.y = float(y[-1])
        return y

    def spectrum_key(self) -> tuple:
        return ("LagNoise", self.a, self.white.sigma)

    def initial(self) -> float:
        return self.y

    def spectrum(self, f: np.ndarray, dt: float) -> np.ndarray:
        w = 2 * np.pi * np.asarray(f, float) * dt
        return held_psd(_ar1_norm(self.a, ((1 - self.a) * self.white.sigma) ** 2, w), dt)


class TelegraphJumps:
    """Random offset steps of +-amplitude at Poisson times (the thesis's locked-oscillator
    offsets: square-wave-like jumps of tens of urad, 40-400 s apart, Ch. II B.10)."""

    def __init__(
        self, rng: np.random.Generator, amplitude: float, mean_interval_s: float, dt: float
    ) -> None:
        self.rng, self.amp, self.p = rng, amplitude, dt / mean_interval_s
        self.level = amplitude * (1 if rng.random() < 0.5 else -1)

    def take(self, n: int) -> np.ndarray:
        if self.amp == 0.0 or n == 0:
            return np.zeros(n)
        flips = self.rng.random(n) < self.p
        sign = np.where(np.cumsum(flips) % 2 == 1, -1.0, 1.0)
        out = self.level * sign
        self.level = float(out[-1])
        return out

    def spectrum_key(self) -> tuple:
        return ("TelegraphJumps", self.amp, self.p)

    def initial(self) -> float:
        return self.level if self.amp else 0.0

    def spectrum(self, f: np.ndarray, dt: float) -> np.ndarray:
        """A random telegraph signal flipping with probability p per step has autocorrelation
        A^2 (1 - 2p)^|k|: an AR(1) spectrum with r = 1 - 2p and innovation variance A^2 (1 - r^2)."""
        w = 2 * np.pi * np.asarray(f, float) * dt
        r = 1.0 - 2.0 * self.p
        return held_psd(_ar1_norm(r, self.amp**2 * (1 - r * r), w), dt)
