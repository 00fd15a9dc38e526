"""The scoring rules of the development set in ``tests/data/gapdata`` (its README, "How an
answer is scored"), shared by ``test_devset.py`` and ``bench/_devset.py``.

* a null is right when ``significant`` is false;
* a single catalogue effect is right when it is named first and nothing else is, its key
  parameter within 15 % (``freq_hz`` 5 %, ``corner_hz`` 30 %; a pickup line's amplitude 15 %
  and frequency 5 %);
* a file with several effects is right when all are named, nothing else is, each key within
  its tolerance;
* an effect outside the catalogue is right when ``significant`` and not ``explained``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

#: where the set lives (twelve files and ``truth.json``)
DEVSET = Path(__file__).resolve().parents[3] / "data" / "gapdata"

#: the key parameters the set's README scores, and their relative tolerances
KEYS: dict[str, dict[str, float]] = {
    "bearing_friction": {"stiffness_Nm_per_rad": 0.15},
    "mount_resonance": {"freq_hz": 0.05},
    "pickup_line": {"freq_hz": 0.05, "amplitude_V": 0.15},
    "flicker_noise": {"corner_hz": 0.30},
    "offset_jumps": {"amplitude_urad": 0.15},
    "time_delay": {"delay_s": 0.15},
    "extra_damping": {"damping_Nms": 0.15},
    "scale_factor_error": {"fraction": 0.15},
}


def truth_effects(t: dict[str, Any]) -> dict[str, dict[str, float]]:
    """{effect: its true parameters} of one truth entry ({} for a null or an unknown)."""
    if "effects" in t:
        return {e: t["by_effect"][e] for e in t["effects"]}
    if t["effect"] in ("none", "unknown"):
        return {}
    return {t["effect"]: {k: v for k, v in t.items() if isinstance(v, (int, float))}}


def score(t: dict[str, Any], res: dict[str, Any]) -> tuple[bool, str, list[bool]]:
    """(right, why, interval coverage of each scored key) for one file's JSON result."""
    named = [e["effect"] for e in res["effects"]]
    if t["effect"] == "none":
        return (not res["significant"], f"significant={res['significant']} named={named}", [])
    if t["effect"] == "unknown":
        ok = res["significant"] and not res["explained"]
        return (
            ok,
            f"significant={res['significant']} explained={res['explained']} named={named}",
            [],
        )
    want = truth_effects(t)
    covers: list[bool] = []
    why = []
    ok = sorted(named) == sorted(want)
    if len(want) == 1 and named and named[0] != next(iter(want)):
        ok = False
    for e in res["effects"]:
        true = want.get(e["effect"])
        if true is None:
            continue
        for k, tol in KEYS.get(e["effect"], {}).items():
            if k not in true or k not in e["parameters"] or e["parameters"][k] is None:
                continue
            est = e["parameters"][k]
            rel = est / true[k] - 1
            why.append(f"{e['effect']}.{k} {est:.4g} ({rel:+.1%})")
            ok = ok and abs(rel) <= tol
            iv = e.get("parameters_ci95", {}).get(k)
            if iv and None not in iv:
                covers.append(iv[0] <= true[k] <= iv[1])
                why[-1] += f" [{iv[0]:.4g}, {iv[1]:.4g}]"
    return ok, f"named={named} " + "; ".join(why), covers
