#!/usr/bin/env python3
"""`scene.render` from Python against `isoscope bench` on the same file and camera.

Runs the two alternately (RUNS pairs), each timing FRAMES frames after a warm-up frame at
1024x1024 with 2 threads and the exact intersector, and prints the median ms/frame of each
run, then the ratio of the medians (Python / CLI). The Python time is the whole
`scene.render` call (GIL release, frame, numpy arrays); the CLI's is its render loop.

Usage: python docs/bench-python.py ISOSCOPE_BIN FILE ISO [RUNS] [FRAMES]
(with the `isoscope` package of the same build installed: `pip install ./app/python`).
"""
import json
import statistics
import subprocess
import sys
import time

import isoscope

binary, path, iso = sys.argv[1], sys.argv[2], float(sys.argv[3])
runs = int(sys.argv[4]) if len(sys.argv) > 4 else 5
frames = int(sys.argv[5]) if len(sys.argv) > 5 else 5
size, orbit, threads = (1024, 1024), (30.0, 20.0), 2


def cli_ms():
    out = subprocess.run(
        [binary, "bench", path, "--iso", str(iso), "--size", f"{size[0]}x{size[1]}",
         "--orbit", f"{orbit[0]},{orbit[1]}", "--frames", str(frames), "--threads", str(threads),
         "--skip-dda", "--skip-single", "--json"],
        check=True, capture_output=True, text=True,
    ).stdout
    report = json.loads(out)
    return report["configs"][0]["median_ms"], report["rays_per_second"]


scene = isoscope.Scene(isoscope.open(path), threads=threads)


def python_ms():
    scene.render([iso], orbit=orbit, size=size)  # warm-up, as the bench's
    times = []
    for _ in range(frames):
        t0 = time.perf_counter()
        scene.render([iso], orbit=orbit, size=size)
        times.append(1e3 * (time.perf_counter() - t0))
    return statistics.median(times)


cli, py = [], []
for r in range(runs):
    c, rays = cli_ms()
    p = python_ms()
    cli.append(c)
    py.append(p)
    print(f"run {r}: CLI {c:7.2f} ms ({rays / 1e6:5.1f} Mrays/s), Python {p:7.2f} ms")
ratio = statistics.median(py) / statistics.median(cli)
print(f"median CLI {statistics.median(cli):.2f} ms, Python {statistics.median(py):.2f} ms: "
      f"Python / CLI = {ratio:.3f}")
