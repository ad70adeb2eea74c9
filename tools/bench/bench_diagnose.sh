#!/usr/bin/env bash
# Diagnose timings (printed, not asserted): the 3-joint arm with its band and ripple
# (simdyn-gl: 5000 fit + 1000 test rows x 3 joints, every shipped plugin a candidate), and the
# Panda run undecimated (about 14 000 fit + 6 000 test rows x 7 joints) when ../shared is there.
# Usage: tools/bench/bench_diagnose.sh OUT
set -euo pipefail
out=${1:?usage: bench_diagnose.sh OUT}
root=$(cd "$(dirname "$0")/../.." && pwd)
spml=${SPML:-$root/build/bin/spml}
mkdir -p "$out"
"$spml" generate --scenario simdyn-gl --test-stride 50 --out "$out/arm.h5" > /dev/null
/usr/bin/time -f "arm 6000 x 3: %e s wall, %M KiB peak" "$spml" diagnose --model "$root/mjcf/planar_arm3.xml" --data "$out/arm.h5" \
  --test-split test_interp --out "$out/arm" --no-plots
data=${SPML_SHARED_DATA:-$root/../shared/data}/panda
if [ -f "$data/panda_nohand.xml" ]; then
  "$spml" import --text "$data/exciting_traj_positions.txt=q:joint{1..7}" --text "$data/exciting_traj_velocity.txt=qd:joint{1..7}" \
    --text "$data/exciting_traj_torques.txt=tau:joint{1..7}" --text "$data/exciting_traj_time.txt=t" \
    --x 'q:joint{1..7},qd:joint{1..7}' --y 'tau:joint{1..7}' --t t --lowpass 20 --derive --drop-edges 100 \
    --split train:0:70% --split test:70%: --out "$out/panda_full.h5" > /dev/null
  /usr/bin/time -f "panda 20000 x 7: %e s wall, %M KiB peak" "$spml" diagnose --model "$data/panda_nohand.xml" \
    --data "$out/panda_full.h5" --out "$out/panda" --no-plots 2>&1 | grep -v "^$\|WARNING"
else
  echo "panda: skipped, no $data/panda_nohand.xml (set SPML_SHARED_DATA)"
fi
