#!/usr/bin/env bash
# tools/grid.sh (GNU parallel, 2 shards) and the Slurm script's task/merge path give the
# numbers of one unsharded spml bench (every results.csv column but the fit times).
# Arguments: build dir, source dir, test learner dir. Exit 77 (skipped) without GNU parallel.
set -euo pipefail
build=$1 src=$2 fixtures=$3
command -v parallel > /dev/null || { echo "SKIPPED: GNU parallel is not installed (tools/install-deps.sh installs it)"; exit 77; }
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
export SPML="$build/bin/spml"
opts=(--learners LLS,GP,RandomFeatures --learner-path "$fixtures/random_features.so" --reps 2 --set max_evals=50)
"$src/tools/grid.sh" --shards 2 --jobs 2 --scenarios toy --data-dir "$tmp/data" --out "$tmp/grid" -- "${opts[@]}" > "$tmp/grid.log"
# grid.sh gives each job one BLAS thread; so does the reference run: a GP fit's last digits
# depend on how many threads share a BLAS reduction (seen: NLLH 8.24661 vs 8.2466 when ctest -j2
# left the reference two threads), and the sharding, not the threading, is what is compared.
OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 "$SPML" bench --data "$tmp/data/toy.h5" --out "$tmp/whole" "${opts[@]}" 2> /dev/null
strip() { cut -d, -f1-15,17- "$1"; }   # column 16 is fitsec
diff <(strip "$tmp/whole/results.csv") <(strip "$tmp/grid/toy/merged/results.csv")
[ "$(wc -l < "$tmp/whole/results.csv")" -eq 7 ] || { echo "expected 6 result rows"; exit 1; }
grep -q "toy_extrap_w_noise.csv" "$tmp/grid.log"   # spml compare ran on the merged results

# The Slurm job array's path: each task, then the merge job.
for t in 1 2; do
  SLURM_ARRAY_TASK_ID=$t SLURM_SUBMIT_DIR="$src" bash "$src/tools/slurm/grid.sbatch" --shards 2 --scenarios toy \
    --data-dir "$tmp/data" --out "$tmp/slurm" -- "${opts[@]}" > /dev/null
done
SLURM_SUBMIT_DIR="$src" bash "$src/tools/slurm/grid.sbatch" --merge-only --shards 2 --scenarios toy --data-dir "$tmp/data" \
  --out "$tmp/slurm" -- "${opts[@]}" > /dev/null
diff <(strip "$tmp/whole/results.csv") <(strip "$tmp/slurm/toy/merged/results.csv")
echo "grid and Slurm paths match the unsharded run"
