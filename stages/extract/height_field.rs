//! Height-field sampling (Lai et al., "Geometric Texture Synthesis and Transfer via Geometry
//! Images", §4.1.3) and images as height fields (§5, the leather example: "intensity in the
//! image is converted to height above a plane").
//!
//! Meshes: the plane is fitted as in §4.1.2
//! ([`fit_plane_ransac`](super::planar_ransac::fit_plane_ransac)); the vertices are projected
//! straight onto it ("without the need to perform a parameterization"), an N×N grid is sampled
//! in the largest square of the projected patch, and each sample's height is that of the
//! highest point of the patch on the line through it along the plane's normal (projected
//! triangles overlap where the relief overhangs). Texels are (0, 0, h − mean h).
//!
//! Images: every pixel becomes a texel (0, 0, (grey − mean grey) × height_scale), row y of the
//! image being texel row y; a colour image's grey is its luma (see [`height_field_image`]).

use super::planar_ransac::{
    PlanarExtraction, Plane, RansacParams, fit_sampling_plane, largest_square_on_plane,
    sample_square,
};
use super::{ExtractError, ParamError};
use crate::geom::Mesh;
use crate::geom::geometry_image::TexelImage;
use crate::image::ImageView;
use glam::Vec2;
use std::path::Path;
use texsyn_core::algorithm::Failure;

/// The `height_field_image` node's algorithm and version (part of its key; bump on any change of output).
pub const NODE: texsyn_core::algorithm::Algorithm =
    texsyn_core::algorithm::Algorithm::new("height_field_image", 1);

/// §4.1.3 on a connected sample patch: `size`×`size` texels (0, 0, h − mean h[, r, g, b]).
/// The returned plane is the fitted one moved to the mean height, so that texel heights are
/// measured from it.
pub fn mesh_height_field(
    patch: &Mesh,
    size: u32,
    params: &RansacParams,
    progress: &(dyn Fn(f32) + Sync),
) -> Result<PlanarExtraction, ExtractError> {
    let fit = fit_sampling_plane(patch, size, params)?;
    progress(0.3);
    let coords: Vec<glam::Vec3> = patch
        .positions
        .iter()
        .map(|&p| fit.plane.coords(p))
        .collect();
    let uv: Vec<Vec2> = coords.iter().map(|c| Vec2::new(c.x, c.y)).collect();
    let (plane, uv, square) = largest_square_on_plane(
        patch,
        &fit.plane,
        &uv,
        "its projection onto its plane holds no square",
    )?;
    progress(0.7);
    let channels = super::channels_for(patch);
    let mut texels = sample_square(
        patch,
        &uv,
        &square,
        size,
        |locator, q| {
            // The highest crossing (first triangle on ties), else the nearest triangle.
            let mut best: Option<(f32, u32, [f32; 3])> = None;
            for (f, w) in locator.containing(q) {
                let tri = patch.triangles[f as usize];
                let h = coords[tri[0] as usize].z * w[0]
                    + coords[tri[1] as usize].z * w[1]
                    + coords[tri[2] as usize].z * w[2];
                if best.is_none_or(|b| h > b.0) {
                    best = Some((h, f, w));
                }
            }
            best.map(|(_, f, w)| (f, w)).or_else(|| locator.nearest(q))
        },
        |t, _, p| t[2] = plane.coords(p).z,
    );
    // Mean height in a fixed order.
    let c = channels as usize;
    let mean =
        texels.data.chunks(c).map(|t| t[2] as f64).sum::<f64>() / (size as f64 * size as f64);
    for t in texels.data.chunks_mut(c) {
        t[2] = (t[2] as f64 - mean) as f32;
    }
    progress(1.0);
    Ok(PlanarExtraction {
        texels,
        // The heights are measured from the mean height.
        plane: Plane {
            origin: plane.origin + mean as f32 * plane.normal,
            ..plane
        },
        square,
        inliers: fit.inliers,
    })
}

/// Whether a sample file is an image (read as a height field, §5) rather than a mesh: by its
/// extension, as the readers choose their format.
pub fn is_image_path(path: &Path) -> bool {
    matches!(
        path.extension()
            .and_then(|e| e.to_str())
            .map(|e| e.to_ascii_lowercase())
            .as_deref(),
        Some("png" | "jpg" | "jpeg" | "exr")
    )
}

/// Largest difference between an image's r, g and b that still counts as grey.
const GREY_TOLERANCE: f32 = 2.0 / 255.0;

/// Rec. 709 luma weights of r, g and b.
const LUMA: [f64; 3] = [0.2126, 0.7152, 0.0722];

/// An image read as a height field, and the warning to give about it (`Some` when it was a
/// colour image and its luma was used).
#[derive(Debug)]
pub struct HeightFieldImage {
    pub texels: TexelImage,
    pub warning: Option<String>,
}

/// An image as a height field (§5): texels (0, 0, (grey − mean grey) × `height_scale`), as
/// many as the image has pixels. `path` names the image in errors; the image must be at least
/// `min_size` pixels on each side (the synthesis template's size).
///
/// Grey is the mean of r, g and b when every pixel is grey (within 2/255). A colour image (a
/// photograph of a relief) is read by its luma, Rec. 709 weights of the sRGB-encoded r, g and
/// b as image tools convert to greyscale (no decoding to linear light: brightness as it looks,
/// and no transcendental function in the hashed path), with a warning naming the first colour
/// pixel; with `strict_grey` it is refused instead, naming that pixel. The paper's leather
/// example only says "intensity".
pub fn height_field_image(
    path: &Path,
    img: ImageView,
    height_scale: f32,
    min_size: u32,
    strict_grey: bool,
) -> Result<HeightFieldImage, ExtractError> {
    if !height_scale.is_finite() {
        return Err(ParamError::invalid(
            "height_scale",
            format!("must be a finite number, got {height_scale}"),
        )
        .into());
    }
    if img.width < min_size.max(1) || img.height < min_size.max(1) {
        return Err(ExtractError::TooSmall {
            path: path.to_owned(),
            width: img.width,
            height: img.height,
            min: min_size.max(1),
        });
    }
    let expected = img.width as usize * img.height as usize;
    if img.pixels.len() != expected {
        return Err(ExtractError::PixelCount {
            path: path.to_owned(),
            pixels: img.pixels.len(),
            expected,
            width: img.width,
            height: img.height,
        });
    }
    let mut warning = None;
    for (i, p) in img.pixels.iter().enumerate() {
        if p[..3].iter().any(|c| !c.is_finite()) {
            return Err(ExtractError::NotFinite {
                path: path.to_owned(),
                x: i as u32 % img.width,
                y: i as u32 / img.width,
            });
        }
        let (lo, hi) = (p[0].min(p[1]).min(p[2]), p[0].max(p[1]).max(p[2]));
        if hi - lo > GREY_TOLERANCE && warning.is_none() {
            let (x, y) = (i as u32 % img.width, i as u32 / img.width);
            if strict_grey {
                return Err(ExtractError::NotGreyscale {
                    path: path.to_owned(),
                    x,
                    y,
                    r: p[0],
                    g: p[1],
                    b: p[2],
                });
            }
            warning = Some(format!(
                "{}: a colour image (pixel ({x}, {y}) is r, g, b = {:.3}, {:.3}, {:.3}); its \
                 heights are its luma (0.2126 r + 0.7152 g + 0.0722 b). Set \
                 extract.strict_grey = true to refuse colour images",
                path.display(),
                p[0],
                p[1],
                p[2]
            ));
        }
    }
    let grey = |p: &[f32; 4]| {
        if warning.is_some() {
            LUMA[0] * p[0] as f64 + LUMA[1] * p[1] as f64 + LUMA[2] * p[2] as f64
        } else {
            (p[0] as f64 + p[1] as f64 + p[2] as f64) / 3.0
        }
    };
    let mean = img.pixels.iter().map(grey).sum::<f64>() / expected as f64;
    let mut texels = TexelImage::new(img.width, img.height, 3);
    for (t, p) in texels.data.chunks_mut(3).zip(img.pixels) {
        t[2] = ((grey(p) - mean) * height_scale as f64) as f32;
    }
    Ok(HeightFieldImage { texels, warning })
}

/// The key of an image sample's extraction: its height scale (the other `[extract]` keys are
/// for mesh samples), and what its size is checked against.
#[derive(Debug, Clone, serde::Serialize)]
pub struct HeightFieldKey {
    pub height_scale: f32,
    /// Left out when false: configs that do not set it keep their keys.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub strict_grey: bool,
    /// The variants whose candidates the size is checked against (the template synthesizer);
    /// left out when none (the appearance synthesizer, which checks the sides alone), so that a
    /// cached extraction never skips a check the run needs.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub template_variants: Option<crate::analyse_exemplar::texel_variants::TexelVariantParams>,
}

/// The extract node of an image sample (§5; a colour image by its luma, with a warning,
/// unless `strict_grey`), heights in units of the texel spacing (one pixel). Its size is only
/// known once it is read, so `fits` checks it against the analysis here, where the error can
/// name the sample.
pub fn node(
    path: &Path,
    img: ImageView,
    key: &HeightFieldKey,
    fits: impl Fn(u32, u32) -> Result<(), String>,
) -> Result<TexelImage, Failure> {
    let h = height_field_image(path, img, key.height_scale, 1, key.strict_grey)
        .map_err(Failure::input)?;
    if let Some(w) = &h.warning {
        tracing::warn!("{w}");
    }
    let t = h.texels;
    fits(t.width, t.height)
        .map_err(|e| Failure::input(format!("the sample {}: {e}", path.display())))?;
    Ok(t)
}
