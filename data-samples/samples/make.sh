#!/bin/sh
# Regenerates the committed samples in this directory (see README.md for what each one is).
# Run from anywhere: sh data-samples/samples/make.sh
# `data-samples/tests/committed_samples.rs` checks that these files still equal what the
# generators produce; rerun this script after changing a generator on purpose.
set -eu
here=$(cd "$(dirname "$0")" && pwd)
cd "$here/../.."
cargo build --release -q -p isoscope
isoscope=target/release/isoscope
out=data-samples/samples

$isoscope generate marschner-lobb --size 41 --type u8 --encoding raw --force -o "$out/ml41_u8.nrrd"
$isoscope generate sphere --size 32 --type f32 --encoding gzip --force -o "$out/sphere32_f32.nrrd"
$isoscope generate torus --size 32 --type u8 --encoding raw --force -o "$out/torus32_u8.nrrd"
$isoscope generate nested-spheres --size 32 --type u16 --encoding gzip --force -o "$out/nested32_u16.nrrd"
$isoscope generate phantom --size 64x64x28 --type i16 --encoding gzip --force -o "$out/phantom64_i16.nrrd"
$isoscope generate blobs --size 24 --steps 5 --type f32 --encoding gzip --force -o "$out/blobs24.nrrd"
