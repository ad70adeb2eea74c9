#!/usr/bin/env bash
# EMPS (a real prismatic drive, Janot et al. 2019): import the measured records, diagnose the
# datasheet model mjcf/emps.xml, leave OUT/report.json. Usage: tools/examples/emps.sh OUT
# Data: $SPML_SHARED_DATA/emps (default ../shared/data next to the project), never copied.
set -euo pipefail
out=${1:?usage: emps.sh OUT}
root=$(cd "$(dirname "$0")/../.." && pwd)
spml=${SPML:-$root/build/bin/spml}
data=${SPML_SHARED_DATA:-$root/../shared/data}/emps
[ -f "$data/DATA_EMPS.mat" ] || { echo "emps.sh: no $data/DATA_EMPS.mat (set SPML_SHARED_DATA)" >&2; exit 1; }
mkdir -p "$out"
# The benchmark's own conditioning: 4th-order Butterworth at 100 Hz forward-backward, central
# differences, 50 edge samples dropped, decimation by 10. Motor force = gtau * vir.
import=(--x q:carriage=qm --y 'tau:carriage=vir*gtau' --t t --lowpass 100 --derive --drop-edges 50 --decimate 10)
"$spml" import "$data/DATA_EMPS.mat" "${import[@]}" --out "$out/emps.h5"
"$spml" import "$data/DATA_EMPS_PULSES.mat" "${import[@]}" --split pulses:: --out "$out/emps_pulses.h5"
# One record: the last 30 % (in time) is held out for the selection; the whole record and the
# PULSES record are scored as cross-tests (the published figures are on the whole record).
"$spml" diagnose --model "$root/mjcf/emps.xml" --data "$out/emps.h5" --cross "$out/emps.h5" --cross "$out/emps_pulses.h5" --out "$out"
