#!/usr/bin/env bash
# spml check-plugin over every library spml ships (learners and force plugins): all must
# pass. Prints the suite's wall time (issue #25: at most 60 s on the 2-core reference machine).
set -euo pipefail
spml=$1 learner_dir=$2 plugin_dir=$3
libs=("$learner_dir"/*.so "$plugin_dir"/*.so)
start=$(date +%s.%N)
# BNN and BaMbANN train 300 steps instead of 3000: the clauses check promises, not fit quality,
# and with 3000 their four fits took 56 s of CPU (measured), most of the suite.
# The sanitizer preset builds without LibTorch: no library has the key there, and --set refuses
# a key nobody has.
set_steps=()
[[ -e "$learner_dir/spml_learners_torch.so" ]] && set_steps=(--set steps=300)
"$spml" check-plugin "${set_steps[@]}" "${libs[@]}"
end=$(date +%s.%N)
awk -v a="$start" -v b="$end" -v n="${#libs[@]}" 'BEGIN { printf "check-plugin over %d in-tree libraries: %.1f s wall\n", n, b - a }'
