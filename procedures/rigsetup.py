"""Getting the rig into a procedure's operating state, and waiting for it to settle, with
all the time passing through the recording (so it is in the file and an abort is honoured)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from drivers.errors import DeviceTimeout, PlatformClamped
from procedures.procedure import Context
from procedures.stepresult import StepResult


@dataclass(frozen=True)
class InMode3(StepResult):
    """``bring_to_mode3``'s result: found there ``already`` or brought there in ``waited_s``;
    every loop closed from rig time ``t_caged_s``."""

    already: bool
    waited_s: float
    t_caged_s: float


@dataclass(frozen=True)
class ModeSet(StepResult):
    """The mode the relay node reports after a mode change, and the settling time given it."""

    mode: int
    settle_s: float = 0.0


def bring_to_mode3(
    ctx: Context,
    *,
    spin_timeout_s: float = 900.0,
    cage_timeout_s: float = 600.0,
    poll_s: float = 2.0,
    clamped_ok: bool = False,
) -> InMode3:
    """Mode 3 with the wheels at speed and every channel caged (II D): spin up in mode 2 if
    needed, then mode 3, then wait for the relay driver's null detectors. ``t_caged_s`` is the
    rig time from which every loop is known closed (now, if the rig was found in mode 3): a step
    that needs the caging loops' transients gone waits from there, resumed or not. A clamped
    platform (loops open, Ch. V B) is refused with ``PlatformClamped`` unless ``clamped_ok``
    (the open-loop baseline, which clamps anyway)."""
    rig = ctx.rig
    st = rig.relays.status()
    if st.clamped and not clamped_ok:
        # the loops are open: the null detectors may never see the platform caged, and a
        # procedure would wait for nothing; only the open-loop baseline works clamped
        raise PlatformClamped(
            f"{ctx.proc.name}: cannot bring the rig to mode 3 with the loops closed"
        )
    t0 = ctx.time_s
    if st.mode == 3 and all(st.at_speed.values()) and all(st.caged.values()):
        return InMode3(already=True, waited_s=0.0, t_caged_s=round(ctx.time_s, 3))
    if not all(st.at_speed.values()):
        if st.mode != 2:
            rig.set_mode(2)
        _poll(
            ctx, lambda s: all(s.at_speed.values()), spin_timeout_s, poll_s, "gyro wheels at speed"
        )
    if rig.relays.status().mode != 3:
        rig.set_mode(3)
    _poll(
        ctx,
        lambda s: all(s.caged.values()),
        cage_timeout_s,
        poll_s,
        "every gyro channel caged in mode 3",
    )
    return InMode3(
        already=False, waited_s=round(ctx.time_s - t0, 3), t_caged_s=round(ctx.time_s, 3)
    )


def enter_gyro_mode(ctx: Context, mode: int, settle_s: float) -> ModeSet:
    """Mode 4 or 5 from caged Mode 3 (the relay node refuses it otherwise, II D), then ``settle_s``
    for the network's and the caging loop's transients: the loop now closes through the gyro's
    float, and the caging through the autocollimator."""
    now = ctx.rig.set_mode(mode)
    ctx.acquire(settle_s, keep=False)
    return ModeSet(mode=now, settle_s=settle_s)


def back_to_mode3(ctx: Context) -> ModeSet:
    """Hand the rig back in Mode 3, where the other procedures start."""
    return ModeSet(mode=ctx.rig.set_mode(3))


def _poll(ctx: Context, ok, timeout_s: float, poll_s: float, what: str) -> None:
    t_end = ctx.time_s + timeout_s
    while not ok(ctx.rig.relays.status()):
        if ctx.time_s >= t_end:
            raise DeviceTimeout(f"{what}: not reached within {timeout_s:g} s of rig time")
        ctx.acquire(poll_s, keep=False)


@dataclass
class Settled:
    waited_s: float
    slope_V_per_s: np.ndarray  # per channel, over the last window


def wait_settled(
    ctx: Context,
    columns: list[int],
    *,
    tol_V: float | np.ndarray,
    window_s: float = 40.0,
    chunk_s: float = 2.0,
    min_s: float = 20.0,
    timeout_s: float = 900.0,
) -> Settled:
    """Acquire until the listed channels have settled, decided from the data: a straight line
    through the last ``window_s`` of ``chunk_s`` means changes by less than ``tol_V`` over the
    window, or by less than three standard errors of its slope (no significant trend left)."""
    tol = np.broadcast_to(np.asarray(tol_V, float), (len(columns),))
    n_win = max(3, int(round(window_s / chunk_s)))
    means: list[np.ndarray] = []
    t0 = ctx.time_s
    slope = np.full(len(columns), np.nan)  # no trend until a full window has been fitted
    while True:
        block = ctx.acquire(chunk_s)[:, columns]
        means.append(np.nanmean(block, axis=0))
        waited = ctx.time_s - t0
        if len(means) >= n_win and waited >= min_s:
            y = np.array(means[-n_win:])
            t = (np.arange(n_win) - (n_win - 1) / 2) * chunk_s
            slope = t @ (y - y.mean(axis=0)) / (t @ t)
            resid = y - y.mean(axis=0) - np.outer(t, slope)
            se = np.sqrt((resid**2).sum(axis=0) / (n_win - 2) / (t @ t))
            change = np.abs(slope) * window_s
            if np.all((change < tol) | (np.abs(slope) < 3 * se)):
                return Settled(waited, slope)
        if waited >= timeout_s:
            raise DeviceTimeout(
                f"not settled after {timeout_s:g} s of rig time (last trend "
                f"{np.array2string(np.abs(slope) * window_s, precision=4)} V "
                f"over {window_s:g} s, tolerance {np.array2string(tol, precision=4)} V)"
            )


def mean_and_stderr(x: np.ndarray, batches: int = 10) -> tuple[np.ndarray, np.ndarray]:
    """Column means and their standard errors by batch means (robust to correlated noise)."""
    n = len(x) // batches * batches
    b = np.nanmean(x[:n].reshape(batches, n // batches, -1), axis=1)
    return np.nanmean(x, axis=0), b.std(axis=0, ddof=1) / np.sqrt(batches)
