#!/usr/bin/env python3
"""Real chest CTs for the benchmarks against Embree (docs/benchmarks.md, "Against Embree"):
the two CT volumes that the pyradiomics 3.1.0 source distribution on PyPI carries as its test
cases, `data/lung1_image.nrrd` (512x512x48 i16, 0.57 x 0.57 x 5 mm) and
`data/lung2_image.nrrd` (512x512x61 i16, 0.63 x 0.63 x 5 mm); BSD-3 licence, Harvard Medical
School.

    python fetch_pyradiomics_ct.py OUT_DIR

Downloads the sdist from PyPI (34 MB; `pip download` would try to build it), checks its
sha256 and each extracted file's, and writes OUT_DIR/lung1_image.nrrd and
OUT_DIR/lung2_image.nrrd (each written beside its final name, then renamed). Standard
library only."""
import hashlib
import os
import sys
import tarfile
import tempfile
import urllib.request

SDIST_URL = (
    "https://files.pythonhosted.org/packages/03/c1/"
    "20fc2c50ab1e3304da36d866042a1905a2b05a1431ece35448ab6b4578f2/pyradiomics-3.1.0.tar.gz"
)
SDIST_SHA256 = "24722c962a6bbd09bc39c1c67dbffe92435f9692a421fabaae8a6b4511eb48e4"
FILES = {
    "lung1_image.nrrd": "379fa48bf34cfa961e6f5ec19c0c38757a30b9aa884212ef28dc29b5061c64ed",
    "lung2_image.nrrd": "aa2b94eec79127ed786798ac8dc3c013010e1692d5787bebfae1a1e9685a4651",
}


def sha256_of(path):
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def main():
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    out = sys.argv[1]
    os.makedirs(out, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        sdist = os.path.join(tmp, "pyradiomics-3.1.0.tar.gz")
        urllib.request.urlretrieve(SDIST_URL, sdist)
        got = sha256_of(sdist)
        if got != SDIST_SHA256:
            sys.exit(f"{SDIST_URL}: sha256 {got}, expected {SDIST_SHA256}")
        with tarfile.open(sdist) as tar:
            for name, want in FILES.items():
                member = tar.getmember(f"pyradiomics-3.1.0/data/{name}")
                part = os.path.join(out, name + ".part")
                with tar.extractfile(member) as src, open(part, "wb") as dst:
                    dst.write(src.read())
                got = sha256_of(part)
                if got != want:
                    os.remove(part)
                    sys.exit(f"{name}: sha256 {got}, expected {want}")
                os.replace(part, os.path.join(out, name))
                print(f"{os.path.join(out, name)}: sha256 {got}")


if __name__ == "__main__":
    main()
