#!/usr/bin/env bash
# Run 'fdbench control' and 'fdbench simulate' with every integrator: the compiled fixed-step RK4
# (the default) and scipy's adaptive solve_ivp methods. The RMSEs agree (to ~1e-5 deg at the
# default tolerances) and RK4 is about two orders of magnitude faster: compare the runtime_s
# column.
#
#   examples/compare_integrators.sh [OUT.csv] [extra fdbench options...]
#   examples/compare_integrators.sh integrators.csv --kinematics exact --rtol 1e-8 --atol 1e-11
#
# OUT.csv (default integrators.csv) gets the header once and one row per command and
# integrator: the full record of 'fdbench ... --format csv' (integrator, rmse_rot_deg,
# rmse_torque_nm, runtime_s, t_end, status, ...). Needs the 'fdbench' command on PATH.
set -euo pipefail

out="${1:-integrators.csv}"
if [ $# -gt 0 ]; then shift; fi

if ! command -v fdbench > /dev/null; then
    echo "compare_integrators.sh: 'fdbench' is not on PATH; install it with 'pip install .'" >&2
    exit 2
fi

# write next to the target, then rename: an interrupted run leaves no half-written OUT.csv
tmp="$(mktemp "${out}.XXXXXX")"
trap 'rm -f "$tmp"' EXIT

runs=0
for command in control simulate; do
    for integrator in rk4 rk45 dop853 lsoda radau bdf; do
        csv="$(fdbench "$command" --integrator "$integrator" "$@" --format csv --quiet)"
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
