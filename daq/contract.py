"""The "fbs-run" version 1 layout contract (DESIGN.md section 6), checked.

Checked from metadata alone - attributes, types, shapes; no sample is read. ``daq.reader.RunFile``
refuses a file that breaks it with a ``ContractError`` (a ``RunFileError``) naming each rule
broken and the bad value, so that no analysis runs on what is not volts on one time base. The
rules, in the order checked:

1. the path is a regular file (a FIFO, a directory or a device is refused before it is
   opened: opening a FIFO would wait for a writer forever);
2. it is HDF5 and not truncated, and its metadata reads (``UnreadableRunFile``);
3. root ``format = "fbs-run"`` and ``format_version = 1`` (``READABLE_VERSIONS``; a file of
   another version is refused before its layout is looked at);
4. ``/channels`` is a group of at least one member, each a 1-D dataset in the file (not a
   group, a link to another file, a virtual or external-storage dataset, nor one stored with
   an HDF5 filter this library lacks);
5. every channel is floating point (integer ADC counts are not volts);
6. every channel has a string ``units`` and a number ``sample_rate_hz``, finite and within
   ``MIN_RATE_HZ`` .. ``MAX_RATE_HZ``; all channels have the same rate (to ``RATE_RTOL``);
7. all channels have the same length (one time base), and at least one sample; a file being
   written or left by a writer that died (opened in SWMR mode, or its status still
   "recording": ``fbs recover`` closes it) is exempt from both, as a live writer extends its
   channels one after another and starts with none (its ``n_samples`` is the shortest's);
8. ``/events``, if present, is a 1-D table with ``time`` (a number), ``kind`` and ``text``;
   ``/meta``, if present, a group.

Rules 1 and 2 are the opening's (``daq.reader.open_hdf5``); this module checks 3 to 8 on an open
file and words the error. ``fbs recover`` and the reader share its checks of a channel.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from daq.runfile import FORMAT, FORMAT_VERSION, RunFileError

#: the "fbs-run" format versions the readers read
READABLE_VERSIONS = (FORMAT_VERSION,)
#: ``sample_rate_hz`` a reader accepts, Hz: below one sample in 1000 s no analysis here has a
#: band to look at; above 10 MHz is past any ADC this software drives (the fastest, the sim's, gives
#: 2 MS/s in all). Outside is an encoding mistake (a period for a rate, kHz for Hz, 1e-300).
MIN_RATE_HZ = 1e-3
MAX_RATE_HZ = 1e7
#: channels' rates equal to this relative tolerance are one rate (float32 and float64 of one number)
RATE_RTOL = 1e-6
#: problems a ContractError message lists (the rest are counted)
_MAX_LISTED = 8


class ContractError(RunFileError):
    """An HDF5 file that breaks the "fbs-run" version 1 layout contract (DESIGN.md section 6).
    The message names each rule broken and the bad value; ``problems`` lists them."""

    def __init__(self, message: str, problems: Sequence[str] = ()) -> None:
        super().__init__(message)
        self.problems = tuple(problems) or (message,)


@dataclass(frozen=True)
class Layout:
    """What a file that keeps the contract holds, as the checks found it: its channels, their
    common rate and their units."""

    channels: tuple[str, ...]
    rate_hz: float
    units: dict[str, str]


class _Bad(Exception):
    """An attribute value that is not what the rule asks for (the message says what it is)."""


def _show(v: Any) -> str:
    """A value for a message: short, with its type where the repr hides it."""
    if isinstance(v, np.ndarray):
        text = np.array2string(v, threshold=6, edgeitems=2)
        return f"{text} ({v.dtype} array of shape {v.shape})"
    if isinstance(v, np.generic):
        return f"{v.item()!r} ({v.dtype})"
    text = repr(v)
    return text if len(text) <= 80 else text[:77] + "..."


def _scalar(v: Any) -> Any:
    """A scalar attribute value: a one-element array counts as its element."""
    if isinstance(v, np.ndarray):
        if v.size != 1:
            raise _Bad(f"{_show(v)} is not one value")
        return v.reshape(()).item() if v.dtype.kind in "biufc" else v.reshape(-1)[0]
    return v


def _number(v: Any) -> float:
    """A real number attribute (int or float, not bool, text or complex) as a float."""
    x = _scalar(v)
    if isinstance(x, np.generic):
        x = x.item()
    if isinstance(x, bool) or not isinstance(x, (int, float)):
        raise _Bad(f"{_show(v)} is not a number")
    return float(x)


def _string(v: Any) -> str:
    """A text attribute (str, or UTF-8 bytes) as str."""
    x = _scalar(v)
    if isinstance(x, bytes):
        try:
            return x.decode("utf-8")
        except UnicodeDecodeError:
            raise _Bad(f"{_show(v)} is not UTF-8 text") from None
    if not isinstance(x, str):
        raise _Bad(f"{_show(v)} is not a string")
    try:
        x.encode("utf-8")
    except UnicodeEncodeError:  # h5py's undecodable bytes, as lone surrogates
        raise _Bad(f"{ascii(x)} is not UTF-8 text") from None
    return str(x)


def _rate_problem(rate: float) -> str | None:
    if not math.isfinite(rate):
        return f"{rate!r} is not finite"
    if rate <= 0:
        return f"{rate!r} Hz is not positive"
    if not MIN_RATE_HZ <= rate <= MAX_RATE_HZ:
        return (
            f"{rate!r} Hz is outside the {MIN_RATE_HZ:g} .. {MAX_RATE_HZ:g} Hz this reader accepts"
        )
    return None


def member_dataset(g: h5py.Group, name: str) -> tuple[h5py.Dataset | None, str | None]:
    """``/channels/name`` as a dataset in this file, or why it is not one. The link is looked at
    before it is followed: an external link is never opened (its target may be a FIFO, on which
    HDF5 would wait for ever)."""
    link = g.get(name, getlink=True)
    if isinstance(link, h5py.ExternalLink):
        return None, (
            f"a link to {link.filename}:{link.path} (another file): a channel is a dataset "
            f"in the run file itself"
        )
    obj = g.get(name)
    if obj is None:
        return None, f"a link to {getattr(link, 'path', '?')}, which does not exist"
    if isinstance(obj, h5py.Group):
        return None, "a group, not a 1-D dataset"
    if not isinstance(obj, h5py.Dataset):
        return None, f"a {type(obj).__name__}, not a 1-D dataset"
    return obj, None


def _storage_problem(ds: h5py.Dataset) -> str | None:
    """Samples stored outside the file, or behind a filter this HDF5 cannot decode."""
    if ds.is_virtual:
        return "a virtual dataset (its samples live in other files): a channel's samples are in the run file"
    if ds.external:
        files = ", ".join(str(e[0]) for e in ds.external)
        return (
            f"samples stored in external file(s) {files}: a channel's samples are in the run file"
        )
    plist = ds.id.get_create_plist()
    for i in range(plist.get_nfilters()):
        code, _flags, _values, name = plist.get_filter(i)
        if not h5py.h5z.filter_avail(code):
            label = name.decode(errors="replace") if isinstance(name, bytes) else str(name)
            return f"compressed with HDF5 filter {code} ({label}), which this HDF5 library cannot decode"
    return None


def events_problem(ds: Any) -> str | None:
    """Why ``/events`` is not the contract's table (time, kind, text), or None."""
    if not isinstance(ds, h5py.Dataset):
        return f"/events is a {type(ds).__name__}: it must be a table (dataset) of time, kind, text"
    names = ds.dtype.names or ()
    if not {"time", "kind", "text"} <= set(names):
        return (
            f"/events lacks time, kind or text (has {', '.join(names) or f'no fields: {ds.dtype}'})"
        )
    if ds.ndim != 1:
        return f"/events is {ds.ndim}-D (shape {ds.shape}): it must be a 1-D table"
    t = ds.dtype["time"]
    if t.kind not in "iuf":
        return f"/events time is {t}: it must be a number (seconds)"
    return None


def _names(cs: Sequence[str], most: int = 6) -> str:
    return ", ".join(cs[:most]) + (f" and {len(cs) - most} more" if len(cs) > most else "")


def contract_problems(f: h5py.File, *, live: bool = False) -> tuple[list[str], Layout]:
    """Every rule of the layout contract ``f`` breaks (module docstring), each naming the bad
    value, and what it holds. Reads attributes, types and shapes only. A wrong ``format`` or
    ``format_version`` is the only problem given: the rest of such a file is not this layout's.
    ``live``: the file is being written, or its writer died (opened in SWMR mode, or its status
    still "recording"): its channels may differ in length, or hold nothing yet."""
    problems: list[str] = []
    empty = Layout((), math.nan, {})
    fmt = f.attrs.get("format")
    if fmt is None:
        return [
            f"is not an {FORMAT} file (no root attribute format; an {FORMAT} file has format = {FORMAT!r})"
        ], empty
    try:
        fmt_text = _string(fmt)
    except _Bad as exc:
        fmt_text = str(exc)
    if fmt_text != FORMAT:
        return [f"is not an {FORMAT} file (format = {fmt_text!r})"], empty
    readable = " or ".join(str(v) for v in READABLE_VERSIONS)
    if "format_version" not in f.attrs:
        problems.append(
            f"no root attribute format_version (this reader reads {FORMAT} version {readable})"
        )
    else:
        v = f.attrs["format_version"]
        try:
            version = _number(v)
        except _Bad as exc:
            return [f"format_version = {exc}; this reader reads {FORMAT} version {readable}"], empty
        if version not in READABLE_VERSIONS:
            return [
                f"format_version = {_show(_scalar(v))}: this reader reads {FORMAT} version {readable} only "
                f"(a newer layout needs a newer fbs-hil)"
            ], empty
    linked = []
    for name in ("channels", "events", "meta"):
        link = f.get(name, getlink=True)  # the link only: an external one is not followed
        if isinstance(link, h5py.ExternalLink):
            linked.append(
                f"/{name} is a link to {link.filename}:{link.path} (another file): the layout's "
                f"objects are in the run file itself"
            )
    if linked:
        return problems + linked, empty
    if "channels" not in f:
        problems.append("has no /channels group")
        return problems, empty
    g = f["channels"]
    if not isinstance(g, h5py.Group):
        problems.append(
            f"/channels is a {type(g).__name__}, not a group of one dataset per channel"
        )
        return problems, empty
    names = tuple(g)
    if not names:
        problems.append("has no channels (/channels is empty)")
        return problems, empty
    rates: dict[str, float] = {}
    units: dict[str, str] = {}
    lengths: dict[str, int] = {}
    per_channel: dict[str, list[str]] = {}  # a rule broken -> the channels breaking it

    def bad(c: str, text: str) -> None:
        per_channel.setdefault(text, []).append(c)

    for c in names:
        try:
            c.encode("utf-8")
        except UnicodeEncodeError:
            problems.append(f"/channels/{ascii(c)}: a channel name that is not UTF-8 text")
            continue
        ds, why = member_dataset(g, c)
        if ds is None:
            bad(c, str(why))
            continue
        shape = ds.shape
        if shape is None or len(shape) != 1:
            bad(
                c,
                f"{'a null dataspace' if shape is None else f'{len(shape)}-D (shape {shape})'}: a channel is a "
                f"1-D dataset",
            )
            continue
        lengths[c] = shape[0]
        try:
            dt = ds.dtype
        except (TypeError, ValueError) as exc:
            bad(c, f"an HDF5 type this reader cannot map ({exc}): channels are floating point")
            continue
        if dt.kind != "f":
            hint = (
                " (integer ADC counts are not volts: scale them to volts first)"
                if dt.kind in "iub"
                else ""
            )
            bad(c, f"{dt} samples, not floating point{hint}")
        storage = _storage_problem(ds)
        if storage:
            bad(c, storage)
        if "units" not in ds.attrs:
            bad(c, "no units attribute (a string, e.g. 'V')")
        else:
            try:
                units[c] = _string(ds.attrs["units"])
            except _Bad as exc:
                bad(c, f"units = {exc}")
        if "sample_rate_hz" not in ds.attrs:
            bad(c, "no sample_rate_hz attribute (a number, Hz)")
        else:
            try:
                rate = _number(ds.attrs["sample_rate_hz"])
            except _Bad as exc:
                bad(c, f"sample_rate_hz = {exc}")
            else:
                why_rate = _rate_problem(rate)
                if why_rate:
                    bad(c, f"sample_rate_hz = {why_rate}")
                else:
                    rates[c] = rate
    for text, cs in per_channel.items():
        subject = f"/channels/{cs[0]}" if len(cs) == 1 else f"channels {_names(cs)}"
        problems.append(f"{subject}: {text}")
    if rates:
        lo, hi = min(rates.values()), max(rates.values())
        if not math.isclose(lo, hi, rel_tol=RATE_RTOL):
            by_rate: dict[float, list[str]] = {}
            for c, r in rates.items():
                by_rate.setdefault(r, []).append(c)
            problems.append(
                "channels have different sample rates ("
                + "; ".join(f"{r!r} Hz: {_names(cs)}" for r, cs in by_rate.items())
                + "): all channels share one time base"
            )
    if lengths and not live:
        if len(set(lengths.values())) > 1:
            by_length: dict[int, list[str]] = {}
            for c, n in lengths.items():
                by_length.setdefault(n, []).append(c)
            problems.append(
                "channels have different lengths ("
                + "; ".join(f"{n} samples: {_names(cs)}" for n, cs in sorted(by_length.items()))
                + "): all channels share one time base; a writer that died between channels leaves this, "
                "and `fbs recover FILE` pads the short ones with NaN"
            )
        elif max(lengths.values()) == 0:
            problems.append("holds no samples (every channel has length 0)")
    if "events" in f:
        bad_events = events_problem(f["events"])
        if bad_events:
            problems.append(bad_events)
    if "meta" in f and not isinstance(f["meta"], h5py.Group):
        problems.append("/meta is not a group (JSON strings as its attributes)")
    if problems:
        return problems, empty
    first = names[0]
    return [], Layout(names, rates[first], units)


def contract_error(path: Path, problems: Sequence[str]) -> ContractError:
    """The error a file breaking the rules ``problems`` raises: every rule, in one message."""
    if len(problems) == 1 and problems[0].startswith(("is not an", "has no", "holds no")):
        return ContractError(f"{path} {problems[0]}", problems)
    if len(problems) == 1 and problems[0].startswith("format_version ="):
        return ContractError(f"{path}: {problems[0]}", problems)
    listed = list(problems[:_MAX_LISTED])
    if len(problems) > _MAX_LISTED:
        listed.append(f"... and {len(problems) - _MAX_LISTED} more")
    return ContractError(
        f"{path} breaks the {FORMAT} version {FORMAT_VERSION} layout: " + "; ".join(listed),
        problems,
    )
