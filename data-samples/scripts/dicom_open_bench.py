#!/usr/bin/env python3
"""Opening speed of a DICOM series: Isoscope against SimpleITK (GDCM) and dcm2niix on the
same folder, whole processes, alternating runs, medians (docs/benchmarks.md, "Opening DICOM").

    python dicom_open_bench.py ISOSCOPE DIR [--iso 600] [--runs 5] [--size 1024x768]

Rows: `isoscope info DIR` (reads every file, the volume and its statistics);
`isoscope render DIR` (open, build the kd-tree, first picture: what the viewer does before
its first frame); SimpleITK `ImageSeriesReader` (series file names by GDCM, then the
volume in memory); `dcm2niix` (to an uncompressed NIfTI in a scratch folder). The folder
is read once first, so every tool reads it from the page cache."""
import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

SITK = """
import sys, SimpleITK as sitk
r = sitk.ImageSeriesReader()
r.SetFileNames(r.GetGDCMSeriesFileNames(sys.argv[1]))
img = r.Execute()
print(img.GetSize())
"""


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("isoscope")
    ap.add_argument("dir")
    ap.add_argument("--iso", default="600")
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--size", default="1024x768")
    a = ap.parse_args()
    scratch = tempfile.mkdtemp()
    png = os.path.join(scratch, "first.png")
    cmds = {
        "isoscope info": [a.isoscope, "info", a.dir],
        "isoscope render (open + build + first picture)": [
            a.isoscope, "render", a.dir, "--iso", a.iso, "--size", a.size, "-o", png, "--force"],
        "SimpleITK ImageSeriesReader": [sys.executable, "-c", SITK, a.dir],
    }
    if shutil.which("dcm2niix"):
        out = os.path.join(scratch, "nii")
        os.makedirs(out)
        cmds["dcm2niix (to .nii)"] = ["dcm2niix", "-z", "n", "-w", "1", "-o", out, a.dir]
    for f in os.listdir(a.dir):
        with open(os.path.join(a.dir, f), "rb") as fh:
            fh.read()
    times = {k: [] for k in cmds}
    for _ in range(a.runs + 1):  # the first round warms up and is not counted
        for name, cmd in cmds.items():
            t = time.perf_counter()
            p = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
            dt = time.perf_counter() - t
            if p.returncode != 0:
                sys.exit(f"{name} failed: {p.stderr.decode(errors='replace')}")
            times[name].append(dt)
    shutil.rmtree(scratch)
    print("| command | median s | min s | max s |")
    print("|---|---:|---:|---:|")
    for name, ts in times.items():
        ts = ts[1:]
        print(f"| {name} | {statistics.median(ts):.2f} | {min(ts):.2f} | {max(ts):.2f} |")


if __name__ == "__main__":
    main()
