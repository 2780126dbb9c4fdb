//! OpenEXR export of float grids (geometry images: x, y, z as R, G, B) and of RGB volumes
//! (solid textures: one part per z-slice of a multi-part file).

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

/// A multi-part EXR of an RGB volume of `dims` voxels given as 8-bit values (x fastest, then
/// y, then z, three bytes a voxel: the layout of a raw volume): part `z` (named `z0000`,
/// `z0001`, …) is slice `z`, row 0 at the top as in the raw volume's row order (y = 0 first).
/// Each byte `b` is stored as the half float `b / 255`, which converts back to `b` exactly,
/// so the file holds the raw volume's values and nothing else. Uncompressed, for the same
/// reason as [`write_exr_rgb`].
pub fn write_exr_volume(dims: [u32; 3], rgb8: &[u8]) -> std::result::Result<Vec<u8>, ExrError> {
    let [w, h, d] = dims.map(|x| x as usize);
    assert_eq!(rgb8.len(), w * h * d * 3, "three bytes per voxel");
    let size = Vec2(w, h);
    let layers: Vec<Layer<AnyChannels<FlatSamples>>> = (0..d)
        .map(|z| {
            let slice = &rgb8[z * w * h * 3..(z + 1) * w * h * 3];
            let channel = |name: &str, c: usize| {
                let values: Vec<f16> = slice
                    .chunks_exact(3)
                    .map(|px| f16::from_f32(px[c] as f32 / 255.0))
                    .collect();
                AnyChannel::new(name, FlatSamples::F16(values))
            };
            let list: SmallVec<[AnyChannel<FlatSamples>; 4]> =
                SmallVec::from_vec(vec![channel("R", 0), channel("G", 1), channel("B", 2)]);
            Layer::new(
                size,
                LayerAttributes::named(format!("z{z:04}").as_str()),
                Encoding::UNCOMPRESSED,
                AnyChannels::sort(list),
            )
        })
        .collect();
    let image = Image::from_layers(
        ImageAttributes::new(IntegerBounds::from_dimensions(size)),
        layers,
    );
    let mut out = std::io::Cursor::new(Vec::new());
    image.write().non_parallel().to_buffered(&mut out)?;
    Ok(out.into_inner())
}

/// The 8-bit value a half float of [`write_exr_volume`] stands for.
pub fn byte_of_unit(x: f32) -> u8 {
    (x.clamp(0.0, 1.0) * 255.0 + 0.5) as u8
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each part's name and its voxels' bytes, read with the exr crate.
    pub(crate) fn read_parts(bytes: &[u8]) -> Vec<(String, [usize; 2], Vec<u8>)> {
        let img = exr::prelude::read()
            .no_deep_data()
            .largest_resolution_level()
            .all_channels()
            .all_layers()
            .all_attributes()
            .from_buffered(std::io::Cursor::new(bytes))
            .unwrap();
        img.layer_data
            .iter()
            .map(|layer| {
                let name = layer.attributes.layer_name.as_ref().unwrap().to_string();
                let n = layer.size.area();
                let mut out = vec![0u8; n * 3];
                for ch in &layer.channel_data.list {
                    let c = match ch.name.to_string().as_str() {
                        "R" => 0,
                        "G" => 1,
                        "B" => 2,
                        other => panic!("channel {other}"),
                    };
                    for i in 0..n {
                        out[i * 3 + c] =
                            byte_of_unit(ch.sample_data.value_by_flat_index(i).to_f32());
                    }
                }
                (name, [layer.size.x(), layer.size.y()], out)
            })
            .collect()
    }

    #[test]
    fn a_volume_reads_back_slice_by_slice() {
        let dims = [3u32, 2, 4];
        let raw: Vec<u8> = (0..3 * 2 * 4 * 3).map(|i| (i * 37 % 256) as u8).collect();
        let bytes = write_exr_volume(dims, &raw).unwrap();
        let parts = read_parts(&bytes);
        assert_eq!(parts.len(), 4);
        for (z, (name, size, px)) in parts.iter().enumerate() {
            assert_eq!(*name, format!("z{z:04}"));
            assert_eq!(*size, [3, 2]);
            assert_eq!(px[..], raw[z * 18..(z + 1) * 18]);
        }
        assert_eq!(
            bytes,
            write_exr_volume(dims, &raw).unwrap(),
            "deterministic"
        );
        // Every byte value survives the half float.
        for b in 0..=255u8 {
            assert_eq!(byte_of_unit(f16::from_f32(b as f32 / 255.0).to_f32()), b);
        }
    }

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
