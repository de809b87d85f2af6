//! The mesh under construction: vertices, and triangles clipped to the regions on the way in.
//!
//! A triangle is clipped polygon by polygon, region by region (Sutherland–Hodgman against
//! each half-space). A cut point on the segment between vertices `a` and `b` is memoized by
//! `(min(a, b), max(a, b), plane)`: the triangles on both sides of a shared edge get the same
//! vertex, so clipping opens no cracks. Buffers are reused across triangles; nothing is
//! allocated per triangle once they have grown.

use std::collections::HashMap;

use glam::DVec3;

use super::clip::{HalfSpace, Region};
use super::{ExtractError, TriMesh};

/// Most vertices a mesh holds (indices are `u32`).
const MAX_VERTICES: usize = u32::MAX as usize;

pub(crate) struct MeshBuilder<'r> {
    mesh: TriMesh,
    regions: &'r [Region],
    /// Isovalue index given to new vertices.
    pub surface: u32,
    cuts: HashMap<(u32, u32, u32), u32>,
    /// Polygons being clipped (flat vertex ids, end offsets), current and next.
    polys: Vec<u32>,
    ends: Vec<usize>,
    next_polys: Vec<u32>,
    next_ends: Vec<usize>,
    scratch: [Vec<u32>; 2],
}

impl<'r> MeshBuilder<'r> {
    pub fn new(regions: &'r [Region]) -> Self {
        Self {
            mesh: TriMesh::default(),
            regions,
            surface: 0,
            cuts: HashMap::new(),
            polys: Vec::new(),
            ends: Vec::new(),
            next_polys: Vec::new(),
            next_ends: Vec::new(),
            scratch: [Vec::new(), Vec::new()],
        }
    }

    /// Adds a vertex of the current surface at world position `p`.
    pub fn vertex(&mut self, p: DVec3) -> Result<u32, ExtractError> {
        let id = self.mesh.positions.len();
        if id >= MAX_VERTICES {
            return Err(ExtractError::TooManyVertices);
        }
        self.mesh.positions.push(p.as_vec3().to_array());
        self.mesh.surfaces.push(self.surface);
        Ok(id as u32)
    }

    /// The position of vertex `v`, as stored.
    pub fn position(&self, v: u32) -> DVec3 {
        DVec3::from_array(self.mesh.positions[v as usize].map(f64::from))
    }

    /// Adds triangle `t`, clipped to the regions.
    pub fn triangle(&mut self, t: [u32; 3]) -> Result<(), ExtractError> {
        if self.regions.is_empty() {
            self.mesh.triangles.push(t);
            return Ok(());
        }
        let mut polys = std::mem::take(&mut self.polys);
        let mut ends = std::mem::take(&mut self.ends);
        let mut next_polys = std::mem::take(&mut self.next_polys);
        let mut next_ends = std::mem::take(&mut self.next_ends);
        polys.clear();
        ends.clear();
        polys.extend_from_slice(&t);
        ends.push(3);
        let regions = self.regions;
        let mut result = Ok(());
        for region in regions {
            next_polys.clear();
            next_ends.clear();
            let mut start = 0;
            for &end in &ends {
                let poly = &polys[start..end];
                start = end;
                result = self.clip_region(region, poly, &mut next_polys, &mut next_ends);
                if result.is_err() {
                    break;
                }
            }
            std::mem::swap(&mut polys, &mut next_polys);
            std::mem::swap(&mut ends, &mut next_ends);
            if result.is_err() || ends.is_empty() {
                break;
            }
        }
        if result.is_ok() {
            let mut start = 0;
            for &end in &ends {
                let poly = &polys[start..end];
                start = end;
                for k in 1..poly.len() - 1 {
                    let tri = [poly[0], poly[k], poly[k + 1]];
                    if tri[0] != tri[1] && tri[1] != tri[2] && tri[0] != tri[2] {
                        self.mesh.triangles.push(tri);
                    }
                }
            }
        }
        self.polys = polys;
        self.ends = ends;
        self.next_polys = next_polys;
        self.next_ends = next_ends;
        result
    }

    /// Appends the parts of `poly` that `region` keeps to `out` (polygons of 3+ vertices).
    fn clip_region(
        &mut self,
        region: &Region,
        poly: &[u32],
        out: &mut Vec<u32>,
        out_ends: &mut Vec<usize>,
    ) -> Result<(), ExtractError> {
        match region {
            Region::Convex(hs) => self.clip_convex(hs, poly, out, out_ends),
            Region::Outside { min, max, pieces } => {
                let pts = || poly.iter().map(|&v| self.position(v));
                // Wholly on the outer side of one box face: kept as it is.
                let outside =
                    (0..3).any(|a| pts().all(|p| p[a] <= min[a]) || pts().all(|p| p[a] >= max[a]));
                if outside {
                    out.extend_from_slice(poly);
                    out_ends.push(out.len());
                    return Ok(());
                }
                // Wholly in the open box: removed.
                if pts().all(|p| (0..3).all(|a| p[a] > min[a] && p[a] < max[a])) {
                    return Ok(());
                }
                for piece in pieces {
                    self.clip_convex(piece, poly, out, out_ends)?;
                }
                Ok(())
            }
        }
    }

    /// Clips `poly` by every half-space of `hs` in turn; appends what is left, if anything.
    fn clip_convex(
        &mut self,
        hs: &[HalfSpace],
        poly: &[u32],
        out: &mut Vec<u32>,
        out_ends: &mut Vec<usize>,
    ) -> Result<(), ExtractError> {
        let [mut a, mut b] = std::mem::take(&mut self.scratch);
        a.clear();
        a.extend_from_slice(poly);
        let mut result = Ok(());
        for h in hs {
            b.clear();
            result = self.clip_half(h, &a, &mut b);
            std::mem::swap(&mut a, &mut b);
            if result.is_err() || a.len() < 3 {
                break;
            }
        }
        if result.is_ok() && a.len() >= 3 {
            out.extend_from_slice(&a);
            out_ends.push(out.len());
        }
        self.scratch = [a, b];
        result
    }

    /// One Sutherland–Hodgman step: the part of `poly` with `distance <= 0`. A vertex exactly
    /// on the plane is kept and never doubled by a cut point.
    fn clip_half(
        &mut self,
        h: &HalfSpace,
        poly: &[u32],
        out: &mut Vec<u32>,
    ) -> Result<(), ExtractError> {
        let n = poly.len();
        for k in 0..n {
            let (a, b) = (poly[k], poly[(k + 1) % n]);
            let (da, db) = (h.distance(self.position(a)), h.distance(self.position(b)));
            if da <= 0.0 {
                out.push(a);
            }
            if (da < 0.0 && db > 0.0) || (da > 0.0 && db < 0.0) {
                out.push(self.cut(a, b, h)?);
            }
        }
        Ok(())
    }

    /// The vertex where segment `a`–`b` crosses `h`'s plane (memoized, computed from the
    /// lower vertex id so that it is the same from either side).
    fn cut(&mut self, a: u32, b: u32, h: &HalfSpace) -> Result<u32, ExtractError> {
        let (lo, hi) = (a.min(b), a.max(b));
        let key = (lo, hi, h.plane);
        if let Some(&v) = self.cuts.get(&key) {
            return Ok(v);
        }
        let (p, q) = (self.position(lo), self.position(hi));
        let (dp, dq) = (h.distance(p), h.distance(q));
        let t = dp / (dp - dq);
        let surface = self.surface;
        self.surface = self.mesh.surfaces[lo as usize];
        let v = self.vertex(p + (q - p) * t);
        self.surface = surface;
        let v = v?;
        self.cuts.insert(key, v);
        Ok(v)
    }

    /// The mesh, without the vertices no triangle uses (those of clipped-away parts).
    pub fn finish(self) -> TriMesh {
        let mut mesh = self.mesh;
        let mut remap = vec![u32::MAX; mesh.positions.len()];
        for t in &mesh.triangles {
            for &v in t {
                remap[v as usize] = 0;
            }
        }
        let mut kept = 0u32;
        for (old, slot) in remap.iter_mut().enumerate() {
            if *slot == 0 {
                *slot = kept;
                mesh.positions[kept as usize] = mesh.positions[old];
                mesh.surfaces[kept as usize] = mesh.surfaces[old];
                kept += 1;
            }
        }
        mesh.positions.truncate(kept as usize);
        mesh.surfaces.truncate(kept as usize);
        for t in &mut mesh.triangles {
            *t = t.map(|v| remap[v as usize]);
        }
        mesh
    }
}
