#!/usr/bin/env bash
# Installs spml's development package into a temporary prefix, builds the out-of-tree
# example learner (learners/examples/ridge) against it with its own CMake project, and runs
# it through `spml check-plugin` and `spml bench`: its Toy interpolation RMSE must equal LLS's (lambda ~ 0).
source "$(dirname "$0")/out_of_tree_common.sh" "$@"
build_example learners/examples/ridge ridge
# The contract suite first: the example keeps every promise of the learner ABI.
"$spml" check-plugin "$work/ridge/ridge_learner.so"
"$spml" generate --scenario toy --out "$work/toy.h5" --quiet
"$spml" bench --data "$work/toy.h5" --out "$work/bench" --learner-path "$work/ridge/ridge_learner.so" \
  --learners Ridge,LLS,Ridge-GP --reps 1 2>/dev/null
r="$work/bench/results.csv"
ridge=$(rmse "$r" test_interp Ridge) lls=$(rmse "$r" test_interp LLS) ridge_gp=$(rmse "$r" test_interp Ridge-GP)
echo "Ridge $ridge  LLS $lls  Ridge-GP $ridge_gp"
awk -v r="$ridge" -v l="$lls" -v g="$ridge_gp" 'BEGIN {
  if (r == "" || l == "" || g == "") { print "missing rows in results.csv"; exit 1 }
  if ((r - l) > 1e-3 || (l - r) > 1e-3) { print "Ridge differs from LLS"; exit 1 }
  if (g > 0.56) { print "Ridge-GP interpolation above the noise-level bound 0.56"; exit 1 }
}'
