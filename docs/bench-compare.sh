#!/usr/bin/env bash
# Same-run comparison of two isoscope binaries (a change against its parent), on the CT-like
# phantom (skin, bone) and Marschner-Lobb 256^3 f32 at 1024x1024, 2 threads, exact
# intersector. Runs alternate OLD, NEW, OLD, NEW, ... so drift in machine load hits both; each
# row reports the medians over the pairs and the median of the per-pair NEW/OLD ratios.
# Also renders the same views with both binaries and compares the depth images byte by byte.
#
# Usage: docs/bench-compare.sh OLD_BINARY NEW_BINARY [PAIRS]   (PAIRS default 5)
# Environment: THREADS (default 2), SIZE (default 1024x1024), FRAMES (default 5).
set -euo pipefail
OLD=$1 NEW=$2 PAIRS=${3:-5}
THREADS=${THREADS:-2} SIZE=${SIZE:-1024x1024} FRAMES=${FRAMES:-5}
WORK=$(mktemp -d "${TMPDIR:-/tmp}/bench-compare.XXXXXX")
trap 'rm -rf "$WORK"' EXIT
log() { echo "[bench-compare] $*" >&2; }

"$NEW" generate phantom -o "$WORK/phantom.nrrd" >&2
"$NEW" generate marschner-lobb --size 256 -o "$WORK/ml256.nrrd" >&2
CASES=("phantom-skin $WORK/phantom.nrrd -300" "phantom-bone $WORK/phantom.nrrd 500" "ml256 $WORK/ml256.nrrd 0.5")

for c in "${CASES[@]}"; do
  read -r name file iso <<<"$c"
  for bin in OLD NEW; do
    b=${!bin}
    "$b" render "$file" --iso "$iso" --size "$SIZE" --depth-out "$WORK/$name-$bin.npy" \
      -o "$WORK/$name-$bin.png" >/dev/null 2>&1
  done
  if cmp -s "$WORK/$name-OLD.npy" "$WORK/$name-NEW.npy"; then
    echo "$name identical" >>"$WORK/depth.txt"
  else
    echo "$name DIFFERENT" >>"$WORK/depth.txt"
  fi
  for i in $(seq 1 "$PAIRS"); do
    for bin in OLD NEW; do
      log "$name pair $i $bin"
      "${!bin}" bench "$file" --iso "$iso" --size "$SIZE" --frames "$FRAMES" --threads "$THREADS" \
        --skip-dda --json >"$WORK/$name-$bin-$i.json"
    done
  done
done

python3 - "$WORK" "$PAIRS" "$SIZE" "$THREADS" "$FRAMES" <<'PY'
import json, statistics as st, sys
work, pairs, size, threads, frames = sys.argv[1], int(sys.argv[2]), *sys.argv[3:]
depth = dict(l.split() for l in open(f"{work}/depth.txt"))
print(f"{pairs} alternating pairs, {size}, {threads} threads, median of {frames} frames per run, exact intersector.")
print()
print("| view | config | old ms/frame | new ms/frame | new / old (median of pairs) | old Mrays/s | new Mrays/s | depth image |")
print("|---|---|---:|---:|---:|---:|---:|---|")
for name in ("phantom-skin", "phantom-bone", "ml256"):
    runs = [(json.load(open(f"{work}/{name}-OLD-{i}.json")), json.load(open(f"{work}/{name}-NEW-{i}.json")))
            for i in range(1, pairs + 1)]
    for cfg in [c["name"] for c in runs[0][0]["configs"]]:
        get = lambda r: next(c for c in r["configs"] if c["name"] == cfg)
        o = [get(a)["median_ms"] for a, _ in runs]
        n = [get(b)["median_ms"] for _, b in runs]
        ro = [get(a)["rays_per_second"] / 1e6 for a, _ in runs]
        rn = [get(b)["rays_per_second"] / 1e6 for _, b in runs]
        ratio = st.median(y / x for x, y in zip(o, n))
        print(f"| {name} | {cfg} | {st.median(o):.1f} | {st.median(n):.1f} | {ratio:.3f}× | "
              f"{st.median(ro):.2f} | {st.median(rn):.2f} | {depth[name]} |")
PY
