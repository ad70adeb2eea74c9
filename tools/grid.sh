#!/usr/bin/env bash
# Runs spml bench as N shards per scenario with GNU parallel on this machine, merges each
# scenario's shards into one folder (identical to an unsharded run) and prints spml compare.
#
#   tools/grid.sh [--shards N] [--jobs J] [--out DIR] [--data-dir DIR] [--scenarios "toy via-inst ..."]
#                 [-- BENCH OPTIONS]
#
# Defaults: every paper scenario, N = 4 shards each, J = number of cores, --out out/grid,
# datasets in --data-dir out (relative paths are taken from the repository root).
# Each job gets one BLAS thread (J jobs already fill the cores). Options after -- go to every
# spml bench (default: --learners all). Datasets missing from the data folder are generated. A
# stopped grid continues where it stopped: finished units are reused.
# The grid's jobs are numbered 1 .. (scenarios x N), scenario-major:
#   --task I      runs job I only (what each GNU parallel job and each Slurm array task runs)
#   --merge-only  merges and compares what the jobs left (the last step, also on Slurm)
# tools/slurm/grid.sbatch runs the same jobs as a Slurm job array.
set -euo pipefail
self=$(realpath "$0")   # the jobs call this script again, after the cd below
cd "${SPML_ROOT:-$(dirname "$self")/..}"
spml=${SPML:-build/bin/spml}
shards=4
jobs=$(nproc)
out=out/grid
data_dir=out
scenarios="toy via-inst via-ar simdyn-ll simdyn-gl"
task=""
merge_only=0
bench_options=()
while [ $# -gt 0 ]; do
  case "$1" in
    --shards) shards=$2; shift 2 ;;
    --jobs) jobs=$2; shift 2 ;;
    --out) out=$2; shift 2 ;;
    --data-dir) data_dir=$2; shift 2 ;;
    --scenarios) scenarios=$2; shift 2 ;;
    --task) task=$2; shift 2 ;;
    --merge-only) merge_only=1; shift ;;
    --) shift; bench_options=("$@"); break ;;
    *) echo "grid.sh: unknown option '$1' (see the comment at the top of $0)" >&2; exit 2 ;;
  esac
done
[ ${#bench_options[@]} -gt 0 ] || bench_options=(--learners all)
[ -x "$spml" ] || { echo "grid.sh: $spml not found: build first (tools/build.sh)" >&2; exit 1; }
read -r -a scenario_list <<< "$scenarios"
total=$(( ${#scenario_list[@]} * shards ))

run_task() {   # job number 1..total -> one spml bench --shard
  local i=$(( $1 - 1 ))
  [ "$i" -ge 0 ] && [ "$i" -lt "$total" ] || { echo "grid.sh: --task $1 is not in 1..$total" >&2; exit 2; }
  local s=${scenario_list[$(( i / shards ))]} k=$(( i % shards + 1 ))
  local dir="$out/$s/shard-$k"
  mkdir -p "$dir"
  # The first job of a scenario that finds no dataset writes it; the others wait on the lock.
  flock "$data_dir/.generate.lock" \
    bash -c "[ -f '$data_dir/$s.h5' ] || '$spml' generate --scenario '$s' --out '$data_dir/$s.h5' --quiet"
  if OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 "$spml" bench --data "$data_dir/$s.h5" --out "$dir" --shard "$k/$shards" \
       "${bench_options[@]}" > "$dir/bench.log" 2>&1; then
    echo "grid: $s shard $k/$shards done"
  else
    echo "grid: $s shard $k/$shards FAILED, see $dir/bench.log" >&2
    tail -3 "$dir/bench.log" >&2
    exit 1
  fi
}

mkdir -p "$out" "$data_dir"
if [ -n "$task" ]; then
  run_task "$task"
  exit 0
fi
start=$(date +%s)
if [ "$merge_only" = 0 ]; then
  command -v parallel > /dev/null || { echo "grid.sh: GNU parallel is missing (tools/install-deps.sh installs it)" >&2; exit 1; }
  forward=(--shards "$shards" --out "$out" --data-dir "$data_dir" --scenarios "$scenarios" -- "${bench_options[@]}")
  seq 1 "$total" | parallel --halt now,fail=1 -j "$jobs" --line-buffer "$self" --task {} "${forward[@]@Q}"
fi
# merge loads the same learner and force-plugin libraries as the shards did.
merge_paths=()
for ((i = 0; i < ${#bench_options[@]}; ++i)); do
  case "${bench_options[$i]}" in
    --learner-path|--plugin-path) merge_paths+=("${bench_options[$i]}" "${bench_options[$((i + 1))]}") ;;
    --learner-path=*|--plugin-path=*) merge_paths+=("${bench_options[$i]}") ;;
  esac
done
results=()
for s in "${scenario_list[@]}"; do
  shard_dirs=()
  for k in $(seq 1 "$shards"); do shard_dirs+=("$out/$s/shard-$k"); done
  "$spml" merge "${shard_dirs[@]}" --out "$out/$s/merged" "${merge_paths[@]}" 2> "$out/$s/merge.log" ||
    { echo "grid.sh: merging $s failed, see $out/$s/merge.log" >&2; tail -2 "$out/$s/merge.log" >&2; exit 1; }
  results+=(--results "$out/$s/merged/results.csv")
done
"$spml" compare "${results[@]}"
echo "grid: ${#scenario_list[@]} scenario(s) x $shards shards, wall time $(( $(date +%s) - start )) s"
