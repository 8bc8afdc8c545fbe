#!/usr/bin/env bash
# Run 'fdbench control' and 'fdbench simulate' with every integrator: the compiled fixed-step RK4
# (the default) and scipy's adaptive solve_ivp methods. The RMSEs agree (to ~1e-5 deg at the
# default tolerances) and RK4 is about two orders of magnitude faster.
#
#   examples/compare_integrators.sh [OUT.csv] [extra fdbench options...]
#   examples/compare_integrators.sh integrators.csv --kinematics exact --rtol 1e-8 --atol 1e-11
#
# OUT.csv (default integrators.csv): command, kinematics, integrator, rmse_rot_deg,
# rmse_torque_nm, runtime_s, t_end, status; one row per command and integrator. A comparison
# with RK4 is printed on stdout. Needs the 'fdbench' command on PATH (pip install .).
set -euo pipefail

out="${1:-integrators.csv}"
if [ $# -gt 0 ]; then shift; fi
integrators=(rk4 rk45 dop853 lsoda radau bdf)
commands=(control simulate)
columns="command,kinematics,integrator,rmse_rot_deg,rmse_torque_nm,runtime_s,t_end,status"

if ! command -v fdbench > /dev/null; then
    echo "compare_integrators.sh: 'fdbench' is not on PATH; install it with 'pip install .'" >&2
    exit 2
fi

raw="$(mktemp)"
tmp="$(mktemp "${out}.XXXXXX")"
trap 'rm -f "$raw" "$tmp"' EXIT

first=1
for command in "${commands[@]}"; do
    for integrator in "${integrators[@]}"; do
        echo "fdbench $command --integrator $integrator $*" >&2
        csv="$(fdbench "$command" --integrator "$integrator" "$@" --format csv --quiet)"
        if [ "$first" -eq 1 ]; then
            printf '%s\n' "$csv" > "$raw"
            first=0
        else
            printf '%s\n' "$csv" | tail -n +2 >> "$raw"
        fi
    done
done

# keep the columns of interest, by name (fdbench's CSV quotes fields that hold commas)
awk -v columns="$columns" '
function parse_csv(line, fields,    n, i, c, field, inq) {   # RFC 4180 fields, no embedded newlines
    n = 0; field = ""; inq = 0
    for (i = 1; i <= length(line); i++) {
        c = substr(line, i, 1)
        if (inq) {
            if (c == "\"") {
                if (substr(line, i + 1, 1) == "\"") { field = field "\""; i++ } else inq = 0
            } else field = field c
        } else if (c == "\"") inq = 1
        else if (c == ",") { fields[++n] = field; field = "" }
        else field = field c
    }
    fields[++n] = field
    return n
}
BEGIN { m = split(columns, want, ",") }
NR == 1 {
    n = parse_csv($0, h)
    for (i = 1; i <= n; i++) col[h[i]] = i
    for (j = 1; j <= m; j++) if (!(want[j] in col)) { print "no column " want[j] > "/dev/stderr"; exit 1 }
    print columns
    next
}
{
    parse_csv($0, f)
    line = ""
    for (j = 1; j <= m; j++) line = line (j > 1 ? "," : "") f[col[want[j]]]
    print line
}' "$raw" > "$tmp"
mv "$tmp" "$out"

# the comparison with RK4, per command
awk -F, '
NR == 1 { next }
{ key = $1 SUBSEP $3; rmse[key] = $4; runtime[key] = $6; status[key] = $8
  if (!($1 in seen)) { seen[$1] = 1; order[++n] = $1 }
  if (!($3 in iseen)) { iseen[$3] = 1; integ[++m] = $3 } }
END {
    printf "%-9s %-8s %14s %14s %11s %9s  %s\n", "command", "method", "rmse_rot_deg", "minus rk4", "runtime_s", "x rk4", "status"
    for (i = 1; i <= n; i++) {
        c = order[i]; r0 = rmse[c SUBSEP "rk4"]; t0 = runtime[c SUBSEP "rk4"]
        for (j = 1; j <= m; j++) {
            k = c SUBSEP integ[j]
            printf "%-9s %-8s %14.8f %14.2e %11.5f %9.1f  %s\n", c, integ[j], rmse[k], rmse[k] - r0, runtime[k],
                   (t0 > 0 ? runtime[k] / t0 : 0), status[k]
        }
    }
}' "$out"
echo "wrote $out" >&2
