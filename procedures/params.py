"""A procedure's inputs from outside the run: ``--param`` values and earlier procedures' results.

``parse_params`` turns ``--param k=v`` (and ``--axis``) into the procedure's ``Params``;
``find_prior`` finds the newest completed summary of each procedure (stopwatch needs
earth-rate's K_TO; each carries ``_from``, its JSON file, and ``_file``, its run file: the survey
reads the baseline's record there); ``prior_value`` reads one figure from them, else the data sheet's value.
The command line and the console use the same three.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from drivers.rig_datasheet import PICKOFF_SCALE_TOLERANCE
from procedures.procedure import Procedure


def prior_value(
    prior: Mapping[str, Mapping[str, Any]], procedure: str, key: str, channel: str, nominal: float
) -> tuple[float, str]:
    """An earlier ``procedure``'s measured ``key`` for ``channel`` (e.g. earth-rate's K_TO for X),
    else the data sheet's ``nominal``; with where it came from (``procedure`` or "nominal")."""
    v = (((prior.get(procedure) or {}).get(key)) or {}).get(channel)
    if v is not None and math.isfinite(float(v)) and float(v) > 0:
        return float(v), procedure
    return float(nominal), "nominal"


def prior_rel_half_width(
    prior: Mapping[str, Mapping[str, Any]], source: str, key: str, channel: str, value: float
) -> float | None:
    """The relative 95 % half-width of ``value``, ``channel``'s ``key`` as ``prior_value`` gave
    it from ``source``: the larger side of that summary's ``<key>_ci95`` about it. ``None``
    where there is none: the data sheet's nominal value, or a summary without an interval."""
    if source == "nominal":
        return None
    ci = ((prior.get(source) or {}).get(f"{key}_ci95") or {}).get(channel)
    try:
        lo, hi = (float(v) for v in ci or ())
    except (TypeError, ValueError):
        return None
    if not (math.isfinite(hi - lo) and value):
        return None
    return max(abs(hi - value), abs(value - lo)) / abs(value)


def pickoff_scale_rel_half_width(
    prior: Mapping[str, Mapping[str, Any]], source: str, channel: str, kg: float
) -> float:
    """How well ``kg``, ``channel``'s K_g as ``prior_value`` gave it from ``source``, is known,
    relative, 95 %: the stopwatch interval's half-width (``prior_rel_half_width``), else the
    data sheet's tolerance ``PICKOFF_SCALE_TOLERANCE``."""
    u = prior_rel_half_width(prior, source, "K_g_mV_per_urad", channel, kg)
    return PICKOFF_SCALE_TOLERANCE if u is None else u


def prior_values(
    prior: Mapping[str, Mapping[str, Any]],
    procedure: str,
    key: str,
    channels: Iterable[str],
    nominal: Mapping[str, float],
) -> tuple[dict[str, float], dict[str, str]]:
    """``prior_value`` for each of ``channels``: the values, and where each came from."""
    got = {ch: prior_value(prior, procedure, key, ch, nominal[ch]) for ch in channels}
    return {ch: v for ch, (v, _) in got.items()}, {ch: src for ch, (_, src) in got.items()}


def find_prior(out_dir: Path, extra: list[str] | None = None) -> dict[str, dict[str, Any]]:
    """The newest completed summary (values) of each procedure in ``out_dir``, then ``extra`` files."""
    found: dict[str, tuple[float, dict]] = {}
    candidates = sorted(out_dir.glob("*.json")) if out_dir.is_dir() else []
    for path in candidates:
        if not path.is_file():
            continue  # a FIFO would block the read forever, a folder named *.json is not a summary
        try:
            data = json.loads(path.read_text())
        except (OSError, ValueError):
            continue
        if (
            not isinstance(data, dict)
            or data.get("verdict") not in ("pass", "fail")
            or not isinstance(data.get("procedure"), str)
            or not isinstance(data.get("values"), dict)
        ):
            continue  # not a summary `fbs run` wrote (notes, another tool's JSON): not evidence
        mtime = path.stat().st_mtime
        if data["procedure"] not in found or mtime >= found[data["procedure"]][0]:
            found[data["procedure"]] = (mtime, data["values"] | _provenance(path, data))
    prior = {name: values for name, (_, values) in found.items()}
    for spec in extra or []:
        path = Path(spec)
        if path.exists() and not path.is_file():
            raise ValueError(
                f"--prior {path}: not a regular file (a folder, FIFO or device); give a summary .json"
            )
        try:
            data = json.loads(path.read_text())
        except OSError as exc:
            raise ValueError(f"--prior {path}: cannot read it ({exc.strerror or exc})") from None
        except ValueError as exc:
            raise ValueError(f"--prior {path}: not JSON ({exc})") from None
        if (
            not isinstance(data, dict)
            or not isinstance(data.get("procedure"), str)
            or not isinstance(data.get("values"), dict)
        ):
            raise ValueError(
                f"--prior {path}: not a procedure summary (written by `fbs run` beside its .h5)"
            )
        prior[data["procedure"]] = data["values"] | _provenance(path, data)
    return prior


def _provenance(path: Path, data: Mapping[str, Any]) -> dict[str, Any]:
    """Where a prior summary came from: ``_from`` its JSON file, ``_file`` its run file (the survey
    reads the baseline's clamped record there), looked for beside the JSON when moved with it."""
    out: dict[str, Any] = {"_from": str(path)}
    run = data.get("file")
    if isinstance(run, str) and run:
        f = Path(run)
        out["_file"] = str(
            path.parent / f.name if not f.exists() and (path.parent / f.name).exists() else f
        )
    return out


def parse_params(proc_cls: type[Procedure], specs: list[str], axis: str | None) -> Any:
    """``--param k=v`` (v parsed as JSON when it parses, else a string) and ``--axis``."""
    data: dict[str, Any] = {}
    for spec in specs:
        key, sep, raw = spec.partition("=")
        if not sep or not key:
            raise ValueError(f"--param {spec!r}: use name=value, e.g. repetitions=4")
        try:
            data[key.strip()] = json.loads(raw)
        except ValueError:
            data[key.strip()] = raw
    if axis is not None:
        fields = proc_cls.Params.__dataclass_fields__
        if "axis" in fields:
            data["axis"] = axis
        elif "channels" in fields:
            data["channels"] = [axis]
        else:
            raise ValueError(
                f"fbs run {proc_cls.name}: --axis does not apply (it measures all channels at once)"
            )
    try:
        return proc_cls.params_from(data)
    except TypeError as exc:
        raise ValueError(f"fbs run {proc_cls.name}: bad parameter: {exc}") from None
