#!/usr/bin/env bash
# Reproduces the paper's tables and prints them beside the published ones.
#   tools/reproduce.sh            quick: Toy (every learner incl. BNN rows, 5 repetitions) and SimDyn-Ll
#                                 (8 learners, 1000 of the 5000 training rows); ~4 min on 2 cores
#   tools/reproduce.sh --full     every scenario, every learner, 5 repetitions, all training rows
#                                 (the same units as tools/grid.sh --shards 4 --jobs 2, which ran them all
#                                 in 47 min on 2 cores, one BLAS thread per job; here they run one after
#                                 the other)
# Results go to out/ (datasets) and out/bench/<scenario>/ (results.csv, predictions.h5);
# an interrupted run continues where it stopped when started again.
set -euo pipefail
cd "$(dirname "$0")/.."
spml=build/bin/spml
mode=quick
for arg in "$@"; do
  case "$arg" in
    --full) mode=full ;;
    *) echo "reproduce.sh: unknown option '$arg'" >&2; exit 2 ;;
  esac
done
start=$(date +%s)
mkdir -p out/bench
results=()
bench() {   # scenario, then spml bench options
  local scenario=$1; shift
  [ -f "out/$scenario.h5" ] || "$spml" generate --scenario "$scenario" --out "out/$scenario.h5" --quiet
  "$spml" bench --data "out/$scenario.h5" --out "out/bench/$scenario-$mode" "$@"
  results+=(--results "out/bench/$scenario-$mode/results.csv")
}
if [ "$mode" = quick ]; then
  bench toy --learners all
  bench simdyn-ll --learners LLS,SVR,LLS-prior,LLS-simulated,GP,SPGP,LLS-GP,SVR-GP --train-max 1000
else
  for s in toy via-inst via-ar simdyn-ll simdyn-gl; do bench "$s" --learners all; done
fi
"$spml" compare "${results[@]}"
echo "reproduce.sh ($mode): total wall time $(( $(date +%s) - start )) s"
