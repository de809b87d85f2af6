#!/bin/sh
# Minimises corpus-work/<target> into the committed corpus/<target> (libFuzzer -merge=1, as
# `cargo fuzz cmin` does, keeping edge coverage only: -use_counters=0 drops the hit-count
# buckets, which would keep ~3x more files for the same edges). Run from formats/fuzz or
# app/fuzz after run_campaign.sh: ./cmin.sh TARGET...
set -eu
bin=target/x86_64-unknown-linux-gnu/release
mkdir -p logs
for t in "$@"; do
    case $t in
        isot) len=32768 ;;
        dicom) len=16384 ;;
        camera_json | session_json) len=2048 ;;
        *) len=4096 ;;
    esac
    rm -rf corpus/"$t"
    mkdir -p corpus/"$t"
    nice -n 15 "$bin/$t" -merge=1 -use_counters=0 -max_len=$len corpus/"$t" corpus-work/"$t" \
        > logs/cmin-"$t".log 2>&1
    echo "$t: $(ls corpus-work/"$t" | wc -l) -> $(ls corpus/"$t" | wc -l) files, $(du -sb corpus/"$t" | cut -f1) bytes"
done
