//! The rendered frame → an egui image, without converting it pixel by pixel.
//!
//! The renderer writes RGBA8 with alpha always 255 (`volume_core::render::Frame`), and for
//! opaque pixels egui's premultiplied [`Color32`] has the same bytes as unmultiplied RGBA.
//! So the frame's buffer is reinterpreted as `Vec<Color32>` in place (`bytemuck`, no copy)
//! and moved into the [`ColorImage`] that [`egui::TextureHandle::set`] takes. Only a buffer
//! that cannot be reinterpreted in place (its capacity is not a whole number of pixels) is
//! copied, by egui's converting path.

use egui::{Color32, ColorImage};

/// `rgba8` (row 0 at the top, 4 bytes per pixel, opaque) as an image of `size` =
/// `[width, height]` pixels; `None` when the buffer does not hold that many.
pub fn color_image(size: [usize; 2], rgba8: Vec<u8>) -> Option<ColorImage> {
    if size[0] == 0 || size[1] == 0 || rgba8.len() != size[0] * size[1] * 4 {
        return None;
    }
    match bytemuck::allocation::try_cast_vec::<u8, Color32>(rgba8) {
        Ok(pixels) => Some(ColorImage::new(size, pixels)),
        Err((_, rgba8)) => Some(ColorImage::from_rgba_unmultiplied(size, &rgba8)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn opaque_frames_keep_their_bytes() {
        let px = [10u8, 200, 30, 255, 0, 0, 0, 255];
        let img = color_image([2, 1], px.to_vec()).unwrap();
        assert_eq!(
            img.pixels,
            vec![Color32::from_rgb(10, 200, 30), Color32::from_rgb(0, 0, 0)]
        );
        // A capacity that is not whole pixels is copied, with the same result.
        let mut odd = Vec::with_capacity(9);
        odd.extend_from_slice(&px);
        assert_eq!(color_image([2, 1], odd).unwrap().pixels, img.pixels);
        assert!(color_image([2, 2], px.to_vec()).is_none());
        assert!(color_image([0, 1], Vec::new()).is_none());
    }
}
