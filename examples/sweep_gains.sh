#!/usr/bin/env bash
# Sweep the PD gains of 'fdbench control' and collect every run's indicators into one CSV.
#
#   examples/sweep_gains.sh [OUT.csv] [extra fdbench control options...]
#   examples/sweep_gains.sh gains.csv --kinematics exact
#   KP_VALUES="40 80" KD_VALUES="0.3" examples/sweep_gains.sh small.csv
#
# OUT.csv (default gains.csv) gets the header once and one row per (Kp, Kd): the full record of
# 'fdbench control --format csv' (kp, kd, rmse_rot_deg, rmse_torque_nm, runtime_s, t_end,
# status, ...). Needs the 'fdbench' command on PATH (pip install .).
set -euo pipefail

out="${1:-gains.csv}"
if [ $# -gt 0 ]; then shift; fi
read -r -a kp_values <<< "${KP_VALUES:-20 40 80 160}"   # N m/rad
read -r -a kd_values <<< "${KD_VALUES:-0.1 0.3 1.0}"    # N m s/rad

if ! command -v fdbench > /dev/null; then
    echo "sweep_gains.sh: 'fdbench' is not on PATH; install it with 'pip install .'" >&2
    exit 2
fi

# write next to the target, then rename: an interrupted sweep leaves no half-written OUT.csv
tmp="$(mktemp "${out}.XXXXXX")"
trap 'rm -f "$tmp"' EXIT

runs=0
for kp in "${kp_values[@]}"; do
    for kd in "${kd_values[@]}"; do
        csv="$(fdbench control --kp "$kp" --kd "$kd" "$@" --format csv --quiet)"
        if [ "$runs" -eq 0 ]; then
            printf '%s\n' "$csv" > "$tmp"                    # header and row
        else
            printf '%s\n' "$csv" | tail -n +2 >> "$tmp"      # row only
        fi
        runs=$((runs + 1))
    done
done
mv "$tmp" "$out"

echo "wrote $out ($runs runs)" >&2
