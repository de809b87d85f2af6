"""Type stubs of the isoscope package (the native module ``isoscope._isoscope``).

Axis convention: a volume array is indexed ``array[z, y, x]``: x is the last axis (fastest
in memory in C order), as in napari and scikit-image. ``spacing`` and ``origin`` are given
as ``(x, y, z)``. A nibabel image's data, indexed ``[i, j, k]``, is passed as ``data.T``
(a view, no copy).
"""

from os import PathLike
from typing import Any, Callable, Dict, Literal, Mapping, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

__version__: str

_Path = Union[str, "PathLike[str]"]
_Vec3 = Tuple[float, float, float]
_Color = Union[str, Tuple[float, float, float]]
#: ``v``, ``(v,)``, ``(v, color)`` or ``(v, color, opacity)``; color ``"#rrggbb"`` or
#: ``(r, g, b)`` in [0, 1]; opacity in [0, 1] (below 1: transparent).
_IsoSpec = Union[float, Tuple[float], Tuple[float, Optional[_Color]], Tuple[float, Optional[_Color], float]]
#: ``(x0, y0, z0, x1, y1, z1)`` or with ``"inside"``/``"outside"`` appended, or the CLI's
#: text ``"x0,y0,z0,x1,y1,z1:outside"``.
_ClipBox = Union[str, Sequence[Union[float, str]]]
#: ``(nx, ny, nz, d)`` keeps ``n·x <= d``; or the CLI's text ``"nx,ny,nz,d"``.
_ClipPlane = Union[str, Sequence[float]]

class Data:
    """Loaded data and its acceleration structure (base of the data classes)."""

    @property
    def path(self) -> str:
        """The file, or ``<numpy array>`` / ``<numpy mesh>``."""
    @property
    def kind(self) -> Literal["grid", "tet", "isot"]: ...
    @property
    def value_range(self) -> Optional[Tuple[float, float]]:
        """Smallest and largest finite value of the current step (physical units)."""
    @property
    def bounds(self) -> Tuple[_Vec3, _Vec3]:
        """World-space bounds ``((x0, y0, z0), (x1, y1, z1))``."""
    @property
    def step_count(self) -> int: ...
    def info(self) -> Dict[str, Any]:
        """The ``isoscope info --json`` object (same fields and values as the CLI)."""
    def describe(self) -> str: ...

class Volume(Data):
    """A rectilinear volume.

    ``Volume(array)`` views the array's memory in place (no copy, no conversion of the
    dtype) when it is C- or F-contiguous in native byte order; other arrays are copied once.
    Supported dtypes: uint8, int8, uint16, int16, uint32, int32, float32, float64.
    ``world_from_grid`` (3×4 or 4×4) maps the grid positions ``origin + index·spacing`` to
    world coordinates. After writing to the array, call ``Scene.refresh()``; do not resize
    the array or write to it while a render runs.
    """

    def __init__(
        self,
        array: npt.NDArray[Any],
        spacing: Optional[Sequence[float]] = None,
        origin: Optional[Sequence[float]] = None,
        world_from_grid: Optional[Union[npt.ArrayLike, Sequence[Sequence[float]]]] = None,
        intersector: str = "exact",
    ) -> None: ...
    @property
    def array(self) -> Optional[npt.NDArray[Any]]:
        """The array given to ``Volume(...)`` (``None`` for a file)."""
    @property
    def zero_copy(self) -> bool:
        """True when the voxels are the array's own memory."""
    @property
    def dims(self) -> Tuple[int, int, int]:
        """Samples per grid axis in memory order, fastest first."""
    @property
    def data_address(self) -> int:
        """Address of the first voxel the renderer reads (compare ``array.ctypes.data``)."""

class Mesh(Data):
    """A tetrahedral mesh: points (N×3), tets (M×4 point indices), per-point scalar fields.

    The arrays are copied into the BVH's own layout (float32 points and values)."""

    def __init__(
        self,
        points: npt.ArrayLike,
        tets: npt.ArrayLike,
        fields: Mapping[str, npt.ArrayLike],
        field: Optional[str] = None,
        bvh: Literal["bih", "sah"] = "sah",
        leaf_size: Optional[int] = None,
        normals: Literal["faceted", "smooth"] = "faceted",
    ) -> None: ...
    @property
    def field(self) -> Optional[str]:
        """The drawn point array."""
    @property
    def fields(self) -> list[str]: ...

class OocVolume(Data):
    """An out-of-core ``.isot`` volume; treelets are paged in by a loader thread."""

class Series(Data):
    """A time series of volumes or meshes; ``Scene.step`` switches steps (a refit)."""

    @property
    def time_values(self) -> list[float]: ...

def open(
    path: _Path,
    *,
    dims: Optional[Union[str, Sequence[int]]] = None,
    voxel_type: Optional[str] = None,
    endian: Optional[Literal["little", "big"]] = None,
    spacing: Optional[Union[str, Sequence[float]]] = None,
    header_bytes: Optional[int] = None,
    origin: Optional[Union[str, Sequence[float]]] = None,
    series: Optional[Union[int, str]] = None,
    field: Optional[str] = None,
    step: Optional[int] = None,
    intersector: Optional[str] = None,
    bvh: Optional[Literal["bih", "sah"]] = None,
    leaf_size: Optional[int] = None,
    normals: Optional[Literal["faceted", "smooth"]] = None,
    budget_mb: Optional[int] = None,
) -> Union[Volume, Mesh, OocVolume, Series]:
    """Opens whatever ``isoscope info``/``render`` open, with the same keywords as their
    flags and the same error messages (``OSError`` for file system errors, ``ValueError``
    otherwise)."""

def preprocess(
    src: _Path,
    dst: _Path,
    *,
    progress: Optional[Callable[[int, int], object]] = None,
    treelet_height: int = 9,
    levels: Optional[int] = None,
    force: bool = False,
) -> None:
    """Writes the out-of-core ``.isot`` file of a volume (``isoscope preprocess``);
    ``progress(done_bytes, total_bytes)`` is called about ten times a second."""

class Camera:
    """A pinhole or orthographic camera in world units (the CLI's camera JSON)."""

    def __init__(
        self,
        eye: Sequence[float],
        target: Sequence[float],
        up: _Vec3 = (0.0, 0.0, 1.0),
        vfov_deg: float = 40.0,
        projection: Literal["pinhole", "orthographic"] = "pinhole",
        ortho_height: Optional[float] = None,
    ) -> None: ...
    @staticmethod
    def orbit(
        scene: Scene,
        azimuth_deg: float = 30.0,
        elevation_deg: float = 20.0,
        vfov_deg: float = 40.0,
        size: Tuple[int, int] = (800, 600),
    ) -> Camera:
        """The camera of the CLI's ``--orbit AZ,EL --size WxH``: as close as the scene's
        bounds fit an image of ``size`` with a 5 % margin."""
    @staticmethod
    def load(path: _Path) -> Camera:
        """Reads a camera JSON file (the CLI's ``--camera``)."""
    def to_json(self) -> str: ...
    @property
    def eye(self) -> _Vec3: ...
    @property
    def target(self) -> _Vec3: ...
    @property
    def up(self) -> _Vec3: ...
    @property
    def vfov_deg(self) -> float: ...
    def rays(self, width: int, height: int) -> Tuple[npt.NDArray[np.float32], npt.NDArray[np.float32]]:
        """Origins and unit directions ((H·W)×3) of the pixel-centre rays, row 0 at the top."""

class Image:
    """A rendered frame."""

    @property
    def width(self) -> int: ...
    @property
    def height(self) -> int: ...
    @property
    def rgba(self) -> npt.NDArray[np.uint8]:
        """H×W×4, row 0 at the top."""
    @property
    def depth(self) -> npt.NDArray[np.float32]:
        """H×W first-hit distance along each pixel's unit ray; ``inf`` where it misses."""
    @property
    def elapsed_s(self) -> float: ...
    def save(self, path: _Path, *, force: bool = False) -> None:
        """Writes an RGBA PNG (atomically; replaces a file only with ``force``)."""
    def _repr_png_(self) -> bytes: ...

class Scene:
    """A view of a data object; the structure is built when the data is loaded.

    The GIL is released while rendering; Ctrl+C cancels. ``threads`` sizes a rayon pool of
    the scene's own (default: the global pool, all cores)."""

    def __init__(
        self,
        data: Data,
        intersector: Optional[str] = None,
        bvh: Optional[Literal["bih", "sah"]] = None,
        leaf_size: Optional[int] = None,
        normals: Optional[Literal["faceted", "smooth"]] = None,
        threads: Optional[int] = None,
    ) -> None: ...
    @property
    def data(self) -> Data: ...
    @property
    def bounds(self) -> Tuple[_Vec3, _Vec3]: ...
    step: int
    """The time step shown; setting it loads that step and refits the structure."""
    def refresh(self) -> Literal["refit", "rebuilt", "unchanged"]:
        """Re-reads a numpy volume's memory after it was written to (kd-tree refit)."""
    def render(
        self,
        isovalues: Optional[Sequence[_IsoSpec]] = None,
        *,
        camera: Optional[Camera] = None,
        orbit: Optional[Tuple[float, float]] = None,
        vfov: float = 40.0,
        size: Tuple[int, int] = (800, 600),
        shadows: bool = False,
        light_dir: Optional[_Vec3] = None,
        clip_boxes: Optional[Sequence[_ClipBox]] = None,
        clip_planes: Optional[Sequence[_ClipPlane]] = None,
        layers: int = 4,
        background: Optional[_Color] = None,
        supersample: int = 1,
        level_timeout: float = 120.0,
        color_by: Optional[str] = None,
        colormap: Optional[str] = None,
        color_range: Optional[Tuple[float, float]] = None,
        scalar_bar: bool = True,
        depth_only: bool = False,
    ) -> Image:
        """Renders the isosurfaces (default: one at the middle of the value range), as
        ``isoscope render`` does with the same settings; ``supersample=k`` averages k×k
        rays per pixel (anti-aliasing, 1 to 8).

        ``color_by`` colours every surface by another field through ``colormap``
        (``"viridis"`` (default), ``"magma"``, ``"coolwarm"``, ``"grey"``): a mesh point
        array, ``"gradient"`` (a volume's gradient magnitude) or the path of another volume
        with the same dims and geometry. ``color_range=(min, max)`` fixes the values at the
        colormap's ends (default: the field's data range; values outside are clamped);
        ``scalar_bar=False`` leaves the scalar bar out of the image.

        ``depth_only=True`` finds each pixel's first hit only (``render --depth-only``):
        the image shows it in its surface's flat colour, with no lighting, shadows or
        transparency, and ``Image.depth`` is the same as a shaded frame's, faster."""
    def export(
        self,
        path: _Path,
        isovalues: Optional[Sequence[_IsoSpec]] = None,
        *,
        clip_boxes: Optional[Sequence[_ClipBox]] = None,
        clip_planes: Optional[Sequence[_ClipPlane]] = None,
        normals: bool = False,
        force: bool = False,
    ) -> Dict[str, Union[str, int, float]]:
        """Writes the isosurfaces at the current time step, clipped, as one triangle mesh
        (``.ply`` with vertex colours, ``.stl`` or ``.obj``), as ``isoscope export`` does.
        Returns ``{"format", "vertices", "triangles", "area"}``. An existing file is
        replaced only with ``force=True``; an input file never is."""
    def first_hit(
        self,
        origins: npt.ArrayLike,
        directions: npt.ArrayLike,
        isovalues: Sequence[float],
        *,
        t_min: float = 0.0,
        t_max: float = float("inf"),
    ) -> Tuple[npt.NDArray[np.float32], npt.NDArray[np.float32], npt.NDArray[np.int32]]:
        """First hits of N rays (N×3 origins and directions): ``(t, normal, surface)``;
        ``t`` along the normalized direction (``inf`` on a miss), ``normal`` unit N×3 (NaN on
        a miss), ``surface`` the index into ``isovalues`` (``-1`` on a miss)."""
