//! PNG encoding of 8-bit images into memory (previews, bakes, grey maps).

use image::ImageEncoder;

/// The PNG bytes of `img`: RGBA if `keep_alpha`, else RGB with the alpha channel dropped.
/// Deterministic for a given `image` version (pinned by Cargo.lock).
pub fn encode_png(img: &image::RgbaImage, keep_alpha: bool) -> Vec<u8> {
    let mut out = Vec::new();
    let encoder = image::codecs::png::PngEncoder::new(&mut out);
    let result = if keep_alpha {
        encoder.write_image(
            img.as_raw(),
            img.width(),
            img.height(),
            image::ExtendedColorType::Rgba8,
        )
    } else {
        let rgb: Vec<u8> = img
            .pixels()
            .flat_map(|p| [p.0[0], p.0[1], p.0[2]])
            .collect();
        encoder.write_image(
            &rgb,
            img.width(),
            img.height(),
            image::ExtendedColorType::Rgb8,
        )
    };
    result.expect("PNG encoding into memory");
    out
}
