//! Shading normals of rectilinear isosurfaces (thesis seed 004 §6.4), for the hits of
//! [`super::hit`].
//!
//! Central differences at the 8 corners of the hit cell (one-sided at the volume border or
//! next to a void neighbour), trilinearly interpolated at the hit ("derivative first", as the
//! thesis suggests), mapped to world space with the inverse transpose of `world_from_grid`
//! and the per-axis spacing. If that gradient vanishes, the analytic gradient of the cell's
//! trilinear interpolant is used; if that vanishes too (a constant cell), the normal faces
//! the ray. Normals are never NaN and point towards increasing values.
//!
//! Faceted normals ([`faceted_normal_at`]) are that analytic gradient alone: the exact
//! normal of the trilinear surface in the hit cell, from its 8 corners only (cheaper; the
//! surface's shading then shows the cells).
//!
//! A packet's hits take the smooth normal 8 at a time ([`normals_x8`]): the same operations
//! in `f32x8` lanes, the same normals bit for bit.
//!
//! The same central-difference gradient, unnormalised ([`gradient_local_at`]), is what a
//! surface coloured by gradient magnitude shows ([`super::sample`]).

use glam::{DVec3, Vec3};
use wide::f32x8;

use crate::intersect::TraversalFrame;
use crate::voxel::{Voxel, VoxelType};

/// World normal at cell-local position `uvw` of `cell` (see the module docs).
pub fn normal_at<T: Voxel>(
    frame: &TraversalFrame,
    voxels: &[T],
    dims: [usize; 3],
    cell: [usize; 3],
    uvw: Vec3,
) -> Option<Vec3> {
    if let Some(g) = gradient_interior_f32(frame, voxels, dims, cell, uvw) {
        return frame.world_normal_f32(g);
    }
    normal_general(frame, voxels, dims, cell, uvw)
}

/// The central-difference gradient at cell-local position `uvw` of `cell`, in stored
/// value per traversal unit (map it to world units with
/// [`TraversalFrame::world_gradient`]): the gradient [`normal_at`] normalises, without its
/// fallback for a vanishing gradient (zero stays zero). Components without a finite
/// difference (void neighbours on both sides) are 0.
pub fn gradient_local_at<T: Voxel>(
    frame: &TraversalFrame,
    voxels: &[T],
    dims: [usize; 3],
    cell: [usize; 3],
    uvw: Vec3,
) -> DVec3 {
    if let Some(g) = gradient_interior_f32(frame, voxels, dims, cell, uvw) {
        return g.as_dvec3();
    }
    central_differences(frame, voxels, dims, cell, uvw).0
}

/// Whether `f32` holds voxel type `T`'s values well enough for the interior `f32` gradient
/// (not 32-bit integers or `f64`).
const fn f32_holds<T: Voxel>() -> bool {
    !matches!(T::TYPE, VoxelType::F64 | VoxelType::I32 | VoxelType::U32)
}

/// Whether every central difference at `cell`'s corners has both neighbours: the cell is
/// at least one sample away from every border.
#[inline]
fn away_from_borders(dims: [usize; 3], cell: [usize; 3]) -> bool {
    (0..3).all(|a| cell[a] > 0 && cell[a] + 3 <= dims[a])
}

/// The common case of the gradient in `f32` with straight-line loads: a cell at least one
/// sample away from every border, a voxel type `f32` holds well (not 32-bit integers or
/// `f64`), and a finite, nonzero result. Every corner then takes the central difference,
/// exactly as in [`central_differences`]; anything else (borders, void or huge values, a
/// vanishing gradient) returns `None` and takes the general path.
#[inline]
fn gradient_interior_f32<T: Voxel>(
    frame: &TraversalFrame,
    voxels: &[T],
    dims: [usize; 3],
    cell: [usize; 3],
    uvw: Vec3,
) -> Option<Vec3> {
    if !f32_holds::<T>() || !away_from_borders(dims, cell) {
        return None;
    }
    let (sy, sz) = (dims[0], dims[0] * dims[1]);
    let base = cell[0] + sy * cell[1] + sz * cell[2];
    // The 32 samples the central differences at the cell's 8 corners read (the 4×4×4
    // block minus its corners and edges), loaded once as short rows (one bounds check per
    // row) and converted to f32 once:
    // - x: for each (y, z) of the cell, the row x = −1..=2;
    // - y: for each z, the rows y = −1 and y = 2 at x = 0..=1;
    // - z: for each y, the rows z = −1 and z = 2 at x = 0..=1.
    let row4 = |o: usize| -> [f32; 4] {
        let r: &[T; 4] = voxels[o..o + 4].try_into().expect("4 samples");
        r.map(Voxel::to_f32)
    };
    let row2 = |o: usize| -> [f32; 2] {
        let r: &[T; 2] = voxels[o..o + 2].try_into().expect("2 samples");
        r.map(Voxel::to_f32)
    };
    // Written out (not `[0, 1].map`, whose closures were left as calls, `perf`).
    // xr[z][y][x + 1]
    let xr = [
        [row4(base - 1), row4(base - 1 + sy)],
        [row4(base - 1 + sz), row4(base - 1 + sy + sz)],
    ];
    // yr[z][0 = y −1, 1 = y 2][x], zr[y][0 = z −1, 1 = z 2][x]
    let yr = [
        [row2(base - sy), row2(base + 2 * sy)],
        [row2(base - sy + sz), row2(base + 2 * sy + sz)],
    ];
    let zr = [
        [row2(base - sz), row2(base + 2 * sz)],
        [row2(base + sy - sz), row2(base + sy + 2 * sz)],
    ];
    // Value at (x, y, z) of the cell's own 2×2×2 corners.
    let v = |x: usize, y: usize, z: usize| xr[z][y][x + 1];
    // Inverse central-difference widths per axis for the cell's two sample planes.
    let inv_w = |a: usize| -> [f32; 2] {
        let p = &frame.pos()[a];
        let c = cell[a];
        [1.0 / (p[c + 1] - p[c - 1]), 1.0 / (p[c + 2] - p[c])]
    };
    let (wx, wy, wz) = (inv_w(0), inv_w(1), inv_w(2));
    let mut grad = Vec3::ZERO;
    for c in 0..8 {
        let (bx, by, bz) = (c & 1, (c >> 1) & 1, (c >> 2) & 1);
        // The neighbours one sample below and above along each axis.
        let (xm, xp) = (xr[bz][by][bx], xr[bz][by][bx + 2]);
        let (ym, yp) = if by == 0 {
            (yr[bz][0][bx], v(bx, 1, bz))
        } else {
            (v(bx, 0, bz), yr[bz][1][bx])
        };
        let (zm, zp) = if bz == 0 {
            (zr[by][0][bx], v(bx, by, 1))
        } else {
            (v(bx, by, 0), zr[by][1][bx])
        };
        let g = Vec3::new((xp - xm) * wx[bx], (yp - ym) * wy[by], (zp - zm) * wz[bz]);
        let w = (if bx == 1 { uvw.x } else { 1.0 - uvw.x })
            * (if by == 1 { uvw.y } else { 1.0 - uvw.y })
            * (if bz == 1 { uvw.z } else { 1.0 - uvw.z });
        grad += g * w;
    }
    if !grad.is_finite() || grad == Vec3::ZERO {
        return None;
    }
    Some(grad)
}

/// [`normal_at`] of up to 8 hits of one block side by side (`out[i]` for `cells[i]` at
/// `uvw[i]`). Lanes whose cell takes the interior `f32` path run its operations, and
/// [`TraversalFrame::world_normal_f32`]'s, in the same order in `f32x8` lanes, so every
/// normal is `normal_at`'s bit for bit (Rust fuses no `a * b + c`); the other lanes, and a
/// lane whose gradient or world normal needs a fallback, call `normal_at` itself. The
/// samples are still loaded lane by lane: what the lanes share is the arithmetic (the six
/// divisions and two normalisations of a scalar normal among it).
pub fn normals_x8<T: Voxel>(
    frame: &TraversalFrame,
    voxels: &[T],
    dims: [usize; 3],
    cells: &[[usize; 3]],
    uvw: &[Vec3],
) -> LaneNormals {
    let m = cells.len().min(8);
    let mut out = LaneNormals {
        xyz: [[0.0; 8]; 3],
        some: 0,
    };
    let scalar = |out: &mut LaneNormals, i: usize| {
        if let Some(n) = normal_at(frame, voxels, dims, cells[i], uvw[i]) {
            (out.xyz[0][i], out.xyz[1][i], out.xyz[2][i]) = n.into();
            out.some |= 1 << i;
        }
    };
    if !f32_holds::<T>() {
        for i in 0..m {
            scalar(&mut out, i);
        }
        return out;
    }
    let (sy, sz) = (dims[0], dims[0] * dims[1]);
    // Lane-major copies of `gradient_interior_f32`'s rows: xr[(z·2 + y)·4 + x + 1],
    // yr[(z·2 + side)·2 + x], zr[(y·2 + side)·2 + x], the central-difference widths
    // wd[axis·2 + plane] and the cell-local position; lanes outside keep zeros (unused).
    let mut xr = [[T::default(); 8]; 16];
    let mut yr = [[T::default(); 8]; 8];
    let mut zr = [[T::default(); 8]; 8];
    // An axis whose two-cell spans all have one width (2 on a uniform axis) gives it to
    // every lane: not loaded per lane, and its reciprocal is divided once, not per call
    // and lane (the same `f32` division, so the same bits).
    let shared = [0, 1, 2].map(|a| frame.central_width(a));
    let mut wd = [[1f32; 8]; 6];
    let mut pos = [[0f32; 8]; 3];
    let mut interior = 0u32;
    for i in 0..m {
        let c = cells[i];
        if !away_from_borders(dims, c) {
            continue;
        }
        interior |= 1 << i;
        let base = c[0] + sy * c[1] + sz * c[2];
        let row = |o: usize, out: &mut [[T; 8]], at: usize, len: usize| {
            for (x, &v) in voxels[o..o + len].iter().enumerate() {
                out[at + x][i] = v;
            }
        };
        for z in 0..2 {
            for y in 0..2 {
                row(base - 1 + y * sy + z * sz, &mut xr, (z * 2 + y) * 4, 4);
            }
            row(base - sy + z * sz, &mut yr, z * 4, 2);
            row(base + 2 * sy + z * sz, &mut yr, z * 4 + 2, 2);
        }
        for y in 0..2 {
            row(base + y * sy - sz, &mut zr, y * 4, 2);
            row(base + y * sy + 2 * sz, &mut zr, y * 4 + 2, 2);
        }
        for a in (0..3).filter(|&a| shared[a].is_none()) {
            let (p, k) = (&frame.pos()[a], c[a]);
            wd[a * 2][i] = p[k + 1] - p[k - 1];
            wd[a * 2 + 1][i] = p[k + 2] - p[k];
        }
        pos[0][i] = uvw[i].x;
        pos[1][i] = uvw[i].y;
        pos[2][i] = uvw[i].z;
    }
    // Converted 8 lanes at a time (exact: `f32` holds these types' values as `to_f32` does).
    let lanes = |r: [T; 8]| f32x8::from(r.map(Voxel::to_f32));
    let (xr, yr, zr) = (xr.map(lanes), yr.map(lanes), zr.map(lanes));
    let one = f32x8::ONE;
    let inv: [f32x8; 6] = std::array::from_fn(|j| match shared[j / 2] {
        Some(w) => f32x8::splat(1.0 / w),
        None => one / f32x8::from(wd[j]),
    });
    let [u, v, w] = pos.map(f32x8::from);
    let corner = |x: usize, y: usize, z: usize| xr[(z * 2 + y) * 4 + x + 1];
    let (mut gx, mut gy, mut gz) = (f32x8::ZERO, f32x8::ZERO, f32x8::ZERO);
    for c in 0..8 {
        let (bx, by, bz) = (c & 1, (c >> 1) & 1, (c >> 2) & 1);
        let xrow = (bz * 2 + by) * 4;
        let (xm, xp) = (xr[xrow + bx], xr[xrow + bx + 2]);
        let (ym, yp) = if by == 0 {
            (yr[bz * 4 + bx], corner(bx, 1, bz))
        } else {
            (corner(bx, 0, bz), yr[bz * 4 + 2 + bx])
        };
        let (zm, zp) = if bz == 0 {
            (zr[by * 4 + bx], corner(bx, by, 1))
        } else {
            (corner(bx, by, 0), zr[by * 4 + 2 + bx])
        };
        let weight = (if bx == 1 { u } else { one - u })
            * (if by == 1 { v } else { one - v })
            * (if bz == 1 { w } else { one - w });
        gx += (xp - xm) * inv[bx] * weight;
        gy += (yp - ym) * inv[2 + by] * weight;
        gz += (zp - zm) * inv[4 + bz] * weight;
    }
    // `world_normal_f32`: the matrix product (glam's column order), then `normalize_or_zero`.
    let mat = frame.world_gradient_from_local_f32();
    let row_of = |a: usize| {
        f32x8::splat(mat.x_axis[a]) * gx
            + f32x8::splat(mat.y_axis[a]) * gy
            + f32x8::splat(mat.z_axis[a]) * gz
    };
    let (nx, ny, nz) = (row_of(0), row_of(1), row_of(2));
    let rcp = one / (nx * nx + ny * ny + nz * nz).sqrt();
    let grad = [gx, gy, gz].map(f32x8::to_array);
    // Written as whole lanes and read back by component: a normal assembled on the stack
    // from three `f32` stores and read back as one wider load stalled store forwarding
    // (13 % of this function's samples in `perf`).
    out.xyz = [nx * rcp, ny * rcp, nz * rcp].map(f32x8::to_array);
    let rcp = rcp.to_array();
    for i in 0..m {
        let g = Vec3::new(grad[0][i], grad[1][i], grad[2][i]);
        let nrm = Vec3::new(out.xyz[0][i], out.xyz[1][i], out.xyz[2][i]);
        if interior >> i & 1 == 1
            && g.is_finite()
            && g != Vec3::ZERO
            && rcp[i].is_finite()
            && rcp[i] > 0.0
            && nrm != Vec3::ZERO
            && nrm.is_finite()
        {
            out.some |= 1 << i;
        } else {
            scalar(&mut out, i);
        }
    }
    out
}

/// The normals of [`normals_x8`]'s lanes: lane `i`'s components in `xyz[axis][i]`, bit `i`
/// of `some` set where it has one (`normal_at` gave `Some`).
#[derive(Debug, Clone, Copy)]
pub struct LaneNormals {
    pub xyz: [[f32; 8]; 3],
    pub some: u32,
}

impl LaneNormals {
    /// Lane `i`'s normal, as [`normal_at`] returns it.
    #[inline]
    pub fn get(&self, i: usize) -> Option<Vec3> {
        (self.some >> i & 1 == 1).then(|| Vec3::new(self.xyz[0][i], self.xyz[1][i], self.xyz[2][i]))
    }
}

/// [`normal_at`] for every case, in `f64` (see the module docs).
fn normal_general<T: Voxel>(
    frame: &TraversalFrame,
    voxels: &[T],
    dims: [usize; 3],
    cell: [usize; 3],
    uvw: Vec3,
) -> Option<Vec3> {
    let (grad, corner_vals) = central_differences(frame, voxels, dims, cell, uvw);
    if grad.is_finite()
        && let Some(n) = frame.world_normal(grad)
    {
        return Some(n);
    }
    cell_normal(frame, &corner_vals, cell, uvw)
}

/// Faceted normals ([`crate::render::Normals::Faceted`]): the world normal at cell-local
/// position `uvw` of `cell`'s own trilinear interpolant, the exact normal of the surface the
/// exact intersector hits (it turns at cell faces). Reads only the cell's 8 corners; `None`
/// where that gradient vanishes or is not finite (the caller faces the ray).
pub fn faceted_normal_at<T: Voxel>(
    frame: &TraversalFrame,
    voxels: &[T],
    dims: [usize; 3],
    cell: [usize; 3],
    uvw: Vec3,
) -> Option<Vec3> {
    let (sy, sz) = (dims[0], dims[0] * dims[1]);
    let base = cell[0] + sy * cell[1] + sz * cell[2];
    let corner_vals: [f64; 8] = std::array::from_fn(|c| {
        voxels[base + (c & 1) + sy * ((c >> 1) & 1) + sz * ((c >> 2) & 1)].to_f64()
    });
    cell_normal(frame, &corner_vals, cell, uvw)
}

/// The world normal of the trilinear interpolant of `corner_vals` (corner `c` at
/// `(c & 1, c >> 1 & 1, c >> 2 & 1)`) over `cell`, at cell-local `uvw`: each partial
/// derivative is a bilinear blend of the 4 edge differences along its axis (exactly 0 in a
/// constant cell). Mapped to world space in `f32` when the gradient fits (a shading normal
/// needs no more; `f64` otherwise).
fn cell_normal(frame: &TraversalFrame, c: &[f64; 8], cell: [usize; 3], uvw: Vec3) -> Option<Vec3> {
    let (u, v, w) = (f64::from(uvw.x), f64::from(uvw.y), f64::from(uvw.z));
    let (lo, hi) = frame.cell_box(cell);
    let width = (hi - lo).as_dvec3();
    let blend = |a: f64, b: f64, d: [f64; 4]| {
        (1.0 - a) * (1.0 - b) * d[0] + a * (1.0 - b) * d[1] + (1.0 - a) * b * d[2] + a * b * d[3]
    };
    let g = DVec3::new(
        blend(v, w, [c[1] - c[0], c[3] - c[2], c[5] - c[4], c[7] - c[6]]) / width.x,
        blend(u, w, [c[2] - c[0], c[3] - c[1], c[6] - c[4], c[7] - c[5]]) / width.y,
        blend(u, v, [c[4] - c[0], c[5] - c[1], c[6] - c[2], c[7] - c[3]]) / width.z,
    );
    if !g.is_finite() {
        return None;
    }
    let g32 = g.as_vec3();
    if g32.is_finite() && g32 != Vec3::ZERO {
        frame.world_normal_f32(g32)
    } else {
        frame.world_normal(g)
    }
}

/// Central differences (one-sided at the border or next to a void sample) at the 8 corners
/// of `cell`, trilinearly blended at `uvw`, in `f64` (traversal units), and the corner
/// values.
fn central_differences<T: Voxel>(
    frame: &TraversalFrame,
    voxels: &[T],
    dims: [usize; 3],
    cell: [usize; 3],
    uvw: Vec3,
) -> (DVec3, [f64; 8]) {
    let uvw = uvw.as_dvec3();
    let mut grad = DVec3::ZERO;
    let mut corner_vals = [0.0f64; 8];
    for (c, corner_val) in corner_vals.iter_mut().enumerate() {
        let v = [
            cell[0] + (c & 1),
            cell[1] + ((c >> 1) & 1),
            cell[2] + ((c >> 2) & 1),
        ];
        let (f0, g) = sample_gradient_local(frame, voxels, dims, v);
        *corner_val = f0;
        let w = (if c & 1 == 1 { uvw.x } else { 1.0 - uvw.x })
            * (if c & 2 == 2 { uvw.y } else { 1.0 - uvw.y })
            * (if c & 4 == 4 { uvw.z } else { 1.0 - uvw.z });
        grad += g * w;
    }
    (grad, corner_vals)
}

/// The stored value at sample `v` and its central-difference gradient (one-sided at the
/// border or next to a void sample, 0 along an axis without a finite difference), in
/// traversal units: the corner gradients the trilinear blend of [`gradient_local_at`] mixes.
pub fn sample_gradient_local<T: Voxel>(
    frame: &TraversalFrame,
    voxels: &[T],
    dims: [usize; 3],
    v: [usize; 3],
) -> (f64, DVec3) {
    let value =
        |i: usize, j: usize, k: usize| -> f64 { voxels[i + dims[0] * (j + dims[1] * k)].to_f64() };
    let f0 = value(v[0], v[1], v[2]);
    let mut g = DVec3::ZERO;
    for a in 0..3 {
        let sample = |idx: usize| {
            let mut w = v;
            w[a] = idx;
            let f = value(w[0], w[1], w[2]);
            f.is_finite().then_some((f, f64::from(frame.pos()[a][idx])))
        };
        let minus = if v[a] > 0 { sample(v[a] - 1) } else { None };
        let plus = if v[a] + 1 < dims[a] {
            sample(v[a] + 1)
        } else {
            None
        };
        let here = f0
            .is_finite()
            .then_some((f0, f64::from(frame.pos()[a][v[a]])));
        g[a] = match (minus, here, plus) {
            (Some((fm, xm)), _, Some((fp, xp))) => (fp - fm) / (xp - xm),
            (Some((fm, xm)), Some((fh, xh)), None) => (fh - fm) / (xh - xm),
            (None, Some((fh, xh)), Some((fp, xp))) => (fp - fh) / (xp - xh),
            _ => 0.0,
        };
    }
    (f0, g)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::rng::Rng;
    use crate::volume::{AxisCoords, Grid};
    use std::sync::Arc;

    /// Strictly increasing coordinates with random gaps in `[0.3, 2.3)`.
    fn explicit_axis(rng: &mut Rng, n: usize) -> AxisCoords {
        let mut x = rng.range_f32(-5.0, 5.0) as f64;
        let coords: Vec<f64> = (0..n)
            .map(|_| {
                x += 0.3 + 2.0 * rng.unit_f64();
                x
            })
            .collect();
        AxisCoords::Explicit(Arc::from(coords))
    }

    /// The `f32` lanes of the interior cells against the `f64` central differences of the
    /// general path, on random values and a rectilinear grid with uneven spacing.
    fn interior_lanes_match_the_f64_path<T: Voxel>(scale: f64, seed: u64) {
        let mut rng = Rng::new(seed);
        let dims = [7, 6, 5];
        let grid = Grid::new(
            dims,
            [
                explicit_axis(&mut rng, dims[0]),
                explicit_axis(&mut rng, dims[1]),
                explicit_axis(&mut rng, dims[2]),
            ],
            None,
        )
        .unwrap();
        let frame = TraversalFrame::new(&grid);
        let voxels: Vec<T> = (0..grid.voxel_count())
            .map(|_| T::from_f64(scale * rng.unit_f64()))
            .collect();
        let mut checked = 0;
        for k in 1..dims[2] - 2 {
            for j in 1..dims[1] - 2 {
                for i in 1..dims[0] - 2 {
                    for _ in 0..4 {
                        let uvw = Vec3::new(rng.unit_f32(), rng.unit_f32(), rng.unit_f32());
                        let cell = [i, j, k];
                        let fast = gradient_interior_f32(&frame, &voxels, dims, cell, uvw)
                            .expect("an interior cell of finite, varying values");
                        let (slow, _) = central_differences(&frame, &voxels, dims, cell, uvw);
                        let tol = 1e-5 * slow.abs().max_element().max(1e-3 * scale);
                        assert!(
                            (fast.as_dvec3() - slow).abs().max_element() <= tol,
                            "cell {cell:?} at {uvw}: f32 {fast} against f64 {slow}"
                        );
                        checked += 1;
                    }
                }
            }
        }
        assert_eq!(checked, 4 * 4 * 3 * 2);
        // The border cells take the general path.
        assert!(
            gradient_interior_f32(&frame, &voxels, dims, [0, 1, 1], Vec3::splat(0.5)).is_none()
        );
        assert!(
            gradient_interior_f32(&frame, &voxels, dims, [1, 1, 3], Vec3::splat(0.5)).is_none()
        );
    }

    /// Faceted normals against the analytic gradient of a field that trilinear
    /// interpolation reproduces exactly on any rectilinear grid (degree ≤ 1 per axis), at
    /// random points of every cell, border cells included: in the `f32` path (`f32`, `i16`
    /// voxels) and the `f64` one (`f64` voxels).
    #[test]
    fn faceted_normals_are_the_gradient_of_the_trilinear_field() {
        faceted_normals_match::<f32>(1.0, 7);
        faceted_normals_match::<f64>(1.0, 8);
        faceted_normals_match::<i16>(1000.0, 9);
    }

    fn faceted_normals_match<T: Voxel>(scale: f64, seed: u64) {
        let f = |p: DVec3| {
            1.0 + 2.0 * p.x - p.y + 0.5 * p.z + 0.3 * p.x * p.y - 0.2 * p.y * p.z
                + 0.1 * p.x * p.y * p.z
        };
        let grad = |p: DVec3| {
            DVec3::new(
                2.0 + 0.3 * p.y + 0.1 * p.y * p.z,
                -1.0 + 0.3 * p.x - 0.2 * p.z + 0.1 * p.x * p.z,
                0.5 - 0.2 * p.y + 0.1 * p.x * p.y,
            )
        };
        let mut rng = Rng::new(seed);
        let dims = [5, 4, 6];
        let axes = [
            explicit_axis(&mut rng, dims[0]),
            explicit_axis(&mut rng, dims[1]),
            explicit_axis(&mut rng, dims[2]),
        ];
        let grid = Grid::new(dims, axes.clone(), None).unwrap();
        let frame = TraversalFrame::new(&grid);
        let coord = |a: usize, i: usize| {
            let AxisCoords::Explicit(c) = &axes[a] else {
                unreachable!("explicit_axis makes explicit coordinates")
            };
            c[i]
        };
        let mut voxels = Vec::new();
        for k in 0..dims[2] {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    let x = scale * f(DVec3::new(coord(0, i), coord(1, j), coord(2, k)));
                    voxels.push(T::from_f64(x));
                }
            }
        }
        for k in 0..dims[2] - 1 {
            for j in 0..dims[1] - 1 {
                for i in 0..dims[0] - 1 {
                    let cell = [i, j, k];
                    for _ in 0..3 {
                        let uvw = Vec3::new(rng.unit_f32(), rng.unit_f32(), rng.unit_f32());
                        let p = DVec3::new(
                            coord(0, i) + f64::from(uvw.x) * (coord(0, i + 1) - coord(0, i)),
                            coord(1, j) + f64::from(uvw.y) * (coord(1, j + 1) - coord(1, j)),
                            coord(2, k) + f64::from(uvw.z) * (coord(2, k + 1) - coord(2, k)),
                        );
                        let want = grad(p).normalize();
                        if T::TYPE == VoxelType::I16 {
                            // Rounded samples: the gradient of the stored (rounded) field.
                            let got = faceted_normal_at(&frame, &voxels, dims, cell, uvw)
                                .expect("a nonvanishing gradient")
                                .as_dvec3();
                            assert!((got - want).length() < 0.05, "{got} against {want}");
                            continue;
                        }
                        let got = faceted_normal_at(&frame, &voxels, dims, cell, uvw)
                            .expect("a nonvanishing gradient")
                            .as_dvec3();
                        assert!(
                            (got - want).length() < 1e-4,
                            "cell {cell:?} at {uvw}: {got} against {want}"
                        );
                    }
                }
            }
        }
        // A constant cell has no normal (the caller faces the ray).
        let flat = vec![T::from_f64(3.0); voxels.len()];
        assert!(faceted_normal_at(&frame, &flat, dims, [1, 1, 1], Vec3::splat(0.5)).is_none());
    }

    /// The lanes of [`normals_x8`] against [`normal_at`] one by one, bit for bit: random
    /// cells (border cells and a constant block among them, which take the fallbacks) at
    /// random positions, an uneven sheared and rotated grid, lanes of 1 to 8, each voxel type
    /// kind (`f64` takes `normal_at` in every lane); then uniform x and z axes with an
    /// uneven y (the lanes' widths of a uniform axis are not loaded).
    #[test]
    fn normals_in_lanes_equal_normal_at_bit_for_bit() {
        for (uniform, coarse) in [
            ([false; 3], false),
            ([true, false, true], false),
            ([true, false, true], true),
        ] {
            lanes_equal_normal_at::<u8>(255.0, 11, uniform, coarse);
            lanes_equal_normal_at::<i16>(3000.0, 12, uniform, coarse);
            lanes_equal_normal_at::<f32>(1.0, 13, uniform, coarse);
            lanes_equal_normal_at::<f64>(1.0, 14, uniform, coarse);
        }
    }

    /// `coarse`: the positions replaced as a level-1 treelet's are (every other sample of
    /// the volume, from an offset: two-cell spans of 4 units on a uniform axis).
    fn lanes_equal_normal_at<T: Voxel>(scale: f64, seed: u64, uniform: [bool; 3], coarse: bool) {
        let mut rng = Rng::new(seed);
        let dims = [9, 8, 7];
        let world = glam::DAffine3::from_rotation_z(0.7)
            * glam::DAffine3::from_mat3(glam::DMat3::from_cols(
                DVec3::new(1.0, 0.0, 0.0),
                DVec3::new(0.3, 1.0, 0.0),
                DVec3::new(0.0, 0.2, 1.5),
            ));
        let axes = [0, 1, 2].map(|a| {
            if uniform[a] {
                AxisCoords::Uniform {
                    origin: -2.0,
                    spacing: 0.7 + a as f64,
                }
            } else {
                explicit_axis(&mut rng, dims[a])
            }
        });
        let grid = Grid::new(dims, axes, Some(world)).unwrap();
        let mut frame = TraversalFrame::new(&grid);
        if coarse {
            let pos = frame
                .pos()
                .each_ref()
                .map(|p| p.iter().map(|&x| 2.0 * x + 10.0).collect());
            frame.set_positions(pos);
        }
        let span = if coarse { 4.0 } else { 2.0 };
        assert_eq!(
            [0, 1, 2].map(|a| frame.central_width(a)),
            uniform.map(|u| u.then_some(span))
        );
        let voxels: Vec<T> = (0..grid.voxel_count())
            .map(|v| {
                // A constant block around (2..5, 2..5, 2..5): vanishing gradients there.
                let (i, j, k) = (v % dims[0], v / dims[0] % dims[1], v / (dims[0] * dims[1]));
                let flat = [i, j, k].iter().all(|&c| (2..5).contains(&c));
                T::from_f64(scale * if flat { 0.5 } else { rng.unit_f64() })
            })
            .collect();
        let (mut lanes_fast, mut lanes_fallback) = (0, 0);
        for round in 0..400 {
            let m = 1 + round % 8;
            let cells: Vec<[usize; 3]> = (0..m)
                .map(|_| [0, 1, 2].map(|a| rng.below(dims[a] as u32 - 1) as usize))
                .collect();
            let uvw: Vec<Vec3> = (0..m)
                .map(|_| Vec3::new(rng.unit_f32(), rng.unit_f32(), rng.unit_f32()))
                .collect();
            let lanes = normals_x8(&frame, &voxels, dims, &cells, &uvw);
            assert_eq!(
                lanes.some >> m,
                0,
                "no normal in a lane beyond the {m} given"
            );
            let got: Vec<Option<Vec3>> = (0..m).map(|i| lanes.get(i)).collect();
            for i in 0..m {
                let want = normal_at(&frame, &voxels, dims, cells[i], uvw[i]);
                assert_eq!(
                    got[i].map(|n| n.to_array().map(f32::to_bits)),
                    want.map(|n| n.to_array().map(f32::to_bits)),
                    "lane {i} of {m}: cell {:?} at {}",
                    cells[i],
                    uvw[i]
                );
                let interior = gradient_interior_f32(&frame, &voxels, dims, cells[i], uvw[i]);
                if interior.is_some() {
                    lanes_fast += 1;
                } else {
                    lanes_fallback += 1;
                }
            }
        }
        // Both kinds of lane were compared (for f64 every lane is a fallback).
        assert!(lanes_fallback > 50, "{lanes_fallback} fallback lanes");
        assert!(
            T::TYPE == VoxelType::F64 || lanes_fast > 300,
            "{lanes_fast} lanes"
        );
    }

    #[test]
    fn interior_gradients_in_lanes_equal_the_general_central_differences() {
        interior_lanes_match_the_f64_path::<u8>(255.0, 1);
        interior_lanes_match_the_f64_path::<i16>(3000.0, 2);
        interior_lanes_match_the_f64_path::<f32>(1.0, 3);
    }
}
