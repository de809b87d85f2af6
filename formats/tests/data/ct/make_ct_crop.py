#!/usr/bin/env python3
"""Writes lung1_spine_crop.nrrd: a 96x96x16 crop (spine, the ribs beside it) of the chest CT
`lung1_image.nrrd` from the pyradiomics 3.1.0 sdist, samples unchanged (i16 HU), geometry
kept (spacing 0.5703125 x 0.5703125 x 5 mm, the origin moved to the crop's first sample).

    python make_ct_crop.py LUNG1_IMAGE.nrrd [OUT.nrrd]

LUNG1_IMAGE.nrrd: from `data-samples/scripts/fetch_pyradiomics_ct.py DIR`. Needs numpy and
pynrrd."""
import os
import sys

import nrrd
import numpy as np

# First sample of the crop (i, j, k) and its size.
START = (176, 352, 16)
SIZE = (96, 96, 16)


def main():
    if len(sys.argv) not in (2, 3):
        sys.exit(__doc__)
    src = sys.argv[1]
    out = sys.argv[2] if len(sys.argv) == 3 else os.path.join(
        os.path.dirname(os.path.abspath(__file__)), "lung1_spine_crop.nrrd")
    data, head = nrrd.read(src)
    (i, j, k), (n, m, p) = START, SIZE
    crop = np.ascontiguousarray(data[i:i + n, j:j + m, k:k + p]).astype(np.int16)
    dirs = np.asarray(head["space directions"], dtype=float)
    origin = np.asarray(head["space origin"], dtype=float) + dirs.T @ np.array(START, float)
    header = {
        "space": head["space"],
        "space directions": dirs,
        "space origin": origin,
        "kinds": ["domain"] * 3,
        "encoding": "gzip",
        "endian": "little",
    }
    part = out + ".part"
    nrrd.write(part, crop, header, index_order="F")
    os.replace(part, out)
    print(f"{out}: {crop.shape} {crop.dtype}, values {crop.min()}..{crop.max()}")


if __name__ == "__main__":
    main()
