"""Shared fixtures: the repository, the CLI binary the results are compared against, and
helpers that run it.

The tests compare the package against an independent truth: the ``isoscope`` command line
program (built from the same workspace, run as a separate process on files), brute force
or analytic distances. ``ISOSCOPE_BIN`` names the binary; by default the tests look in the
cargo target directory (``CARGO_TARGET_DIR`` or ``target/``) for a debug, then release, build.
"""

import json
import os
import pathlib
import subprocess

import numpy as np
import pytest

REPO = pathlib.Path(__file__).resolve().parents[3]
SAMPLES = REPO / "data-samples" / "samples"


def _find_cli():
    if os.environ.get("ISOSCOPE_BIN"):
        return pathlib.Path(os.environ["ISOSCOPE_BIN"])
    target = pathlib.Path(os.environ.get("CARGO_TARGET_DIR", REPO / "target"))
    for profile in ("debug", "release"):
        p = target / profile / "isoscope"
        if p.is_file():
            return p
    pytest.fail(
        "no isoscope binary: build it (cargo build) or set ISOSCOPE_BIN", pytrace=False
    )


@pytest.fixture(scope="session")
def cli():
    """Runs the CLI; returns the CompletedProcess (check=False)."""
    exe = _find_cli()

    def run(*args):
        return subprocess.run(
            [str(exe), *map(str, args)], capture_output=True, text=True, check=False
        )

    return run


@pytest.fixture(scope="session")
def cli_render(cli, tmp_path_factory):
    """``isoscope render FILE ARGS -o x.png --depth-out x.npy``: (png bytes, depth)."""
    counter = iter(range(10**6))

    def render(path, *args):
        out = tmp_path_factory.mktemp("cli") / f"r{next(counter)}"
        r = cli("render", path, *args, "-o", f"{out}.png", "--depth-out", f"{out}.npy")
        assert r.returncode == 0, r.stderr
        return pathlib.Path(f"{out}.png").read_bytes(), np.load(f"{out}.npy")

    return render


@pytest.fixture(scope="session")
def cli_info(cli):
    def info(*args):
        r = cli("info", *args, "--json")
        assert r.returncode == 0, r.stderr
        return json.loads(r.stdout)

    return info


def cli_error(cli, *args):
    """The CLI's error for a failing command: (first line, [causes])."""
    r = cli(*args)
    assert r.returncode != 0, r.stdout
    text = r.stderr.split("Stack backtrace:")[0].strip()
    text = text.split("Error: ", 1)[-1]
    first, _, rest = text.partition("\n\nCaused by:")
    causes = []
    for line in rest.splitlines():
        line = line.strip()
        if line:
            causes.append(line.split(": ", 1)[1] if line[:1].isdigit() and ": " in line else line)
    return first.strip(), causes


def assert_same_error(exc, cli_err):
    """The exception's message starts with the CLI's and contains each of its causes."""
    first, causes = cli_err
    msg = str(exc)
    assert msg.startswith(first), (msg, first)
    for c in causes:
        assert c in msg, (msg, c)
