//! The geometry-image method's results as files: the input displaced by the synthesized
//! relief and what shows it (Lai, Hu, Gu & Martin, "Geometric Texture Synthesis and Transfer
//! via Geometry Images", §4.4, in ../shared/papers/geometry-images-geometric-texture.txt).
//!
//! §4.4 adds each synthesized texel to its grid point in the local frame, with flip avoidance
//! (§4.4.1): that is [`super::displacement`], run here with the texel unit S̄ of the input
//! (the median sample spacing, [`reference_spacing`]). The paper stops at the displaced
//! model; the files are ours:
//! - `relief.obj`, `relief.ply` (vertex colours when the sample has colour) and `relief.glb`
//!   (shared vertices with area-weighted normals, so the relief is not faceted; colours made
//!   linear);
//! - `geometry_image.exr` and `geometry_image_normals.exr`: the input's geometry image;
//! - `sample_relief.png` and `synthesized_relief.png`: the dn channel in grey, ±3σ about its
//!   mean;
//! - `preview.png`: three views of the displaced mesh, and `relief_map.png`: the synthesized
//!   dn painted on the undisplaced surface, unlit, which shows how the texture lies on the
//!   shape (orientation, scale, seams) without the shading of the displacement.

use super::displacement::{DisplacementParams, displace, grid_mesh};
use crate::export::encode_png;
use crate::field::param_field::{local_spacing, reference_spacing};
use crate::geom::Mesh;
use crate::geom::geometry_image::{GeometryImage, TexelImage};
use crate::render::up_axis::UpAxis;
use glam::Vec3;
use serde::{Deserialize, Serialize};
use texsyn_core::algorithm::Failure;

/// The `displacement` node's algorithm and version (part of its key; bump on any change of output).
pub const NODE: texsyn_core::algorithm::Algorithm =
    texsyn_core::algorithm::Algorithm::new("displacement", 6);

/// `[reconstruct]` of the geometry-image method: the displacement (§4.4) and the preview.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct ReliefExportParams {
    /// Multiplies the relief, 0..=100. Default: 1.
    pub amplitude: f32,
    /// Increasing steps in which the texture is added (§4.4.1), 1..=100. Default: 10.
    pub steps: u32,
    /// A sample stops growing where a triangle's normal turns by more than this, degrees,
    /// 1..=180. Default: 150 (the paper's example).
    pub flip_angle: f32,
    /// Side of each preview view, 16..=4096. Default: 512.
    pub preview_size: u32,
    /// The mesh's up direction in the previews, or `"auto"` (the default): guessed from the
    /// mesh, the side it stands on most steadily ([`crate::render::up_axis`]). Left out of the
    /// node's key when `"auto"`.
    #[serde(skip_serializing_if = "UpAxis::is_auto")]
    pub up: UpAxis,
}

impl ReliefExportParams {
    /// The displacement's own parameters.
    pub fn displacement(&self) -> DisplacementParams {
        DisplacementParams {
            amplitude: self.amplitude,
            steps: self.steps,
            flip_angle: self.flip_angle,
        }
    }
}

impl Default for ReliefExportParams {
    fn default() -> Self {
        let d = DisplacementParams::default();
        ReliefExportParams {
            amplitude: d.amplitude,
            steps: d.steps,
            flip_angle: d.flip_angle,
            preview_size: 512,
            up: UpAxis::default(),
        }
    }
}

/// Why the files could not be written.
#[derive(Debug, thiserror::Error)]
pub enum ReliefExportError {
    #[error("{file}: {source}")]
    Exr {
        file: &'static str,
        source: crate::export::exr::ExrError,
    },
}

/// The output files, by name: the displaced mesh (OBJ, PLY, .glb), the input's geometry image
/// as EXR, the sample's (`sample`) and the synthesized (`texels`) relief as grey images, and
/// the previews. `progress` receives fractions of the work done.
pub fn export_relief(
    gi: &GeometryImage,
    texels: &TexelImage,
    sample: &TexelImage,
    p: &ReliefExportParams,
    progress: &dyn Fn(f32),
) -> Result<Vec<(String, Vec<u8>)>, ReliefExportError> {
    let n = gi.n as usize;
    let unit = reference_spacing(&local_spacing(gi));
    let displaced = displace(gi, texels, unit, &p.displacement());
    if displaced.held_back > 0 {
        tracing::info!(
            "reconstruct: flip avoidance held {} of {} samples short of their full displacement",
            displaced.held_back,
            n * n
        );
    }
    progress(0.3);
    let (mesh, samples) = grid_mesh(gi, &displaced.positions);
    let colors: Option<Vec<[f32; 4]>> = (texels.channels == 6).then(|| {
        samples
            .iter()
            .map(|&s| {
                let t = texels.texel(s % gi.n, s / gi.n);
                [t[3], t[4], t[5], 1.0]
            })
            .collect()
    });
    let mesh = Mesh::with_colors(mesh.positions, mesh.triangles, colors);
    let exr = |file: &'static str, values: &[Vec3]| {
        crate::export::exr::write_exr_rgb(gi.n, gi.n, values)
            .map(|bytes| (file.to_string(), bytes))
            .map_err(|source| ReliefExportError::Exr { file, source })
    };
    let mut files = vec![
        (
            "relief.obj".to_string(),
            crate::export::write_obj(&mesh, None, None, "relief").into_bytes(),
        ),
        (
            "relief.ply".to_string(),
            crate::geom::io::write_ply(&mesh, mesh.colors.as_deref()),
        ),
        (
            "relief.glb".to_string(),
            crate::export::write_glb(&glb_of(&mesh)),
        ),
    ];
    progress(0.5);
    files.push(exr("geometry_image.exr", &gi.positions)?);
    files.push(exr("geometry_image_normals.exr", &gi.normals)?);
    files.push(("sample_relief.png".into(), dn_png(sample)));
    files.push(("synthesized_relief.png".into(), dn_png(texels)));
    progress(0.6);
    let opts = crate::render::ViewOptions {
        size: p.preview_size,
        up: p
            .up
            .resolve(&mesh.positions, &mesh.triangles, "reconstruct"),
        ..Default::default()
    };
    let preview = match crate::render::VertexColorShader::from_mesh(&mesh) {
        Some(s) => crate::render::render_views(&mesh, &s, &opts),
        None => crate::render::render_views(
            &mesh,
            &crate::render::ConstantShader(Vec3::splat(0.8)),
            &opts,
        ),
    };
    files.push(("preview.png".into(), encode_png(&preview, false)));
    files.push(("relief_map.png".into(), relief_map(gi, texels, opts)));
    progress(1.0);
    Ok(files)
}

/// The grey image of a texel image's dn channel, mapped from [-3σ, 3σ] around its mean.
pub fn dn_png(t: &TexelImage) -> Vec<u8> {
    let c = t.channels as usize;
    let dn: Vec<f32> = t.data.chunks(c).map(|x| x[2]).collect();
    let n = dn.len().max(1) as f64;
    let mean = dn.iter().map(|&v| v as f64).sum::<f64>() / n;
    let sd = (dn.iter().map(|&v| (v as f64 - mean).powi(2)).sum::<f64>() / n)
        .sqrt()
        .max(1e-12);
    let mut img = image::RgbaImage::new(t.width, t.height);
    for (px, v) in img.pixels_mut().zip(&dn) {
        let g = (((*v as f64 - mean) / (6.0 * sd) + 0.5).clamp(0.0, 1.0) * 255.0).round() as u8;
        px.0 = [g, g, g, 255];
    }
    encode_png(&img, false)
}

/// The synthesized relief (dn, grey from −3σ to 3σ about its mean) painted on the undisplaced
/// surface, unlit: how the texture lies on the shape without the displacement's shading.
fn relief_map(
    gi: &GeometryImage,
    texels: &TexelImage,
    opts: crate::render::ViewOptions,
) -> Vec<u8> {
    let (flat, flat_samples) = grid_mesh(gi, &gi.positions);
    let dn: Vec<f32> = flat_samples
        .iter()
        .map(|&s| texels.texel(s % gi.n, s / gi.n)[2])
        .collect();
    let mean = dn.iter().sum::<f32>() / dn.len().max(1) as f32;
    let sd = (dn.iter().map(|v| (v - mean) * (v - mean)).sum::<f32>() / dn.len().max(1) as f32)
        .sqrt()
        .max(1e-12);
    let grey: Vec<[f32; 4]> = dn
        .iter()
        .map(|v| {
            let g = ((v - mean) / (6.0 * sd) + 0.5).clamp(0.0, 1.0);
            [g, g, g, 1.0]
        })
        .collect();
    let shader = crate::render::VertexColorShader::new(&flat.triangles, &grey);
    let map = crate::render::render_views(
        &flat,
        &shader,
        &crate::render::ViewOptions { lit: false, ..opts },
    );
    encode_png(&map, false)
}

/// A .glb of the displaced mesh: unwelded corners with face normals would facet the relief,
/// so vertices are shared and carry area-weighted normals; colours (sRGB in the texels)
/// become linear COLOR_0.
pub fn glb_of(mesh: &Mesh) -> crate::export::GlbMesh {
    crate::export::GlbMesh {
        name: "relief".into(),
        positions: mesh.positions.clone(),
        normals: mesh.vertex_normals().to_vec(),
        colors: mesh.colors.as_ref().map(|c| {
            c.iter()
                .map(|x| {
                    let l = |v: f32| crate::render::srgb::to_linear(v.clamp(0.0, 1.0));
                    [l(x[0]), l(x[1]), l(x[2]), x[3]]
                })
                .collect()
        }),
        indices: mesh.triangles.iter().flatten().copied().collect(),
        material: crate::export::GlbMaterial {
            double_sided: true,
            roughness: 0.6,
            ..Default::default()
        },
        ..Default::default()
    }
}

/// The reconstruct node: the relief's files.
pub fn node(
    gi: &GeometryImage,
    texels: &TexelImage,
    sample: &TexelImage,
    p: &ReliefExportParams,
    progress: &dyn Fn(f32),
) -> Result<Vec<(String, Vec<u8>)>, Failure> {
    export_relief(gi, texels, sample, p, progress).map_err(Failure::input)
}
