#!/bin/sh
# Runs fuzz targets one after another (one core), each for RUNS executions, from the seeds
# into corpus-work/<target> (git-ignored), logging to logs/<target>.log. Usage, from
# formats/fuzz (app/fuzz for session_json):
#   ./run_campaign.sh [RUNS] TARGET...
# MAX_TIME (seconds, default 900) caps each target's run; the log says how many runs it did.
# Then minimise into the committed corpus:
#   cargo +nightly fuzz cmin -s none -a TARGET corpus/TARGET   (after copying corpus-work)
set -eu
runs=${1:-10000000}
max_time=${MAX_TIME:-900}
shift
mesh=../tests/data/mesh
mkdir -p logs corpus-work
# Build once, then run the binaries directly: a reader fixed mid-campaign does not trigger a
# rebuild in front of every later target (what `cargo fuzz run` would do).
nice -n 15 cargo +nightly fuzz build -s none -a > logs/build.log 2>&1
bin=target/x86_64-unknown-linux-gnu/release
for t in "$@"; do
    w=corpus-work/$t
    mkdir -p "$w"
    case $t in
        nrrd_header) cp corpus-seed/* "$w"/; len=4096 ;;
        # corpus-seed and seeds/nrrd_data share names: prefix the header-only seeds
        nrrd_data) for f in corpus-seed/*; do cp "$f" "$w/hdr_${f##*/}"; done; cp seeds/nrrd_data/* "$w"/; len=4096 ;;
        vtk_legacy) cp $mesh/*.vtk "$w"/; len=4096 ;;
        vtu) cp $mesh/*.vtu $mesh/series/*.vtu "$w"/; len=4096 ;;
        gmsh) cp $mesh/*.msh "$w"/; len=4096 ;;
        isot) cp seeds/isot/* "$w"/; len=32768 ;;
        dicom) cp seeds/dicom/* "$w"/; len=16384 ;;
        camera_json | session_json) cp seeds/$t/* "$w"/; len=2048 ;;
        *) cp seeds/$t/* "$w"/; len=4096 ;;
    esac
    [ -d "corpus/$t" ] && cp corpus/"$t"/* "$w"/ 2>/dev/null || true
    start=$(date +%s)
    status=0
    mkdir -p artifacts/"$t"
    nice -n 15 "$bin/$t" -artifact_prefix=artifacts/"$t"/ "$w" \
        -runs="$runs" -max_total_time="$max_time" -max_len=$len -rss_limit_mb=512 -timeout=10 -print_final_stats=1 \
        > logs/"$t".log 2>&1 || status=$?
    echo "$t: exit $status, $(( $(date +%s) - start )) s wall, $(grep -Eo 'Done [0-9]+ runs in [0-9]+ second\(s\)|stat::number_of_executed_units: *[0-9]+|stat::average_exec_per_sec: *[0-9]+' logs/"$t".log | tr '\n' ' ')" >> logs/summary.txt
done
