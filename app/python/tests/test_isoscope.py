"""The Python package against the CLI (same files, cameras and settings), brute force and
analytic truths. See conftest.py for the fixtures."""

import json
import os
import pathlib
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

import isoscope
from conftest import SAMPLES, assert_same_error, cli_error

PHANTOM = SAMPLES / "phantom64_i16.nrrd"
SIZE = (96, 72)
SIZE_ARG = "96x72"


def png_bytes_of(image, tmp_path, name="py.png"):
    p = tmp_path / name
    image.save(p)
    return p.read_bytes()


def ellipsoid_field(shape=(20, 24, 28), dtype=np.float32):
    """An off-centre ellipsoid's implicit field, indexed [z, y, x]; no two axes alike, so a
    swapped or mirrored axis changes the picture."""
    nz, ny, nx = shape
    z, y, x = np.meshgrid(
        np.linspace(-1, 1, nz), np.linspace(-1, 1, ny), np.linspace(-1, 1, nx), indexing="ij"
    )
    f = np.sqrt(((x - 0.25) / 0.9) ** 2 + ((y + 0.1) / 0.6) ** 2 + ((z - 0.05) / 0.75) ** 2)
    if np.issubdtype(dtype, np.integer):
        f = np.clip(f * 100, 0, np.iinfo(dtype).max)
    return np.ascontiguousarray(f.astype(dtype))


# --- files: the same picture, depth and info as the CLI ---------------------------------


def test_a_file_renders_as_the_cli_renders_it(cli_render, tmp_path):
    vol = isoscope.open(PHANTOM)
    assert isinstance(vol, isoscope.Volume)
    scene = isoscope.Scene(vol)
    img = scene.render(
        [(-300, "#e0c0a0", 0.4), (500, (230 / 255, 230 / 255, 217 / 255))], orbit=(40, 15), size=SIZE
    )
    png, depth = cli_render(
        PHANTOM, "--iso", "-300:#e0c0a0:0.4", "--iso", "500:#e6e6d9", "--orbit", "40,15", "--size", SIZE_ARG
    )
    assert img.rgba.shape == (SIZE[1], SIZE[0], 4) and img.rgba.dtype == np.uint8
    assert img.depth.dtype == np.float32
    np.testing.assert_array_equal(img.depth, depth)
    assert np.isfinite(depth).any() and np.isinf(depth).any()
    assert png_bytes_of(img, tmp_path) == png


def test_clips_shadows_and_cameras_match_the_cli(cli_render, tmp_path):
    scene = isoscope.Scene(isoscope.open(PHANTOM))
    cam = isoscope.Camera(eye=(300, -250, 120), target=(0, 0, 0), up=(0, 0, 1), vfov_deg=35)
    cam_file = tmp_path / "cam.json"
    cam_file.write_text(cam.to_json())
    img = scene.render(
        [(500, "#d0d0c0")],
        camera=cam,
        size=SIZE,
        shadows=True,
        clip_boxes=[(-120, -120, -90, 0, 120, 90, "outside")],
        clip_planes=["0,0,1,40"],
    )
    png, depth = cli_render(
        PHANTOM, "--iso", "500:#d0d0c0", "--camera", cam_file, "--size", SIZE_ARG, "--shadows",
        "--clip-box", "-120,-120,-90,0,120,90:outside", "--clip-plane", "0,0,1,40",
    )
    np.testing.assert_array_equal(img.depth, depth)
    assert png_bytes_of(img, tmp_path) == png


def test_depth_only_has_the_shaded_depth_and_matches_the_cli(cli_render, tmp_path):
    scene = isoscope.Scene(isoscope.open(PHANTOM))
    isos = [(-300, "#e0c0a0", 0.4), (500, "#d0d0c0")]
    shaded = scene.render(isos, orbit=(40, 15), size=SIZE)
    flat = scene.render(isos, orbit=(40, 15), size=SIZE, depth_only=True)
    np.testing.assert_array_equal(flat.depth, shaded.depth)
    hit = np.isfinite(flat.depth)
    assert hit.any()
    # Each hit pixel is one of the two flat colours; the shaded image has many more.
    flat_colours = {tuple(p) for p in flat.rgba[hit]}
    assert flat_colours <= {(0xE0, 0xC0, 0xA0, 255), (0xD0, 0xD0, 0xC0, 255)}, flat_colours
    assert len({tuple(p) for p in shaded.rgba[hit]}) > 10
    png, depth = cli_render(
        PHANTOM, "--iso", "-300:#e0c0a0:0.4", "--iso", "500:#d0d0c0", "--orbit", "40,15",
        "--size", SIZE_ARG, "--depth-only",
    )
    np.testing.assert_array_equal(flat.depth, depth)
    assert png_bytes_of(flat, tmp_path) == png
    with pytest.raises(ValueError, match="depth_only"):
        scene.render(isos, size=SIZE, depth_only=True, shadows=True)


def test_faceted_normals_of_a_volume_shade_the_same_hits_as_the_cli(cli_render, tmp_path):
    vol = isoscope.open(PHANTOM)
    smooth = isoscope.Scene(vol).render([500], orbit=(40, 15), size=SIZE)
    faceted = isoscope.Scene(vol, normals="faceted").render([500], orbit=(40, 15), size=SIZE)
    np.testing.assert_array_equal(faceted.depth, smooth.depth)
    assert np.isfinite(faceted.depth).any()
    assert (faceted.rgba != smooth.rgba).any()
    png, _ = cli_render(PHANTOM, "--iso", "500", "--orbit", "40,15", "--size", SIZE_ARG, "--normals", "faceted")
    assert png_bytes_of(faceted, tmp_path) == png
    # A scene made later without normals keeps its own (the volume's default, smooth).
    again = isoscope.Scene(vol).render([500], orbit=(40, 15), size=SIZE)
    np.testing.assert_array_equal(again.rgba, smooth.rgba)
    with pytest.raises(ValueError, match="faceted or smooth"):
        isoscope.Scene(vol, normals="bumpy")


def test_supersampling_averages_the_rays_of_a_larger_image_as_the_cli_does(cli_render, tmp_path):
    scene = isoscope.Scene(isoscope.open(PHANTOM))
    cam = isoscope.Camera(eye=(300, -250, 120), target=(0, 0, 0), up=(0, 0, 1), vfov_deg=35)
    k = 3
    small = scene.render([(500, "#d0d0c0")], camera=cam, size=SIZE, supersample=k)
    big = scene.render([(500, "#d0d0c0")], camera=cam, size=(SIZE[0] * k, SIZE[1] * k))
    # The box filter by numpy: each k x k block of the big image, rounded to nearest.
    blocks = big.rgba.astype(np.uint32).reshape(SIZE[1], k, SIZE[0], k, 4).sum(axis=(1, 3))
    np.testing.assert_array_equal(small.rgba, ((blocks + k * k // 2) // (k * k)).astype(np.uint8))
    nearest = big.depth.reshape(SIZE[1], k, SIZE[0], k).min(axis=(1, 3))
    np.testing.assert_array_equal(small.depth, nearest)
    cam_file = tmp_path / "cam.json"
    cam_file.write_text(cam.to_json())
    png, depth = cli_render(
        PHANTOM, "--iso", "500:#d0d0c0", "--camera", cam_file, "--size", SIZE_ARG, "--supersample", str(k)
    )
    np.testing.assert_array_equal(small.depth, depth)
    assert png_bytes_of(small, tmp_path) == png
    with pytest.raises(ValueError, match="supersampling 9"):
        scene.render([500], size=SIZE, supersample=9)


def test_changing_isovalues_needs_no_rebuild_and_matches_fresh_scenes():
    vol = isoscope.open(PHANTOM)
    scene = isoscope.Scene(vol)
    a = scene.render([500], size=SIZE).depth
    b = scene.render([-300], size=SIZE).depth
    fresh = isoscope.Scene(isoscope.open(PHANTOM)).render([-300], size=SIZE).depth
    np.testing.assert_array_equal(b, fresh)
    assert not np.array_equal(a, b)


def test_info_is_the_cli_json(cli_info, tmp_path, cli):
    assert isoscope.open(PHANTOM).info() == cli_info(PHANTOM)
    ball = tmp_path / "ball.vtu"
    assert cli("generate", "tet-ball", "--tets", "3000", "-o", ball).returncode == 0
    mesh = isoscope.open(ball)
    assert isinstance(mesh, isoscope.Mesh)
    assert mesh.info() == cli_info(ball)


def test_a_mesh_file_renders_as_the_cli(cli, cli_render, tmp_path):
    ball = tmp_path / "ball.vtu"
    assert cli("generate", "tet-ball", "--tets", "3000", "-o", ball).returncode == 0
    mesh = isoscope.open(ball, normals="smooth")
    img = isoscope.Scene(mesh).render([(0.5, "#80c0ff")], orbit=(10, 30), size=SIZE)
    png, depth = cli_render(ball, "--iso", "0.5:#80c0ff", "--orbit", "10,30", "--size", SIZE_ARG, "--normals", "smooth")
    np.testing.assert_array_equal(img.depth, depth)
    assert png_bytes_of(img, tmp_path) == png


def test_series_steps_refit_and_match_the_cli(cli_render, tmp_path):
    pattern = SAMPLES / "blobs24_%03d.nrrd"
    series = isoscope.open(pattern)
    assert isinstance(series, isoscope.Series) and series.step_count == 5
    scene = isoscope.Scene(series)
    first = scene.render([0.5], orbit=(30, 20), size=SIZE)
    scene.step = 3
    assert scene.step == 3
    img = scene.render([0.5], orbit=(30, 20), size=SIZE)
    png, depth = cli_render(pattern, "--iso", "0.5", "--step", "3", "--orbit", "30,20", "--size", SIZE_ARG)
    np.testing.assert_array_equal(img.depth, depth)
    assert png_bytes_of(img, tmp_path) == png
    assert not np.array_equal(first.depth, img.depth)
    with pytest.raises(ValueError, match="time step 9"):
        scene.step = 9


def test_preprocess_and_the_isot_file_match_the_cli(cli, cli_render, cli_info, tmp_path):
    seen = []
    out = tmp_path / "phantom.isot"
    isoscope.preprocess(PHANTOM, out, progress=lambda done, total: seen.append((done, total)), treelet_height=3)
    assert seen and seen[-1][0] == seen[-1][1]
    assert all(a[0] <= b[0] for a, b in zip(seen, seen[1:]))
    ref = tmp_path / "cli.isot"
    r = cli("preprocess", PHANTOM, "-o", ref, "--treelet-height", "3")
    assert r.returncode == 0, r.stderr
    assert out.read_bytes() == ref.read_bytes()
    ooc = isoscope.open(out)
    assert isinstance(ooc, isoscope.OocVolume)
    img = isoscope.Scene(ooc).render([500], orbit=(30, 20), size=SIZE)
    png, depth = cli_render(out, "--iso", "500", "--orbit", "30,20", "--size", SIZE_ARG)
    np.testing.assert_array_equal(img.depth, depth)
    assert ooc.info() == cli_info(out)
    taken = tmp_path / "taken.isot"
    taken.write_bytes(b"")
    with pytest.raises(FileExistsError, match="already exists"):
        isoscope.preprocess(PHANTOM, taken)
    # An output that this process has read is refused, as in the CLI.
    with pytest.raises(OSError, match="refusing to write over it"):
        isoscope.preprocess(PHANTOM, out, force=True)


# --- numpy volumes: zero-copy, axis order, dtypes ----------------------------------------


@pytest.mark.parametrize("dtype", [np.uint8, np.int16, np.float32])
def test_a_c_ordered_array_is_the_raw_file_x_fastest(dtype, cli_render, tmp_path):
    """array[z, y, x] in C order is x fastest: the same bytes as a raw file, so the CLI's
    render of that file is the truth for the axis convention."""
    a = ellipsoid_field(dtype=dtype)
    iso = 70 if np.issubdtype(dtype, np.integer) else 0.7
    raw = tmp_path / "e.raw"
    a.tofile(raw)
    nz, ny, nx = a.shape
    vol = isoscope.Volume(a, spacing=(0.5, 0.75, 1.25), origin=(-3, 2, 1))
    assert vol.zero_copy and vol.data_address == a.ctypes.data
    assert vol.dims == (nx, ny, nz)
    img = isoscope.Scene(vol).render([iso], orbit=(35, 25), size=SIZE)
    png, depth = cli_render(
        raw, "--dims", f"{nx}x{ny}x{nz}", "--type", np.dtype(dtype).name.replace("uint", "u").replace("int", "i").replace("float", "f"),
        "--endian", "little", "--spacing", "0.5,0.75,1.25", "--origin", "-3,2,1",
        "--iso", str(iso), "--orbit", "35,25", "--size", SIZE_ARG,
    )
    np.testing.assert_array_equal(img.depth, depth)
    assert png_bytes_of(img, tmp_path) == png
    # The info object is the CLI's for the same voxels, but for the name and the mapping.
    info = vol.info()
    assert info["dims"] == [nx, ny, nz] and info["voxel_type"] == np.dtype(dtype).name.replace("uint", "u").replace("int", "i").replace("float", "f")
    assert info["memory_mapped"] is True


def test_an_f_ordered_array_is_viewed_in_place_with_the_same_world_volume():
    a = ellipsoid_field()
    f = np.asfortranarray(a)
    assert f.flags.f_contiguous and not f.flags.c_contiguous
    vc = isoscope.Volume(a, spacing=(0.5, 0.75, 1.25))
    vf = isoscope.Volume(f, spacing=(0.5, 0.75, 1.25))
    assert vf.zero_copy and vf.data_address == f.ctypes.data
    assert vf.dims == a.shape  # memory order: z fastest
    np.testing.assert_allclose(vf.bounds, vc.bounds, atol=1e-5)
    dc = isoscope.Scene(vc).render([0.7], orbit=(35, 25), size=SIZE).depth
    df = isoscope.Scene(vf).render([0.7], orbit=(35, 25), size=SIZE).depth
    hit_c, hit_f = np.isfinite(dc), np.isfinite(df)
    # The grids differ by an axis permutation: the same trilinear surface, traced in
    # another order, so equal up to rounding (a silhouette pixel may flip).
    assert (hit_c != hit_f).mean() < 0.005 and hit_c.sum() > 200
    both = hit_c & hit_f
    np.testing.assert_allclose(df[both], dc[both], rtol=1e-4, atol=1e-4)


def test_strided_and_byte_swapped_arrays_are_copied_once_with_the_same_values():
    a = ellipsoid_field()
    ref = isoscope.Scene(isoscope.Volume(a)).render([0.7], size=SIZE).depth
    swapped = a.astype(a.dtype.newbyteorder(">"))
    strided = np.ascontiguousarray(np.repeat(a, 2, axis=2))[:, :, ::2]
    for arr in (swapped, strided):
        v = isoscope.Volume(arr)
        assert not v.zero_copy
        np.testing.assert_array_equal(isoscope.Scene(v).render([0.7], size=SIZE).depth, ref)


@pytest.mark.parametrize("dtype", [np.int8, np.uint16, np.uint32, np.int32, np.float64])
def test_every_voxel_type_is_viewed_without_conversion(dtype):
    a = ellipsoid_field(dtype=dtype)
    v = isoscope.Volume(a)
    assert v.zero_copy and v.data_address == a.ctypes.data
    info = v.info()
    assert info["value_range"] == [float(a.min()), float(a.max())]


def test_writing_the_array_then_refresh_shows_the_change():
    a = np.zeros((16, 16, 16), np.float32)
    a[4:12, 4:12, 4:12] = 1.0
    vol = isoscope.Volume(a)
    scene = isoscope.Scene(vol)
    before = scene.render([0.5], orbit=(30, 20), size=SIZE).depth
    a[4:12, 4:12, 4:12] = 0.0
    a[1:6, 1:6, 1:6] = 1.0  # the renderer reads this very memory
    assert scene.refresh() == "refit"
    after = scene.render([0.5], orbit=(30, 20), size=SIZE).depth
    truth = isoscope.Scene(isoscope.Volume(a.copy())).render([0.5], orbit=(30, 20), size=SIZE).depth
    assert not np.array_equal(before, after)
    np.testing.assert_array_equal(after, truth)
    assert vol.value_range == (0.0, 1.0)


# --- batched first hits ------------------------------------------------------------------


def test_first_hit_equals_the_renderers_depth_for_the_pixel_rays():
    scene = isoscope.Scene(isoscope.open(PHANTOM))
    cam = isoscope.Camera.orbit(scene, 40, 15)
    w, h = SIZE
    img = scene.render([-300, 500], camera=cam, size=SIZE)
    origins, directions = cam.rays(w, h)
    t, normal, surface = scene.first_hit(origins, directions, [-300, 500])
    np.testing.assert_allclose(t.reshape(h, w), img.depth, rtol=2e-5, atol=1e-4)
    hit = np.isfinite(t)
    assert hit.any() and (~hit).any()
    np.testing.assert_allclose(np.linalg.norm(normal[hit], axis=1), 1, atol=1e-4)
    assert set(np.unique(surface[hit])) <= {0, 1} and (surface[~hit] == -1).all()


def test_first_hit_on_a_sampled_sphere_is_the_analytic_distance():
    n = 65
    c = np.linspace(-1, 1, n)
    z, y, x = np.meshgrid(c, c, c, indexing="ij")
    centre = np.array([0.1, -0.05, 0.03])
    dist = np.sqrt((x - centre[0]) ** 2 + (y - centre[1]) ** 2 + (z - centre[2]) ** 2).astype(np.float32)
    scene = isoscope.Scene(isoscope.Volume(dist, spacing=(2 / (n - 1),) * 3, origin=(-1, -1, -1)))
    rng = np.random.default_rng(1)
    d = rng.normal(size=(2000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    origins = centre + 3.0 * d           # outside, aimed at the centre
    t, normal, surface = scene.first_hit(origins, -d * 2.5, [0.6])  # unnormalized directions
    assert np.isfinite(t).all() and (surface == 0).all()
    # The trilinear interpolant of |p - c| deviates from the sphere by well under a voxel.
    np.testing.assert_allclose(t, 3.0 - 0.6, atol=0.01)
    radial = np.abs(np.sum(normal * d, axis=1))
    assert radial.min() > 0.99
    # t_max before the surface: no hit.
    t2, _, s2 = scene.first_hit(origins, -d, [0.6], t_max=2.3)
    assert np.isinf(t2).all() and (s2 == -1).all()


# --- meshes from arrays ------------------------------------------------------------------


def write_vtk(path, points, tets, name, values):
    lines = ["# vtk DataFile Version 4.2", "tets", "ASCII", "DATASET UNSTRUCTURED_GRID", f"POINTS {len(points)} double"]
    lines += [" ".join(repr(float(v)) for v in p) for p in points]
    lines.append(f"CELLS {len(tets)} {5 * len(tets)}")
    lines += ["4 " + " ".join(str(int(i)) for i in t) for t in tets]
    lines.append(f"CELL_TYPES {len(tets)}")
    lines += ["10"] * len(tets)
    lines += [f"POINT_DATA {len(points)}", f"SCALARS {name} double 1", "LOOKUP_TABLE default"]
    lines += [repr(float(v)) for v in values]
    path.write_text("\n".join(lines) + "\n")


def cube_tets(n):
    """n³ cubes, each split into 6 tets, over [-1, 1]³."""
    c = np.linspace(-1, 1, n + 1)
    z, y, x = np.meshgrid(c, c, c, indexing="ij")
    points = np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1)
    idx = np.arange((n + 1) ** 3).reshape(n + 1, n + 1, n + 1)
    tets = []
    for k in range(n):
        for j in range(n):
            for i in range(n):
                v = [idx[k + dz, j + dy, i + dx] for dz in (0, 1) for dy in (0, 1) for dx in (0, 1)]
                for a, b in ((1, 3), (3, 2), (2, 6), (6, 4), (4, 5), (5, 1)):
                    tets.append([v[0], v[a], v[b], v[7]])
    return points, np.array(tets)


def test_a_mesh_from_arrays_renders_as_the_same_mesh_from_a_file(cli_render, tmp_path):
    points, tets = cube_tets(6)
    values = np.linalg.norm(points - [0.1, 0.0, -0.1], axis=1)
    vtk = tmp_path / "cubes.vtk"
    write_vtk(vtk, points, tets, "distance", values)
    mesh = isoscope.Mesh(points, tets, {"distance": values, "x": points[:, 0]})
    assert mesh.fields == ["distance", "x"] and mesh.field == "distance"
    img = isoscope.Scene(mesh).render([(0.7, "#c08040")], orbit=(20, 25), size=SIZE)
    png, depth = cli_render(vtk, "--iso", "0.7:#c08040", "--orbit", "20,25", "--size", SIZE_ARG)
    np.testing.assert_array_equal(img.depth, depth)
    assert png_bytes_of(img, tmp_path) == png
    assert mesh.info()["tets"] == len(tets)


# --- errors ------------------------------------------------------------------------------


def test_file_errors_are_the_cli_messages(cli, tmp_path):
    missing = tmp_path / "nope.nrrd"
    with pytest.raises(OSError) as e:
        isoscope.open(missing)
    assert_same_error(e.value, cli_error(cli, "info", missing))
    raw = tmp_path / "v.raw"
    raw.write_bytes(bytes(64))
    with pytest.raises(ValueError) as e:
        isoscope.open(raw, dims=(4, 4, 4))
    assert_same_error(e.value, cli_error(cli, "info", raw, "--dims", "4x4x4"))
    with pytest.raises(ValueError) as e:
        isoscope.open(raw, dims="4x4x4", voxel_type="u16")
    assert_same_error(e.value, cli_error(cli, "info", raw, "--dims", "4x4x4", "--type", "u16"))
    bad = tmp_path / "bad.nrrd"
    bad.write_bytes(b"NRRD0004\ntype: float\ndimension: 3\nsizes: 4 4\nencoding: raw\n\n")
    with pytest.raises(ValueError) as e:
        isoscope.open(bad)
    assert_same_error(e.value, cli_error(cli, "info", bad))


def test_bad_arrays_and_arguments_raise_clear_exceptions():
    with pytest.raises(ValueError, match="3D"):
        isoscope.Volume(np.zeros((4, 4), np.float32))
    with pytest.raises(ValueError, match="complex128"):
        isoscope.Volume(np.zeros((4, 4, 4), np.complex128))
    with pytest.raises(ValueError, match="int64"):
        isoscope.Volume(np.zeros((4, 4, 4), np.int64))
    with pytest.raises(ValueError, match="spacing"):
        isoscope.Volume(np.zeros((4, 4, 4), np.float32), spacing=(1, 0, 1))
    with pytest.raises(ValueError, match="point index"):
        isoscope.Mesh(np.zeros((4, 3)), np.array([[0, 1, 2, 7]]), {"f": np.zeros(4)})
    scene = isoscope.Scene(isoscope.Volume(ellipsoid_field()))
    with pytest.raises(ValueError, match="opacity"):
        scene.render([(0.5, "#ffffff", 2.0)])
    with pytest.raises(ValueError, match="colour"):
        scene.render([(0.5, "#fffff")])
    with pytest.raises(ValueError, match="outside"):
        scene.render([0.5], clip_boxes=[(0, 0, 0, 1, 1, 1, "sideways")])
    with pytest.raises(ValueError):
        scene.render([0.5], size=(0, 10))
    with pytest.raises(ValueError, match="N×3"):
        scene.first_hit(np.zeros((3, 2)), np.zeros((3, 2)), [0.5])
    with pytest.raises(ValueError, match="tetrahedral"):
        isoscope.Scene(isoscope.Volume(ellipsoid_field()), bvh="sah")
    with pytest.raises(ValueError, match="single"):
        scene.step = 1


# --- Jupyter, threads, Ctrl+C -----------------------------------------------------------


def test_repr_png_is_the_saved_png_and_threads_do_not_change_the_picture(tmp_path):
    vol = isoscope.Volume(ellipsoid_field())
    one = isoscope.Scene(vol, threads=1).render([0.7], size=SIZE)
    two = isoscope.Scene(vol, threads=2).render([0.7], size=SIZE)
    assert one._repr_png_() == png_bytes_of(one, tmp_path)
    assert one._repr_png_().startswith(b"\x89PNG\r\n\x1a\n")
    np.testing.assert_array_equal(one.rgba, two.rgba)
    with pytest.raises(FileExistsError, match="already exists"):
        one.save(tmp_path / "py.png")
    one.save(tmp_path / "py.png", force=True)


@pytest.mark.skipif(sys.platform == "win32", reason="SIGINT to a child process")
def test_ctrl_c_cancels_a_long_render(tmp_path):
    script = tmp_path / "long.py"
    script.write_text(
        "import sys, time, numpy as np, isoscope\n"
        "a = np.random.default_rng(0).random((96, 96, 96), dtype=np.float32)\n"
        "scene = isoscope.Scene(isoscope.Volume(a), intersector='reference')\n"
        "print('ready', flush=True)\n"
        "t0 = time.time()\n"
        "try:\n"
        "    scene.render([0.5], size=(4000, 4000), layers=64, shadows=True)\n"
        "    print('finished', time.time() - t0, flush=True)\n"
        "except KeyboardInterrupt:\n"
        "    print('interrupted', time.time() - t0, flush=True)\n"
    )
    # A child inherits an ignored SIGINT (a runner's background job), and Python then installs
    # no handler for it: give the child the default disposition, as a terminal would.
    p = subprocess.Popen(
        [sys.executable, str(script)],
        stdout=subprocess.PIPE,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    assert p.stdout.readline().strip() == "ready"
    time.sleep(1.0)
    p.send_signal(signal.SIGINT)
    out, _ = p.communicate(timeout=60)
    assert out.startswith("interrupted"), out
    assert float(out.split()[1]) < 20


# --- export: the same mesh file as the CLI ------------------------------------------------


def test_export_writes_the_cli_mesh_at_the_current_step(cli, tmp_path):
    pattern = SAMPLES / "blobs24_%03d.nrrd"
    scene = isoscope.Scene(isoscope.open(pattern))
    scene.step = 2
    ours = tmp_path / "py.ply"
    summary = scene.export(ours, [(0.5, "#ff8000")], clip_planes=[(1, 0, 0, 0.2)])
    theirs = tmp_path / "cli.ply"
    r = cli("export", pattern, "--step", "2", "--iso", "0.5:#ff8000", "--clip-plane", "1,0,0,0.2", "-o", theirs)
    assert r.returncode == 0, r.stderr
    assert ours.read_bytes() == theirs.read_bytes()
    assert summary["format"] == "ply" and summary["triangles"] > 0
    assert f"{summary['vertices']} vertices, {summary['triangles']} triangles" in r.stdout
    # The triangle count is in the PLY header; an existing file needs force=True.
    assert f"element face {summary['triangles']}".encode() in ours.read_bytes()[:400]
    with pytest.raises(FileExistsError, match="already exists"):
        scene.export(ours, [0.5])
    assert scene.export(ours, [0.5], force=True)["triangles"] != summary["triangles"]
    with pytest.raises(ValueError, match=r"\.ply"):
        scene.export(tmp_path / "x.vrml", [0.5])


# --- colouring by another field ----------------------------------------------------------


def test_color_by_renders_as_the_cli(cli, cli_render, tmp_path):
    """Another volume on the same grid, a volume's gradient and a mesh array colour the
    picture exactly as ``isoscope render --color-by`` does (scalar bar included)."""
    blobs0, blobs1 = SAMPLES / "blobs24_000.nrrd", SAMPLES / "blobs24_001.nrrd"
    scene = isoscope.Scene(isoscope.open(blobs0))
    size, size_arg = (240, 100), "240x100"
    img = scene.render(
        [0.5], orbit=(30, 20), size=size, color_by=str(blobs1), colormap="magma", color_range=(0, 1)
    )
    png, depth = cli_render(
        blobs0, "--iso", "0.5", "--orbit", "30,20", "--size", size_arg,
        "--color-by", blobs1, "--colormap", "magma", "--color-range", "0,1",
    )
    np.testing.assert_array_equal(img.depth, depth)
    assert png_bytes_of(img, tmp_path) == png
    flat = scene.render([0.5], orbit=(30, 20), size=size)
    assert not np.array_equal(flat.rgba, img.rgba)
    np.testing.assert_array_equal(flat.depth, img.depth)
    # Without the bar, only the right part of the image differs from with it.
    bare = scene.render(
        [0.5], orbit=(30, 20), size=size, color_by=str(blobs1), colormap="magma",
        color_range=(0, 1), scalar_bar=False,
    )
    cols = np.nonzero((bare.rgba != img.rgba).any(axis=2).any(axis=0))[0]
    assert cols.size > 0 and cols.min() >= size[0] // 2

    grad = scene.render([0.5], orbit=(30, 20), size=size, color_by="gradient")
    png, _ = cli_render(blobs0, "--iso", "0.5", "--orbit", "30,20", "--size", size_arg, "--color-by", "gradient")
    assert png_bytes_of(grad, tmp_path, "grad.png") == png

    ball = tmp_path / "ball.vtu"
    assert cli("generate", "tet-ball", "--tets", "3000", "-o", ball).returncode == 0
    mesh_scene = isoscope.Scene(isoscope.open(ball))
    img = mesh_scene.render([0.5], orbit=(10, 30), size=size, color_by="gaussians", colormap="coolwarm")
    png, _ = cli_render(
        ball, "--iso", "0.5", "--orbit", "10,30", "--size", size_arg, "--color-by", "gaussians", "--colormap", "coolwarm"
    )
    assert png_bytes_of(img, tmp_path, "mesh.png") == png


def test_color_by_errors_name_the_available_fields(cli, tmp_path):
    ball = tmp_path / "ball.vtu"
    assert cli("generate", "tet-ball", "--tets", "2000", "-o", ball).returncode == 0
    scene = isoscope.Scene(isoscope.open(ball))
    with pytest.raises(ValueError) as e:
        scene.render([0.5], color_by="nope")
    assert "nope" in str(e.value) and "distance, gaussians, moving_gaussian" in str(e.value)
    with pytest.raises(ValueError, match="jet"):
        scene.render([0.5], color_by="distance", colormap="jet")
    with pytest.raises(ValueError, match="color_by"):
        scene.render([0.5], colormap="magma")
    with pytest.raises(ValueError, match="range"):
        scene.render([0.5], color_by="distance", color_range=(2, 1))
    vol = isoscope.Scene(isoscope.open(PHANTOM))
    with pytest.raises(ValueError) as e:
        vol.render(color_by=str(SAMPLES / "sphere32_f32.nrrd"))
    assert "same dims and geometry" in str(e.value) and "32x32x32" in str(e.value)
