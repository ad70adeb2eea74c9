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
# Issue #22: the same arm measured as a real log (PD forward simulation, 6 s at 1 kHz, 1 %
# torque noise, 18-bit encoders, a 4 ms torque delay, LuGre friction on joint1), 6000 rows x 3
# after the import: the delay search, the stateful fits by simulation and the unexplained GPs.
sed 's#</mujoco>#<custom><text name="spml.plugin.lugre" data="type=stick_slip joints=joint1 fc=4 fs=6 vs=0.1 sigma0=2000 sigma1=5 sigma2=0"/></custom></mujoco>#' \
  "$root/mjcf/planar_arm3.xml" > "$out/arm_lugre.xml"
"$spml" generate --model "$out/arm_lugre.xml" --duration 6.6 --seed 5 --out "$out/arm_lugre.csv" > /dev/null
/usr/bin/python3 - "$out/arm_lugre.csv" <<'PY'
import sys, csv
rows = list(csv.reader(open(sys.argv[1])))
head, body = rows[0], rows[1:]
tau = [i for i, n in enumerate(head) if n.startswith("tau:")]
late = [list(r) for r in body]
for k in range(len(body)):            # the torque log reads the command of 4 ticks before
    for i in tau: late[k][i] = body[max(0, k - 4)][i]
csv.writer(open(sys.argv[1], "w", newline="")).writerows([head] + late)
PY
"$spml" import "$out/arm_lugre.csv" --t t --x 'q:joint0,q:joint1,q:joint2' --y 'tau:joint0,tau:joint1,tau:joint2' \
  --lowpass 20 --derive --drop-edges 300 --out "$out/arm_lugre.h5" > /dev/null
/usr/bin/time -f "arm 6000 x 3, delay + LuGre: %e s wall, %M KiB peak" "$spml" diagnose --model "$root/mjcf/planar_arm3.xml" \
  --data "$out/arm_lugre.h5" --out "$out/arm_lugre" --no-plots 2>&1 | grep -v "^$\|WARNING"
# The same on one thread (the shipped plugins' simulations run on the cores otherwise): the
# report must be the same, timings aside.
/usr/bin/time -f "arm 6000 x 3, delay + LuGre, --threads 1: %e s wall, %M KiB peak" "$spml" diagnose --model "$root/mjcf/planar_arm3.xml" \
  --data "$out/arm_lugre.h5" --out "$out/arm_lugre_1" --no-plots --threads 1 2>&1 | grep -v "^$\|WARNING"
/usr/bin/python3 - "$out/arm_lugre/report.json" "$out/arm_lugre_1/report.json" <<'PY'
import json, sys
a, b = (json.load(open(f)) for f in sys.argv[1:])
for r in (a, b):
    r.pop("timings_s", None)   # wall times, the consistent fit's of `parameters` too
    for c in r.get("causes", []):
        if isinstance(c.get("written"), dict): c["written"].pop("seconds", None)
print("report.json on the cores and on one thread:", "identical (timings aside)" if a == b else "DIFFERENT")
PY
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
