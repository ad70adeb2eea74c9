#!/usr/bin/env bash
# Installs the whole of spml (binary, libraries, force and learner plugins, headers, MJCF
# models, the paper's tables, the CMake package) into a temporary prefix, moves the prefix
# elsewhere, and uses it with no SPML_* variables set: everything must be found relative to
# the installed binary, and nothing may point back into the build or source tree.
set -euo pipefail
build_dir=$(cd "$1" && pwd) source_dir=$(cd "$2" && pwd)
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cmake --install "$build_dir" --prefix "$work/prefix" >/dev/null
mv "$work/prefix" "$work/moved"
p="$work/moved"
run() { env -u SPML_PLUGIN_PATH -u SPML_LEARNER_PATH -u SPML_MJCF_DIR -u SPML_SHARE_DIR "$@"; }
for f in bin/spml include/spml/learner.h include/spml/force_plugin.h include/spml/abi.h \
         share/spml/mjcf/planar_arm3_ll.xml share/spml/published/tables.csv lib/cmake/spml/spmlConfig.cmake; do
  [ -e "$p/$f" ] || { echo "not installed: $f"; exit 1; }
done
listing=$(run "$p/bin/spml" learners; run "$p/bin/spml" plugins)
# Here-strings, not `echo | grep -q`: under pipefail grep's early exit at the first match can
# kill echo's later writes with SIGPIPE, and the step fails now and then (3 of about 30 full
# runs of the suite, 1.5 s in, where the listing is read).
grep -q "LLS" <<<"$listing" || { echo "no learners found:"; echo "$listing"; exit 1; }
grep -q "friction_band" <<<"$listing" || { echo "no force plugins found:"; echo "$listing"; exit 1; }
if echo "$listing" | grep -e "$build_dir" -e "$source_dir"; then echo "paths into the build/source tree"; exit 1; fi
# SimDyn-Ll needs the shipped MJCF and the friction_band plugin; bench needs the learners
# and, through compare, the paper's tables.
run "$p/bin/spml" generate --scenario simdyn-ll --test-stride 50 --out "$work/arm.h5" --quiet >/dev/null
run "$p/bin/spml" generate --scenario toy --out "$work/toy.h5" --quiet >/dev/null
run "$p/bin/spml" bench --data "$work/toy.h5" --out "$work/bench" --learners LLS,GP --reps 1 2>/dev/null >/dev/null
# (Captured first, for the same reason.)
compared=$(run "$p/bin/spml" compare --results "$work/bench/results.csv")
grep -q "toy_interp_w_noise.csv" <<<"$compared" || { echo "compare does not list toy_interp_w_noise.csv:"; echo "$compared"; exit 1; }
# No RUNPATH and no string constant (.rodata) of an installed binary names the build or
# source tree (debug information may, and is not looked at).
for f in "$p/bin/spml" $(find "$p/lib" -name '*.so'); do
  if readelf -d "$f" | grep -F -e "$build_dir" -e "$source_dir"; then echo "$f: RUNPATH into the build tree"; exit 1; fi
  objcopy -O binary --only-section=.rodata "$f" "$work/rodata" 2>/dev/null || continue
  # (a sanitizer build keeps source file names for its reports: those are no look-up paths)
  if strings "$work/rodata" | grep -F -e "$build_dir" -e "$source_dir" | grep -vE '\.(cc|c|h|hpp)$'; then
    echo "$f: a string names the build or source tree"; exit 1
  fi
done
echo "installed, moved and used: OK"
