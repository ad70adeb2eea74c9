#!/usr/bin/env bash
# spml plot draws every figure as a real image: PNG and PDF per figure, each PNG decodes to
# a picture with drawn content (not a blank canvas), and bad input is refused by name.
# Arguments: spml binary, a toy dataset is generated into a temporary folder.
set -euo pipefail
spml=$1
/usr/bin/python3 -c "import matplotlib" 2> /dev/null || { echo "SKIPPED: /usr/bin/python3 has no matplotlib (tools/install-deps.sh installs python3-matplotlib)"; exit 77; }
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
"$spml" generate --scenario toy --out "$tmp/toy.h5" --quiet
"$spml" bench --data "$tmp/toy.h5" --out "$tmp/b" --learners LLS,GP,LLS-GP --reps 2 --set max_evals=60 2> /dev/null > /dev/null
"$spml" plot --results "$tmp/b/results.csv" --predictions "$tmp/b/predictions.h5" --out "$tmp/fig" > "$tmp/list"
for name in table_toy_test_interp_0 table_toy_test_extrap_0 pred_toy_test_interp_0 pred_toy_test_extrap_0 \
            residual_toy_test_interp_0 residual_toy_test_extrap_0; do
  for ext in png pdf; do
    grep -qx "$tmp/fig/$name.$ext" "$tmp/list" || { echo "missing $name.$ext in the list spml plot printed"; cat "$tmp/list"; exit 1; }
  done
  head -c 4 "$tmp/fig/$name.pdf" | grep -q "%PDF" || { echo "$name.pdf is not a PDF"; exit 1; }
  /usr/bin/python3 - "$tmp/fig/$name.png" <<'PY'
import sys
import matplotlib.image as mpimg
img = mpimg.imread(sys.argv[1])           # fails unless a valid PNG
h, w = img.shape[:2]
drawn = (img[..., :3].min(axis=2) < 0.9).mean()   # share of pixels that are not (near) white
assert h >= 300 and w >= 600, f"{sys.argv[1]}: {w}x{h} pixels"
assert drawn > 0.02, f"{sys.argv[1]}: only {drawn:.1%} of the pixels drawn"
PY
done
ls "$tmp/fig" | grep -q "tmp-" && { echo "temporary files left"; exit 1; }
# Every figure's axes are labelled and its x data are what the label says (Toy: the input x,
# VIA: time stamps in s, the output named tau:link [N·m]); the diagnose figures too.
"$spml" generate --scenario via-inst --out "$tmp/via.h5" --quiet > /dev/null
"$spml" bench --data "$tmp/via.h5" --out "$tmp/s" --learners LLS,LLS-prior --reps 1 --test-max 1000 --quiet > /dev/null
here=$(cd "$(dirname "$0")" && pwd)
SPML_PUBLISHED="$here/../data/published" /usr/bin/python3 "$here/python/test_figures.py" "$here/../tools/plots" "$tmp/b" "$tmp/s"
# A results.csv of schema 1 (spml before outputs were named) is still drawn, its outputs by index.
cut -d, -f1-3,6- "$tmp/b/results.csv" | sed '1s/.*/scenario,split,output,algo,rmsemean,rmsestd,rmsemin,rmsemax,nllhmean,nllhstd,nllhmin,nllhmax,fits,fitsec,warnings/' \
  | awk -F, 'BEGIN {OFS = ","} NR > 1 {$3 = 0} {print}' > "$tmp/v1.csv"
"$spml" plot --results "$tmp/v1.csv" --out "$tmp/fig1" > "$tmp/list1"
grep -q "table_toy_test_interp_0.png" "$tmp/list1" || { echo "schema-1 results not drawn"; cat "$tmp/list1"; exit 1; }
# Bad input is named.
echo "not,a,results,file" > "$tmp/bad.csv"
if out=$("$spml" plot --results "$tmp/bad.csv" --out "$tmp/fig2" 2>&1); then echo "accepted a bad results.csv"; exit 1; fi
grep -q "bad.csv" <<<"$out" || { echo "error does not name the file: $out"; exit 1; }
echo "all figures drawn"
