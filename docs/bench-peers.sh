#!/usr/bin/env bash
# Isoscope against the classic pipeline (VTK extraction + Embree casting, ../shared/peers) in
# the same run: ROUNDS alternating rounds of the peer script, then every configuration of
# every Isoscope binary given, with the peer's camera, 1024x1024, 2 threads, exact
# intersector. Prints per binary and configuration the median frame, rays/s and the median
# of the rounds' Isoscope/Embree ratios (min-max), and what a new isovalue costs the peer
# against one Isoscope frame. Nothing else should run meanwhile: compare ratios within a run.
#
# Usage: docs/bench-peers.sh grid VOLUME.nrrd ISO ROUNDS BINARY [BINARY...]
#        docs/bench-peers.sh tet MESH.vtu ISO ROUNDS BINARY [BINARY...]   (FIELD=name, default t1)
# Environment: PY (the peers' Python, default target/peers-venv/bin/python; made by
# ../shared/peers/setup.sh), PEERS (default ../shared/peers), OUT (default target/bench-peers),
# THREADS (2), SIZE (1024), FRAMES (11). Configurations: grids shaded and --depth-only; tets
# --normals faceted, --normals smooth and faceted --depth-only.
set -euo pipefail
KIND=$1 FILE=$2 ISO=$3 ROUNDS=$4
shift 4
BINS=("$@")
[ ${#BINS[@]} -gt 0 ] || { echo "usage: $0 grid|tet FILE ISO ROUNDS BINARY [BINARY...]" >&2; exit 2; }
PY=${PY:-target/peers-venv/bin/python} PEERS=${PEERS:-../shared/peers} OUT=${OUT:-target/bench-peers}
THREADS=${THREADS:-2} SIZE=${SIZE:-1024} FRAMES=${FRAMES:-11} FIELD=${FIELD:-t1}
mkdir -p "$OUT"
case $KIND in
  grid)
    PEER=("$PY" "$PEERS/iso_peer.py" "$FILE" --iso "$ISO")
    EXTRA=()
    CONFIGS=("shaded:" "depth-only:--depth-only") ;;
  tet)
    PEER=("$PY" "$PEERS/tet_peer.py" "$FILE" --field "$FIELD" --iso "$ISO")
    EXTRA=(--field "$FIELD")
    CONFIGS=("faceted:--normals faceted" "smooth:--normals smooth" "depth-only:--normals faceted --depth-only") ;;
  *) echo "$0: kind must be grid or tet, not '$KIND'" >&2; exit 2 ;;
esac
for i in $(seq 1 "$ROUNDS"); do
  echo "[bench-peers] round $i/$ROUNDS" >&2
  # The peer prints its record as the first line of its output.
  "${PEER[@]}" --threads "$THREADS" --size "$SIZE" --runs 3 --out "$OUT" | head -n 1 >"$OUT/peer_$i.json"
  for b in "${!BINS[@]}"; do
    for c in "${CONFIGS[@]}"; do
      name=${c%%:*} flags=${c#*:}
      # shellcheck disable=SC2086 # the configuration's flags are words
      "${BINS[$b]}" bench "$FILE" --iso "$ISO" "${EXTRA[@]}" $flags --camera "$OUT/camera.json" \
        --size "${SIZE}x${SIZE}" --threads "$THREADS" --skip-dda --skip-single --frames "$FRAMES" \
        --json >"$OUT/b${b}_${name}_$i.json"
    done
  done
done
names=$(printf '%s\n' "${CONFIGS[@]}" | cut -d: -f1 | tr '\n' ' ')
python3 - "$OUT" "$ROUNDS" "${#BINS[@]}" "$names" "${BINS[@]}" <<'PY'
import json, statistics as st, sys
out, rounds, nbins, names = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4].split()
bins = sys.argv[5:]
load = lambda f: json.load(open(f"{out}/{f}.json"))
peer = [load(f"peer_{i}") for i in range(1, rounds + 1)]
embree = [p["embree_rays_per_s"] for p in peer]
print(f"Embree: {st.median(embree) / 1e6:.2f} M rays/s (median of {rounds} rounds), "
      f"{peer[0]['triangles']} triangles, hit fraction {peer[0]['hit_fraction']:.2f}")
for b in range(nbins):
    for n in names:
        runs = [load(f"b{b}_{n}_{i}") for i in range(1, rounds + 1)]
        ms = [r["configs"][0]["median_ms"] for r in runs]
        ratio = [r["rays_per_second"] / e for r, e in zip(runs, embree)]
        change = [p["iso_change_ms"] / m for p, m in zip(peer, ms)]
        bare = [p["iso_change_no_upload_ms"] / m for p, m in zip(peer, ms)]
        print(f"{bins[b]} {n}: frame {st.median(ms):.2f} ms, "
              f"{st.median(r['rays_per_second'] for r in runs) / 1e6:.2f} M rays/s, "
              f"Isoscope/Embree {st.median(ratio):.2f}x ({min(ratio):.2f}-{max(ratio):.2f}); "
              f"new isovalue: peer / frame {st.median(change):.1f}x "
              f"({st.median(bare):.1f}x without upload)")
PY
