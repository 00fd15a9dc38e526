#!/bin/sh
# Detection curves of every catalogue effect (docs/gap.md section 6; issue 23, acceptance E):
# one `fbs campaign gap` per effect over its key parameter, each in OUT/EFFECT/ (runs.jsonl,
# curves.json, curves.md, curves.png), and every curves.md in one OUT/curves.md for the docs.
#
#   bench/gap_curves.sh [EFFECT ...]            # default: every effect below
#
# Settings (environment): OUT (default curves), SEEDS (20), N grid points (8), DURATION (300 s:
# the detection-limit record), SCHEDULER (a Dask scheduler address; default the local pool),
# JOBS, FBS (the command, default .venv/bin/fbs, else fbs). A campaign stopped part-way goes
# on where it stopped when this is run again (runs.jsonl is resumed). The full set is about
# 10 effects x (8 x 20 + 20) runs of 15-40 s of CPU each: a cluster's job, not a laptop's.
# A tiny run to see that it works: SEEDS=1 N=2 DURATION=74 OUT=/tmp/curves bench/gap_curves.sh pickup_line
#
# Not a benchmark of `make bench` (bench/run_all.py runs the *.py files only).
set -eu

OUT=${OUT:-curves}
SEEDS=${SEEDS:-20}
N=${N:-8}
DURATION=${DURATION:-300}
if [ -z "${FBS:-}" ]; then
    if [ -x .venv/bin/fbs ]; then FBS=.venv/bin/fbs; else FBS=fbs; fi
fi

# effect  grid (PARAM=LO:HI, log-spaced): from below what the record resolves to well above it
grids='
bearing_friction      stiffness_Nm_per_rad=50:2000
extra_damping         damping_Nms=0.05:10
flicker_noise         corner_hz=2:50
gyro_cross_coupling   factor=0.1:10
mount_resonance       freq_hz=20:150
offset_jumps          amplitude_urad=0.5:30
pickup_line           amplitude_V=0.0001:0.01
platform_disturbance  torque_rms_Nm=0.00001:0.001
scale_factor_error    fraction=0.01:0.5
time_delay            delay_s=0.0002:0.01
'

# every effect of the catalogue has a grid here (a new effect module needs a line above)
PY=$(dirname "$FBS")/python
[ -x "$PY" ] || PY=python3
for e in $("$PY" -c "from simhw.effects import catalogue; print(' '.join(n for n in catalogue() if n != 'none'))"); do
    echo "$grids" | grep -q "^$e " || { echo "gap_curves.sh: effect $e has no grid here; add one" >&2; exit 2; }
done

effects=${*:-$(echo "$grids" | awk 'NF { print $1 }')}
mkdir -p "$OUT"
status=0
for e in $effects; do
    grid=$(echo "$grids" | awk -v e="$e" '$1 == e { print $2 }')
    if [ -z "$grid" ]; then echo "gap_curves.sh: no grid for effect $e" >&2; exit 2; fi
    set -- --effect "$e" --grid "$grid:$N" --log --seeds "$SEEDS" --duration "$DURATION" --out "$OUT/$e"
    if [ -n "${SCHEDULER:-}" ]; then set -- "$@" --scheduler "$SCHEDULER"; fi
    if [ -n "${JOBS:-}" ]; then set -- "$@" --jobs "$JOBS"; fi
    echo "== $FBS campaign gap $*" >&2
    "$FBS" campaign gap "$@" || status=$?
done
for e in $effects; do
    if [ -f "$OUT/$e/curves.md" ]; then cat "$OUT/$e/curves.md"; echo; fi
done > "$OUT/curves.md"
echo "gap_curves.sh: curves of $(echo $effects | wc -w) effect(s) in $OUT/curves.md (exit $status)" >&2
exit $status
