"""Isoscope from Python: exact isosurfaces of volume data by CPU ray tracing.

>>> import numpy as np, isoscope
>>> z, y, x = np.mgrid[-1:1:64j, -1:1:64j, -1:1:64j]        # array[z, y, x]
>>> vol = isoscope.Volume(np.sqrt(x*x + y*y + z*z).astype(np.float32), spacing=(2/63,)*3)
>>> img = isoscope.Scene(vol).render([(0.5, "#e0c080")], orbit=(30, 20), size=(320, 240))
>>> img.rgba.shape
(240, 320, 4)

Arrays are indexed ``[z, y, x]`` (x is the last axis, fastest in C order). See
``docs/python.md`` in the repository for the whole guide; the classes are documented in
the type stub (``__init__.pyi``).
"""

from ._isoscope import (
    Camera,
    Data,
    Image,
    Mesh,
    OocVolume,
    Scene,
    Series,
    Volume,
    __version__,
    open,
    preprocess,
)

__all__ = [
    "Camera",
    "Data",
    "Image",
    "Mesh",
    "OocVolume",
    "Scene",
    "Series",
    "Volume",
    "__version__",
    "open",
    "preprocess",
]
