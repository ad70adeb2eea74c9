#!/usr/bin/env bash
# The force-plugin kit end to end: installs spml's development package into a temporary prefix,
# builds the out-of-tree example effect (plugins/examples/cubic_damping) against it with its own
# CMake project, lists it with `spml plugins`, and scores an MJCF that declares it on data whose
# torque is exactly that effect plus the link's inertia: tau = 0.02*qdd + c*qd^3 for one hinge
# with no gravity (inverse dynamics: tau = M*qdd + bias - passive, passive = -c*qd^3). With the
# plugin declared the model's error is at rounding level; without it, it misses c*qd^3. regressor
# and identify find the plugin through --plugin-path and identify recovers c.
source "$(dirname "$0")/out_of_tree_common.sh" "$@"
build_example plugins/examples/cubic_damping effect
lib="$work/effect/spml_force_cubic_damping.so"

"$spml" plugins --plugin-path "$lib" > "$work/plugins.txt"
grep -q "cubic_damping" "$work/plugins.txt" || { echo "spml plugins does not list cubic_damping:"; cat "$work/plugins.txt"; exit 1; }

model() {   # $1: the plugin declaration (empty for none)
  cat <<XML
<mujoco model="cubic">
  <option gravity="0 0 0"/>
  <custom>$1</custom>
  <worldbody>
    <body name="arm"><joint name="j" type="hinge" axis="0 0 1"/>
      <inertial pos="0.1 0 0" mass="1" diaginertia="0.01 0.01 0.01"/></body>
  </worldbody>
</mujoco>
XML
}
model '<text name="spml.plugin.seal" data="type=cubic_damping joints=j c=0.7"/>' > "$work/with.xml"
model '' > "$work/without.xml"

/usr/bin/python3 - "$work/data.h5" <<'PY'
import sys, h5py, numpy as np
rng = np.random.default_rng(3)
f = h5py.File(sys.argv[1], "w")
f.attrs["format"] = "spml/1"
for split, n in (("train", 200), ("test", 100)):
    q, qd = rng.uniform(-3, 3, n), rng.uniform(-2, 2, n)
    g = f.create_group(split)
    qdd = rng.uniform(-5, 5, n)
    X = np.stack([q, qd, qdd], axis=1)
    g.create_dataset("X", data=X).attrs["columns"] = "q:j,qd:j,qdd:j"
    # inertia about the hinge: 0.01 + 1 kg * (0.1 m)^2 = 0.02
    g.create_dataset("Y", data=(0.02 * qdd + 0.7 * qd**3)[:, None]).attrs["columns"] = "tau:j"
PY

"$spml" bench --data "$work/data.h5" --out "$work/with" --model "$work/with.xml" --plugin-path "$lib" \
  --learners LLS-prior --reps 1 >/dev/null 2>&1
"$spml" bench --data "$work/data.h5" --out "$work/without" --model "$work/without.xml" --plugin-path "$lib" \
  --learners LLS-prior --reps 1 >/dev/null 2>&1
# regressor and identify find the plugin too: its column seal.c joins the base parameters and
# identify recovers c = 0.7 from the data of the model without the declaration's value.
"$spml" regressor --model "$work/with.xml" --plugin-path "$lib" --json > "$work/regressor.json"
/usr/bin/python3 - "$work/regressor.json" <<'PY'
import json, sys
names = json.load(open(sys.argv[1]))["names"]
assert any("seal" in n or "j.c" in n for n in names), f"no cubic-damping base parameter in {names}"
PY
"$spml" identify --model "$work/with.xml" --data "$work/data.h5" --plugin-path "$lib" --json > "$work/identify.json"
/usr/bin/python3 - "$work/identify.json" <<'PY'
import json, sys
j = json.load(open(sys.argv[1]))
c = [e for n, e in zip(j["names"], j["estimate"]) if n.endswith(".c")]
assert len(c) == 1 and abs(c[0] - 0.7) < 1e-9, f"identify: c = {c} (names {j['names']})"
print(f"identify --plugin-path: c = {c[0]:.12g} (true 0.7)")
PY
with=$(rmse "$work/with/results.csv" test LLS-prior) without=$(rmse "$work/without/results.csv" test LLS-prior)
echo "LLS-prior test RMSE: with the plugin declared $with, without $without"
awk -v w="$with" -v wo="$without" 'BEGIN {
  if (w == "" || wo == "") { print "missing rows in results.csv"; exit 1 }
  if (w > 1e-9) { print "the declared plugin does not reproduce tau = 0.02*qdd + c*qd^3"; exit 1 }
  if (wo < 1) { print "without the plugin the model should miss c*qd^3"; exit 1 }
}'
