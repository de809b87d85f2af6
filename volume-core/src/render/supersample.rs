//! Supersampling (anti-aliasing): a frame is rendered at `k` times its size on each axis
//! and each `k × k` block of samples is averaged into one pixel (a box filter).
//!
//! Colours are linear RGB stored as bytes (the renderer writes no transfer curve), so the
//! plain average of the bytes is the average of the light. A pixel's depth is the nearest
//! first hit of its samples: the pixel shows a surface wherever one of its samples does.

use crate::render::renderer::Frame;

/// Largest accepted supersampling factor per axis (64 samples per pixel).
pub const MAX_SUPERSAMPLE: u32 = 8;

/// Averages each `k × k` block of `fine` (`k` times `coarse`'s size on each axis) into one
/// pixel of `coarse`, keeping `fine`'s statistics and time.
pub(crate) fn downsample_into(fine: &Frame, k: u32, coarse: &mut Frame) {
    let (w, h) = (fine.width / k, fine.height / k);
    let (w_us, k_us) = (w as usize, k as usize);
    let fine_w = fine.width as usize;
    coarse.width = w;
    coarse.height = h;
    coarse.scale = 1;
    coarse.rgba8.clear();
    coarse.rgba8.resize(w_us * h as usize * 4, 0);
    coarse.depth.clear();
    coarse.depth.resize(w_us * h as usize, f32::INFINITY);
    let samples = k * k;
    for y in 0..h as usize {
        for x in 0..w_us {
            let mut sum = [0u32; 4];
            let mut nearest = f32::INFINITY;
            for sy in 0..k_us {
                let row = (y * k_us + sy) * fine_w + x * k_us;
                for i in row..row + k_us {
                    for (c, s) in sum.iter_mut().enumerate() {
                        *s += u32::from(fine.rgba8[i * 4 + c]);
                    }
                    nearest = nearest.min(fine.depth[i]);
                }
            }
            let o = y * w_us + x;
            for (c, s) in sum.iter().enumerate() {
                // Rounded to nearest.
                coarse.rgba8[o * 4 + c] = ((s + samples / 2) / samples) as u8;
            }
            coarse.depth[o] = nearest;
        }
    }
    coarse.counts = fine.counts;
    coarse.rays = fine.rays;
    coarse.elapsed = fine.elapsed;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blocks_average_to_one_pixel_and_keep_the_nearest_depth() {
        // 4x2 samples, k = 2: two pixels.
        let mut fine = Frame {
            width: 4,
            height: 2,
            scale: 1,
            ..Frame::default()
        };
        let values: [u8; 8] = [0, 255, 10, 20, 255, 255, 30, 41];
        fine.rgba8 = values.iter().flat_map(|&v| [v, v / 2, 7, 255]).collect();
        fine.depth = vec![
            f32::INFINITY,
            3.0,
            5.0,
            6.0,
            2.5,
            f32::INFINITY,
            f32::INFINITY,
            f32::INFINITY,
        ];
        let mut coarse = Frame::default();
        downsample_into(&fine, 2, &mut coarse);
        assert_eq!((coarse.width, coarse.height), (2, 1));
        // Pixel 0: samples 0, 1, 4, 5 = 0, 255, 255, 255 → 191.25 → 191.
        assert_eq!(coarse.rgba8[0], 191);
        // Green is v / 2: 0, 127, 127, 127, rounded to nearest.
        assert_eq!(coarse.rgba8[1], ((3 * 127 + 2) / 4) as u8);
        assert_eq!(coarse.rgba8[3], 255);
        // Pixel 1: 10, 20, 30, 41 → 25.25 → 25.
        assert_eq!(coarse.rgba8[4], 25);
        assert_eq!(coarse.depth, vec![2.5, 5.0]);
    }
}
