#!/usr/bin/env bash
# Franka Panda (a real 7-joint excitation run with joint torque sensors, Gaz et al. 2019) and
# the MuJoCo Menagerie model: import, diagnose, leave OUT/report.json. Usage: tools/examples/panda.sh OUT
# Data: $SPML_SHARED_DATA/panda (default ../shared/data next to the project), never copied.
set -euo pipefail
out=${1:?usage: panda.sh OUT}
root=$(cd "$(dirname "$0")/../.." && pwd)
spml=${SPML:-$root/build/bin/spml}
data=${SPML_SHARED_DATA:-$root/../shared/data}/panda
[ -f "$data/panda_nohand.xml" ] || { echo "panda.sh: no $data/panda_nohand.xml (set SPML_SHARED_DATA)" >&2; exit 1; }
mkdir -p "$out"
# Logs hold 7 values per sample at uneven steps: resampled to the median step, 20 Hz zero-phase
# low-pass, accelerations by central differences, 100 edge samples dropped, every 5th kept;
# the first 70 % (in time) to fit, the rest held out.
"$spml" import --text "$data/exciting_traj_positions.txt=q:joint{1..7}" --text "$data/exciting_traj_velocity.txt=qd:joint{1..7}" \
  --text "$data/exciting_traj_torques.txt=tau:joint{1..7}" --text "$data/exciting_traj_time.txt=t" \
  --x 'q:joint{1..7},qd:joint{1..7}' --y 'tau:joint{1..7}' --t t --lowpass 20 --derive --drop-edges 100 --decimate 5 \
  --split train:0:70% --split test:70%: --out "$out/panda.h5"
"$spml" diagnose --model "$data/panda_nohand.xml" --data "$out/panda.h5" --out "$out"
