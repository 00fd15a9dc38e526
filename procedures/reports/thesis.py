"""The thesis's reported figures (Klinger 1974), for the reference columns of reports only.

Procedures never measure with these: they are what a report sets a measurement beside.
``SOURCES`` says where each figure stands in the thesis (table or section, and page: the pages
are the thesis's own, from its lists of contents, tables and figures) with its words, and where
the thesis contradicts itself, or a figure is derived rather than printed, it says so.
K_TO and K_g: II C.1.a (1) and (6) (text, not a table); bearing To and eta: Ch. V F.4, stiffness
Table 5's K_S; closed-loop platform rms and the autocollimator spectrum's dip: Ch. V E.1-2
(Figs. 42, 45); closed-loop roots: Tables 5 and 6; the open-loop baselines: Table 1, Ch. V B.
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

#: Ch. V B, Figs. 32-34 and Table 1: the open-loop baselines. The NEA is Table 1's figure per
#: channel (0.1-100 Hz): control 0.451 / 0.506, instrumentation 0.610 / 0.550 (X / Y), azimuth
#: 2.78 urad (pure 1/f). Ch. V B.3 (p. 122) gives 0.55 urad for the X instrumentation channel
#: (Fig. 32b), Table 1's Y figure, not its X one (see SOURCES); the 1/f corner "below 3 Hz"; the
#: pickoff 6.2 / 12.4 urad rms (Ch. VI A) with the lines, 2.18 urad of white noise in 1-50 Hz on
#: X (derived, see FIGURES)
BASELINE: dict[str, Any] = {
    "source": "thesis (Ch. V B, Table 1)",
    "nea_urad": {
        "X": {"ctl": 0.451, "inst": 0.610, "z": 2.78},
        "Y": {"ctl": 0.506, "inst": 0.550, "z": 2.78},
    },
    "flicker_corner_hz": {"ctl": 3.0, "inst": 3.0},
    "pickoff_rms_urad": {"X": {"1-50 Hz": 2.18, "0.1-200 Hz": 6.2}, "Y": {"0.1-200 Hz": 12.4}},
    "pickoff_lines_hz": [70.6, 71.4, 102.0, 187.0],
}


#: the thesis's closed-loop roots (rad/s): Table 5 (Mode 3; its platform pair's frequency is not
#: legible in the scan) and Table 6 (modes 4 and 5, read off the root locus of Fig. 28)
CLOSED_LOOP_ROOTS: dict[int, dict[str, dict[str, float | None]]] = {
    3: {
        "X": {"c1": 5.6, "c4": 123.0, "platform_w": None, "platform_zeta": 0.13},
        "Y": {"c1": 4.5, "c4": 96.0, "platform_w": None, "platform_zeta": 0.09},
    },
    4: {
        "X": {"c1": 5.0, "c4": 160.0, "platform_w": 43.0, "platform_zeta": 0.24},
        "Y": {"c1": 5.0, "c4": 160.0, "platform_w": 60.0, "platform_zeta": 0.27},
    },
}


def closed_loop_roots(mode: int, axis: str) -> dict[str, float | None]:
    """Table 5's roots for Mode 3, Table 6's for the gyro modes, with the table's number."""
    return dict(CLOSED_LOOP_ROOTS[3 if mode == 3 else 4][axis]) | {
        "table": 5.0 if mode == 3 else 6.0
    }


#: Where each figure of ``FIGURES``, ``BASELINE`` and ``CLOSED_LOOP_ROOTS`` stands in the thesis:
#: {key: {channel or "*": text}}, the text quoting the thesis and naming its table or section and
#: page (the thesis's page numbers, from its lists of contents, tables and figures; a figure in
#: running text between two numbered figures is given as that span). Where the thesis states a
#: figure twice and the two differ, or the figure is derived here rather than printed, it says so.
SOURCES: dict[str, dict[str, str]] = {
    "K_TO_urad_per_s_per_V": {
        "*": 'Ch. II C.1.a(1), pp. 23-31 (text between Figs. 5 and 6): "The values of this '
        'parameter, K_TO, are 31.6, 33.4, 34.1, 32.0 urad/sec-V"'
    },
    "K_g_mV_per_urad": {
        "*": 'Ch. II C.1.a(6), pp. 23-31 (text): "The scale factors for the X, Y, Z, and X_RD '
        'axes are 6.03, 6.70, 7.51, and 5.74 mV/urad"; Table 5 (p. 87) K_R 6030 / 6700 '
        "V/rad agrees"
    },
    "To_Nm": {
        "*": 'Ch. V F.4, pp. 156-157: "T_o = 0.016 N-m", one figure fitted to Figs. 51, 53, 54 (the axis is not '
        "named; the same value is shown for X and Y)"
    },
    "eta_per_Nm": {
        "X": 'Ch. V F.4, pp. 156-157: "eta = 1.6 x 10^6 (N-m)^-1" (axis not named)',
        "Y": "derived, not printed: Table 5's K_S 380 N m/rad (p. 87) / To^2 (Ch. V F.4 gives only "
        "the one eta, 1.6e6)",
    },
    "stiffness_Nm_per_rad": {
        "X": 'Table 5, p. 87: K_S 410 (units misprinted "in-in/rad"); = eta To^2 of '
        'Ch. V F.4 (409.6); Ch. VI A: "approximately 400 N-m/rad"',
        "Y": 'Table 5, p. 87: K_S 380 (units misprinted "in-in/rad"); Ch. VI A: '
        '"approximately 400 N-m/rad"',
    },
    "platform_rms_urad": {
        "X": 'Ch. V E.2, p. 138: "The computed rms platform angle at frequencies greater than '
        "0.4 Hz is approximately 1.6 urad\" (the gyro's power below 15 Hz); Ch. VI A "
        "(pp. 159-160) states the same 1.6 for the band 0.4 to 200 Hz",
        "Y": 'Ch. V E.2, p. 141: "The computed rms platform angle is 3.6 urad"; Ch. VI A '
        "(pp. 159-160): 0.4-200 Hz, where E.2 used 0.4-15 Hz",
    },
    "dip_hz": {
        "X": 'Ch. V E.1, p. 137: "the pronounced decrease in power at 3.5 Hz"; Table 5\'s open-loop '
        "platform/bearing pair w_p 21.2 rad/s (3.37 Hz) is not sqrt(K_S / I_xx) = sqrt(410 / 0.70) = "
        "24.2 rad/s (3.85 Hz) of Ch. III C's inertia",
        "Y": 'Fig. 45 caption, p. 142: "the dip around 6 Hz", broader than predicted; Table 5: w_p 39.0 '
        "rad/s (6.2 Hz) = sqrt(380 / 0.25)",
    },
    "inertia_kg_m2": {
        "*": 'Ch. III C, p. 73: "I_xx = 0.70 Kg-m^2, I_yy = 0.25 Kg-m^2" (from a closed-loop '
        "frequency response)"
    },
    "pickoff_noise_urad_rms": {
        "X": "derived, not printed: Ch. VI A's 6.2 urad rms (X) less its lines (read off "
        "Fig. 33, pp. 119-120), the white rest over 1-50 Hz"
    },
    "nea_urad": {
        "ctl": "Table 1, p. 40 (control channels, 0.1-100 Hz): 0.451 (X), 0.506 (Y); Ch. VI A (pp. 159-160): "
        '"0.5 urad"',
        "inst": "Table 1, p. 40 (instrumentation channels, 0.1-100 Hz): 0.610 (X), 0.550 (Y); but Ch. V "
        'B.3 (p. 122) gives "0.55 urad" from the X instrumentation channel\'s spectrum (Fig. 32b): '
        "the thesis is inconsistent for X; Table 5 (p. 87) also has K_AI 5830 V/rad for X against "
        "Table 1's 5.63 mV/urad and eq. 3.22's 5630",
        "z": 'Table 1, p. 40 (azimuth): 2.78 urad; Ch. VI A (pp. 159-160): "2.8 urad"',
    },
    "flicker_corner_hz": {
        "*": 'Ch. V B.3, p. 122: "Below 3 Hz the power spectra vary inversely with frequency" '
        "(a reading, not a fitted corner)"
    },
    "pickoff_rms_urad": {
        "0.1-200 Hz": 'Ch. VI A, pp. 159-160: "the overall gyro rms noise level of 6.2 urad in the X '
        "axis, and 12.4 urad in the Y axis\" (the band is not stated; Fig. 33's "
        "spectra span it)",
        "1-50 Hz": "derived, not printed (see the pickoff noise row)",
    },
    "roots": {
        "3": "Table 5, p. 87 (Mode 3): closed-loop w_c1 5.6 / 4.5, w_c4 123 / 96 rad/s, zeta_p 0.13 / "
        "0.09 (X / Y); the scan's platform-pair frequency is not legible",
        "4": "Table 6, p. 90 (Modes 4 and 5): w_c1 5 / 5, w_c4 160 / 160, w_p 43 / 60 rad/s, zeta_p 0.24 / "
        "0.27 (X / Y), read off the root locus of Fig. 28",
    },
}


def source(key: str, channel: str | None = None) -> str:
    """Where the thesis states ``key`` (for ``channel``), or "" where it gives no figure."""
    s = SOURCES.get(key) or {}
    return s.get(channel or "*") or s.get("*") or ""
