//! OpenEXR export of float grids (geometry images: x, y, z as R, G, B).

use exr::prelude::*;
use glam::Vec3;

/// Why the EXR encoder failed.
#[derive(Debug, thiserror::Error)]
#[error(transparent)]
pub struct ExrError(#[from] exr::error::Error);

/// An RGB float EXR of a `width × height` grid of vectors, row 0 at the top. Uncompressed
/// (ZIP would be smaller, but uncompressed bytes are the same on every exr version).
pub fn write_exr_rgb(
    width: u32,
    height: u32,
    values: &[Vec3],
) -> std::result::Result<Vec<u8>, ExrError> {
    assert_eq!(
        values.len(),
        width as usize * height as usize,
        "one value per pixel"
    );
    let channels = SpecificChannels::rgb(|pos: Vec2<usize>| {
        let v = values[pos.y() * width as usize + pos.x()];
        (v.x, v.y, v.z)
    });
    let layer = Layer::new(
        (width as usize, height as usize),
        LayerAttributes::named("geometry"),
        Encoding::UNCOMPRESSED,
        channels,
    );
    let image = Image::from_layer(layer);
    let mut out = std::io::Cursor::new(Vec::new());
    image.write().non_parallel().to_buffered(&mut out)?;
    Ok(out.into_inner())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_read_back_exactly() {
        let vals: Vec<Vec3> = (0..12)
            .map(|i| Vec3::new(i as f32, -0.5 * i as f32, 1e-3 * i as f32))
            .collect();
        let bytes = write_exr_rgb(4, 3, &vals).unwrap();
        let img = crate::image::decode_image(std::path::Path::new("g.exr"), &bytes).unwrap();
        assert_eq!((img.width, img.height), (4, 3));
        for (p, v) in img.pixels.iter().zip(&vals) {
            assert_eq!([p[0], p[1], p[2]], [v.x, v.y, v.z]);
        }
        assert_eq!(bytes, write_exr_rgb(4, 3, &vals).unwrap(), "deterministic");
    }
}
