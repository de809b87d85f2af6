//! Which samples of a frame can see a surface at all: the scene's live boxes
//! ([`IsoScene::live_boxes`]; for a grid, the kd-tree's live nodes at a coarse level)
//! projected to the screen (`RayGen::screen_rect`: the boxes' corners, padded by a pixel),
//! as one bit per sample. A sample outside every projection has a ray that passes beside
//! every live box, so beside every surface: the renderer makes no ray for it. The one live
//! box the rays are clipped to ([`IsoScene::live_bounds`]) lets through the rays that cross
//! its corners beside the surface (around a head's silhouette); the coarse boxes do not.
//!
//! [`IsoScene::live_boxes`]: super::IsoScene::live_boxes
//! [`IsoScene::live_bounds`]: super::IsoScene::live_bounds

use super::camera::RayGen;
use super::renderer::TILE;
use crate::math::Aabb;

/// One bit per sample: bit `x % 64` of word `x / 64` of sample row `y`'s words, set where
/// the sample's ray may meet a live box. 64-bit words: filling a box's rectangle costs a
/// word or two per row (a tenth of a millisecond for the MNI frame's boxes).
#[derive(Debug, Clone)]
pub(crate) struct Coverage {
    words_per_row: usize,
    bits: Vec<u64>,
}

const _: () = assert!(64 % TILE == 0, "a tile row's bits lie in one word");

impl Coverage {
    /// The samples of a `samples[0] × samples[1]` grid (each `scale × scale` pixels of the
    /// image, its ray through the block's centre as the renderer shoots it) whose ray may
    /// meet one of `boxes`. `None` when some box has no bounded projection (a corner at or
    /// behind the eye plane of a pinhole): then any sample may.
    pub(crate) fn new(
        raygen: &RayGen,
        boxes: &[Aabb],
        samples: [u32; 2],
        scale: u32,
    ) -> Option<Self> {
        let words_per_row = samples[0].div_ceil(64) as usize;
        let mut bits = vec![0u64; samples[1] as usize * words_per_row];
        for b in boxes {
            let [x0, x1, y0, y1] = raygen.screen_rect(b)?;
            let (Some((first, last)), Some(ys)) = (
                sample_span(x0, x1, samples[0], scale),
                sample_span(y0, y1, samples[1], scale),
            ) else {
                continue;
            };
            for y in ys.0..=ys.1 {
                let row = &mut bits[y * words_per_row..(y + 1) * words_per_row];
                for (w, word) in row
                    .iter_mut()
                    .enumerate()
                    .take(last / 64 + 1)
                    .skip(first / 64)
                {
                    let lo = first.max(64 * w) - 64 * w;
                    let hi = last.min(64 * w + 63) - 64 * w;
                    // Bits lo..=hi.
                    *word |= (u64::MAX >> (63 - hi)) & (u64::MAX << lo);
                }
            }
        }
        Some(Self {
            words_per_row,
            bits,
        })
    }

    /// The bits of tile column `tile_x` in sample row `y` (bit `dx`: sample
    /// `tile_x · TILE + dx`).
    #[inline]
    pub(crate) fn row(&self, tile_x: u32, y: u32) -> u32 {
        let x = (tile_x * TILE) as usize;
        let word = self.bits[y as usize * self.words_per_row + x / 64];
        ((word >> (x % 64)) & ((1 << TILE) - 1)) as u32
    }
}

/// The samples `[first, last]` (of `n`, each `scale` pixels) whose centre may lie in the
/// pixel range `[a, b]`, a sample wider on each side (the last sample's centre sits left of
/// a full block's; the margin also covers the rounding of the centres); `None` when none.
fn sample_span(a: f32, b: f32, n: u32, scale: u32) -> Option<(usize, usize)> {
    if a > b || n == 0 {
        return None;
    }
    let s = f64::from(scale);
    // A full block's centre is `i·s + s/2`.
    let first = ((f64::from(a) - 0.5 * s) / s).floor() - 1.0;
    let last = ((f64::from(b) - 0.5 * s) / s).floor() + 1.0;
    let max = f64::from(n - 1);
    if last < 0.0 || first > max {
        return None;
    }
    Some((first.max(0.0) as usize, last.min(max) as usize))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::rng::Rng;
    use crate::render::{Camera, Projection};
    use glam::Vec3;

    /// Brute force: every sample whose ray (as the renderer shoots it) meets one of a few
    /// random boxes is covered, for random cameras, image sizes and progressive scales;
    /// and the mask is not trivially full.
    #[test]
    fn every_sample_whose_ray_meets_a_box_is_covered() {
        let mut rng = Rng::new(41);
        let (mut met, mut uncovered) = (0usize, 0usize);
        for case in 0..60 {
            let cam = Camera {
                eye: rng.vec3(-5.0, 5.0),
                target: rng.vec3(-0.5, 0.5),
                up: Vec3::new(0.1, 0.2, 1.0),
                vfov_deg: rng.range_f32(20.0, 70.0),
                projection: if case % 3 == 0 {
                    Projection::Orthographic
                } else {
                    Projection::Pinhole
                },
                ortho_height: None,
            };
            let (w, h) = (rng.below(90) + 7, rng.below(70) + 5);
            let scale = [1, 1, 2, 3][rng.index(4)];
            let raygen = RayGen::new(&cam, w, h);
            let boxes: Vec<Aabb> = (0..=rng.index(4))
                .map(|_| {
                    let c = rng.vec3(-1.0, 1.0);
                    let e = rng.vec3(0.01, 0.4);
                    Aabb::new(c - e, c + e)
                })
                .collect();
            let samples = [w.div_ceil(scale), h.div_ceil(scale)];
            let Some(cover) = Coverage::new(&raygen, &boxes, samples, scale) else {
                continue;
            };
            let centre = |i: u32, n: u32| {
                (i as f32 * scale as f32 + ((i + 1) as f32 * scale as f32).min(n as f32)) * 0.5
            };
            for sy in 0..samples[1] {
                for sx in 0..samples[0] {
                    let ray = raygen.ray_at(centre(sx, w), centre(sy, h));
                    let covered = cover.row(sx / TILE, sy) >> (sx % TILE) & 1 == 1;
                    let meets = boxes
                        .iter()
                        .any(|b| b.intersect(&ray, 0.0, f32::INFINITY).is_some());
                    if meets {
                        met += 1;
                        assert!(covered, "case {case}: sample ({sx}, {sy}) meets a box");
                    } else if !covered {
                        uncovered += 1;
                    }
                }
            }
        }
        assert!(met > 1000, "{met} samples met a box");
        assert!(uncovered > 1000, "{uncovered} samples were left out");
    }

    #[test]
    fn spans_clamp_to_the_samples() {
        assert_eq!(sample_span(5.0, 2.0, 10, 1), None);
        assert_eq!(sample_span(-50.0, -10.0, 10, 1), None);
        assert_eq!(sample_span(30.0, 50.0, 10, 1), None);
        assert_eq!(sample_span(f32::NEG_INFINITY, 3.2, 10, 1), Some((0, 3)));
        assert_eq!(sample_span(4.5, 4.5, 10, 1), Some((3, 5)));
        assert_eq!(sample_span(0.0, 1e9, 4, 2), Some((0, 3)));
    }
}
