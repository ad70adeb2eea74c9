# Sourced by the out-of-tree tests (out_of_tree_learner.sh, out_of_tree_force_plugin.sh) with
# their arguments BUILD_DIR SOURCE_DIR SPML: installs spml's development package into a
# temporary prefix and provides what both need.
set -euo pipefail
build_dir=$1 source_dir=$2 spml=$3
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cmake --install "$build_dir" --component spml_dev --prefix "$work/prefix" >/dev/null

# build_example SOURCE_SUBDIR NAME: configures and builds an example's own CMake project
# against the installed package, into $work/NAME.
build_example() {
  cmake -S "$source_dir/$1" -B "$work/$2" -DCMAKE_PREFIX_PATH="$work/prefix" >/dev/null
  cmake --build "$work/$2" >/dev/null
}

# rmse RESULTS_CSV SPLIT ALGO: the rmsemean of that row of a results.csv, columns found by
# their header names (any results schema).
rmse() {
  awk -F, -v s="$2" -v a="$3" 'NR == 1 {for (i = 1; i <= NF; i++) c[$i] = i; next}
    $c["split"] == s && $c["algo"] == a {print $c["rmsemean"]}' "$1"
}
