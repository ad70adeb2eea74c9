#!/usr/bin/env bash
# Installs spml's development package into a temporary prefix, builds the out-of-tree
# example learner (learners/examples/ridge) against it with its own CMake project, and runs
# it through `spml check-plugin` and `spml bench`: its Toy interpolation RMSE must equal LLS's (lambda ~ 0).
set -euo pipefail
build_dir=$1 source_dir=$2 spml=$3
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cmake --install "$build_dir" --component spml_dev --prefix "$work/prefix" >/dev/null
cmake -S "$source_dir/learners/examples/ridge" -B "$work/ridge" -DCMAKE_PREFIX_PATH="$work/prefix" >/dev/null
cmake --build "$work/ridge" >/dev/null
# The contract suite first: the example keeps every promise of the learner ABI.
"$spml" check-plugin "$work/ridge/ridge_learner.so"
"$spml" generate --scenario toy --out "$work/toy.h5" --quiet
"$spml" bench --data "$work/toy.h5" --out "$work/bench" --learner-path "$work/ridge/ridge_learner.so" \
  --learners Ridge,LLS,Ridge-GP --reps 1 2>/dev/null
rmse() { awk -F, -v a="$1" 'NR == 1 {for (i = 1; i <= NF; i++) c[$i] = i; next}   # columns by name
  $c["split"] == "test_interp" && $c["algo"] == a {print $c["rmsemean"]}' "$work/bench/results.csv"; }
ridge=$(rmse Ridge) lls=$(rmse LLS) ridge_gp=$(rmse Ridge-GP)
echo "Ridge $ridge  LLS $lls  Ridge-GP $ridge_gp"
awk -v r="$ridge" -v l="$lls" -v g="$ridge_gp" 'BEGIN {
  if (r == "" || l == "" || g == "") { print "missing rows in results.csv"; exit 1 }
  if ((r - l) > 1e-3 || (l - r) > 1e-3) { print "Ridge differs from LLS"; exit 1 }
  if (g > 0.56) { print "Ridge-GP interpolation above the noise-level bound 0.56"; exit 1 }
}'
