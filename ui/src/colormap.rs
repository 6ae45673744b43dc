//! Depth images to egui textures with the core's JET colour map (display only: metres become millimetres here).

use tactile_derender::image::Image;
use tactile_derender::io::preview;

/// Colourise `image` over `range` (metres) as an egui image; zeros are "missing" when `zero_is_missing`.
pub fn to_color_image(image: &Image, range: (f32, f32), zero_is_missing: bool) -> egui::ColorImage {
    let rgb = preview::colorize(image, range, zero_is_missing);
    egui::ColorImage::from_rgb([image.width, image.height], rgb.as_raw())
}
