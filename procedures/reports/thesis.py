"""The thesis's reported figures (Klinger 1974), for the reference columns of reports only.

Procedures never measure with these: they are what a report sets a measurement beside.
K_TO and K_g: II C.1.a (Table 4); bearing To, eta and stiffness: Ch. V F; closed-loop
platform rms and the autocollimator spectrum's dip: Ch. V E.1-2 (Figs. 42, 45); closed-loop roots:
Tables 5 and 6.
"""

from __future__ import annotations

from typing import Any

SURVEY: dict[str, Any] = {
    "source": "thesis (Ch. V E)",
    "platform_rms_urad": {"X": 1.6, "Y": 3.6},
    "dip_hz": {"X": 3.5, "Y": "≈6, broad"},
}

FIGURES: dict[str, Any] = {
    "K_TO_urad_per_s_per_V": {"X": 31.6, "Y": 33.4, "Z": 34.1, "XRD": 32.0},
    "K_g_mV_per_urad": {"X": 6.03, "Y": 6.70, "Z": 7.51, "XRD": 5.74},
    "To_Nm": {"X": 0.016, "Y": 0.016},
    "eta_per_Nm": {"X": 1.6e6, "Y": 1.48e6},
    "stiffness_Nm_per_rad": {"X": 410.0, "Y": 380.0},
    "platform_rms_urad": SURVEY["platform_rms_urad"],
    "dip_hz": SURVEY["dip_hz"],
    # Ch. III C (the inertia the thesis computed for its model) and Ch. V B.4 / Fig. 33 (the
    # pickoff's 6.2 urad rms in 0.1-200 Hz, of which the 71 (pair), 102 and 187 Hz lines, 3, 3,
    # 4 and 2 urad, hold 19 urad^2; the white rest, over 1-50 Hz: sqrt(19.44 x 49 / 199.9))
    "inertia_kg_m2": {"X": 0.70, "Y": 0.25},
    "pickoff_noise_urad_rms": {"X": 2.18},
}

#: Ch. V B, Figs. 32-34 and Table 1: the open-loop baselines. The NEA is Table 1's control-channel
#: figure (0.1-100 Hz); Ch. V B.3 found 0.55 urad on the X instrumentation channel; the azimuth
#: unit 2.78 urad (pure 1/f); the 1/f corner "below 3 Hz"; the pickoff 6.2 / 12.4 urad rms in
#: 0.1-200 Hz with the lines, 2.18 urad of white noise in 1-50 Hz on X (see FIGURES)
BASELINE: dict[str, Any] = {
    "source": "thesis (Ch. V B, Table 1)",
    "nea_urad": {"X": {"ctl": 0.451, "inst": 0.55, "z": 2.78}, "Y": {"ctl": 0.506, "z": 2.78}},
    "flicker_corner_hz": {"ctl": 3.0, "inst": 3.0},
    "pickoff_rms_urad": {"X": {"1-50 Hz": 2.18, "0.1-200 Hz": 6.2}, "Y": {"0.1-200 Hz": 12.4}},
    "pickoff_lines_hz": [70.6, 71.4, 102.0, 187.0],
}


#: the thesis's closed-loop roots (rad/s): Table 5 (Mode 3; its platform pair's frequency is not
#: legible in the scan) and Table 6 (modes 4 and 5, read off the root locus of Fig. 28)
CLOSED_LOOP_ROOTS: dict[int, dict[str, dict[str, float | None]]] = {
    3: {"X": {"c1": 5.6, "c4": 123.0, "platform_w": None, "platform_zeta": 0.13},
        "Y": {"c1": 4.5, "c4": 96.0, "platform_w": None, "platform_zeta": 0.09}},
    4: {"X": {"c1": 5.0, "c4": 160.0, "platform_w": 43.0, "platform_zeta": 0.24},
        "Y": {"c1": 5.0, "c4": 160.0, "platform_w": 60.0, "platform_zeta": 0.27}},
}


def closed_loop_roots(mode: int, axis: str) -> dict[str, float | None]:
    """Table 5's roots for Mode 3, Table 6's for the gyro modes, with the table's number."""
    return dict(CLOSED_LOOP_ROOTS[3 if mode == 3 else 4][axis]) | {"table": 5.0 if mode == 3 else 6.0}
