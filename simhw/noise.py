"""Noise sources of the simulated rig, generated block by block and deterministic per seed.

Every source owns its own random stream (spawned from one ``SeedSequence``) and consumes it
strictly sequentially, so the samples do not depend on how a run is cut into blocks.

Flicker (1/f) noise follows the thesis's reference [T1] (Ch. V B.5): a sum of first-order
lags driven by independent white noises, with time constants spread evenly in log frequency.
With lags at corner frequencies f_i spaced by d = ln(f_{i+1}/f_i) and white intensities
q_i = 4 pi d A f_i (two-sided), the sum has one-sided PSD A/f between the extreme corners
(integrate q(fc)/(4 pi^2 (fc^2 + f^2)) over ln fc). Slow lags run at a decimated rate and are
held, so a bank spanning 1e-5..50 Hz costs little per sample.
"""

from __future__ import annotations

import math

import numba
import numpy as np
import scipy.signal


class WhiteNoise:
    """Band-limited white noise held over each step: one-sided PSD ``psd`` up to Nyquist."""

    def __init__(self, rng: np.random.Generator, psd: float, dt: float) -> None:
        self.rng = rng
        self.sigma = math.sqrt(psd / (2.0 * dt)) if psd > 0 else 0.0

    def take(self, n: int) -> np.ndarray:
        if self.sigma == 0.0:
            return np.zeros(n)
        return self.sigma * self.rng.standard_normal(n)


@numba.njit(cache=True, nogil=True)
def _gm_bank(state, a, b, xi, out_sum):
    n, m = xi.shape
    for k in range(n):
        acc = 0.0
        for j in range(m):
            state[j] = a[j] * state[j] + b[j] * xi[k, j]
            acc += state[j]
        out_sum[k] = acc


class FlickerNoise:
    """One-sided PSD ``level / f`` between ``f_lo`` and ``f_hi`` (units^2/Hz at 1 Hz = level)."""

    PER_DECADE = 2.5

    def __init__(self, rng: np.random.Generator, level: float, f_lo: float, f_hi: float, dt: float) -> None:
        self.level, self.dt = level, dt
        self.groups: list[dict] = []
        self.ahead = np.zeros(0)
        if level <= 0:
            return
        f_hi = min(f_hi, 0.2 / dt)
        n = max(2, int(math.ceil(math.log10(f_hi / f_lo) * self.PER_DECADE)) + 1)
        fc = np.geomspace(f_lo, f_hi, n)
        d = math.log(fc[1] / fc[0])
        q = 4 * math.pi * d * level * fc
        # Group lags by decimation (power of two) so each runs at >= 40 x its corner.
        decim = np.maximum(1, 2 ** np.floor(np.log2(1.0 / (40.0 * fc * dt)))).astype(np.int64)
        for dec in sorted(set(decim.tolist())):
            sel = decim == dec
            h = dt * dec
            w = 2 * math.pi * fc[sel]
            a = np.exp(-w * h)
            var = q[sel] / (2 * w)  # stationary variance of each lag
            b = np.sqrt(var * (1 - a * a))
            x0 = np.sqrt(var) * rng.standard_normal(sel.sum())  # start in steady state
            self.groups.append({"dec": int(dec), "a": a, "b": b, "state": x0,
                                "rng": np.random.Generator(np.random.PCG64(rng.integers(2**63))),
                                "held": np.zeros(0), "pos": 0})

    #: Samples are made ahead in chunks of this many steps, always on the same grid from the
    #: run's start, so the output does not depend on how callers cut the run into blocks.
    CHUNK = 4096

    def take(self, n: int) -> np.ndarray:
        if not self.groups:
            return np.zeros(n)
        while len(self.ahead) < n:
            self.ahead = np.concatenate([self.ahead, self._generate(self.CHUNK)])
        out, self.ahead = self.ahead[:n], self.ahead[n:]
        return out

    def _generate(self, n: int) -> np.ndarray:
        out = np.zeros(n)
        for g in self.groups:
            # ``held`` are slow samples not yet fully used; ``pos`` fine steps of held[0] used.
            dec, pos = g["dec"], g["pos"]
            need = -(-(pos + n) // dec) - len(g["held"])
            if need > 0:
                xi = g["rng"].standard_normal((need, len(g["a"])))
                s = np.empty(need)
                _gm_bank(g["state"], g["a"], g["b"], xi, s)
                g["held"] = np.concatenate([g["held"], s])
            if dec == 1:
                out += g["held"][:n]
            else:
                out += g["held"][(pos + np.arange(n)) // dec]
            used, g["pos"] = divmod(pos + n, dec)
            g["held"] = g["held"][used:]
        return out


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

    def __init__(self, rng: np.random.Generator | None, lines: list[tuple[float, float]], dt: float,
                 phase: float | None = None) -> None:
        self.freq_dt = np.array([f * dt for f, _ in lines], float)
        self.amp = np.array([a for _, a in lines], float)
        self.phase = (np.full(len(lines), phase) if phase is not None
                      else rng.uniform(0, 2 * math.pi, len(lines)))
        self.k = 0

    def take(self, n: int) -> np.ndarray:
        out = np.zeros(n)
        _lines(self.k, self.freq_dt, self.amp, self.phase, out)
        self.k += n
        return out


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
        y, _ = scipy.signal.lfilter([1 - self.a], [1, -self.a], self.white.take(n), zi=[self.a * self.y])
        self.y = float(y[-1])
        return y


class TelegraphJumps:
    """Random offset steps of +-amplitude at Poisson times (the thesis's locked-oscillator
    offsets: square-wave-like jumps of tens of urad, 40-400 s apart, Ch. II B.10)."""

    def __init__(self, rng: np.random.Generator, amplitude: float, mean_interval_s: float, dt: float) -> None:
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
