//! Stage: extract: texture or features taken out of a shape.
//!
//! Geometric texture (Lai et al., "Geometric Texture Synthesis and Transfer via Geometry
//! Images", §4.1): a sample model, or a region of it, becomes a [`TexelImage`] of geometry
//! texels (dx, dy, dn), or (dx, dy, dn, r, g, b) when the sample has vertex colours (§4.1.4).
//! Three extractors, chosen by [`ExtractParams::method`]:
//!
//! - [`bilateral_difference`]: smoothing and differencing on the patch's geometry image
//!   (§4.1.1), for curved samples;
//! - [`planar_ransac`]: a RANSAC plane, the patch parameterized with its boundary projected
//!   onto it, sampled in the largest square of the parameter domain (§4.1.2);
//! - [`height_field`]: heights above the same plane without a parameterization (§4.1.3), and
//!   greyscale images read as height fields (§5, the leather example).
//!
//! [`sample_region::select_region`] cuts the sample patch out of the sample model first, and
//! [`Extraction::texels_in_spacing_units`] expresses the result in the sample's texel spacing
//! (what the synthesis and the displacement expect).

pub mod bilateral_difference;
pub mod crease_lines;
pub mod crest_lines;
pub mod height_field;
pub mod planar_ransac;
pub mod sample_region;
pub mod shape_features;
pub mod square_domain;
pub mod vertex_paths;

use crate::geom::Mesh;
use crate::geom::geometry_image::{Frame, TexelImage};
use crate::parameterize::geometry_image::{GeometryImageParams, build_geometry_image};
use glam::Vec3;
use sample_region::Region;
use serde::{Deserialize, Serialize};
use std::path::PathBuf;
use texsyn_core::algorithm::Failure;

/// The `geometric_texture` node's algorithm and version (part of its key; bump on any change of output).
pub const MESH_TEXTURE_NODE: texsyn_core::algorithm::Algorithm =
    texsyn_core::algorithm::Algorithm::new("geometric_texture", 1);

/// Why a texture could not be extracted. Messages name the input and what was wrong.
#[derive(Debug, thiserror::Error)]
pub enum ExtractError {
    /// A parameter out of range; the message names the field, its range and the value.
    #[error("extract: {0}")]
    Params(#[from] ParamError),
    /// A decoded image whose pixel array disagrees with its size.
    #[error(
        "extract: {}: the image holds {pixels} pixels, {expected} expected for {width}×{height}",
        path.display()
    )]
    PixelCount {
        path: PathBuf,
        pixels: usize,
        expected: usize,
        width: u32,
        height: u32,
    },
    #[error("the sample mesh has no triangles")]
    EmptyMesh,
    #[error(
        "the sample region ({region}) holds no triangles: no triangle of the sample mesh has \
         all three vertices inside it (the mesh's bounding box is {bounds})"
    )]
    EmptyRegion { region: String, bounds: String },
    #[error("the sample mesh's vertex {vertex} has a non-finite position {position}")]
    NonFinite { vertex: usize, position: String },
    #[error(
        "the sample patch ({faces} triangles) has no boundary: {method} extraction projects the \
         patch's boundary onto its plane, so it needs an open patch (choose a region)"
    )]
    NoBoundary { faces: usize, method: &'static str },
    /// A patch that cannot give a texture (zero area, no plane, no square in its domain).
    #[error("the sample patch ({faces} triangles): {message}")]
    DegeneratePatch { faces: usize, message: String },
    #[error("the sample patch ({faces} triangles) could not be parameterized: {message}")]
    Parameterize { faces: usize, message: String },
    #[error("the sample patch's geometry image: {0}")]
    GeometryImage(String),
    #[error("{path}: pixel ({x}, {y}) is not a finite number")]
    NotFinite { path: PathBuf, x: u32, y: u32 },
    #[error(
        "{path}: pixel ({x}, {y}) is not grey (r, g, b = {r:.3}, {g:.3}, {b:.3}): with \
         extract.strict_grey = true a height-field image must be greyscale (channels equal \
         within 2/255); without it, a colour image is read by its luma"
    )]
    NotGreyscale {
        path: PathBuf,
        x: u32,
        y: u32,
        r: f32,
        g: f32,
        b: f32,
    },
    #[error(
        "{path}: the image is {width}×{height}, a sample too small for the template: it needs \
         at least {min}×{min} pixels"
    )]
    TooSmall {
        path: PathBuf,
        width: u32,
        height: u32,
        min: u32,
    },
}

/// Which §4.1 extractor to run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ExtractMethod {
    /// §4.1.1 smoothing and differencing on the patch's geometry image: for curved samples.
    Bilateral,
    /// §4.1.2 planar parameter domain sampling: for almost planar samples whose relief may
    /// overhang.
    Planar,
    /// §4.1.3 height-field sampling: for almost planar samples whose relief is a height field;
    /// also the only method for greyscale images (§5).
    HeightField,
}

/// The `[extract]` section of a config: what to cut out of the sample model and how to turn
/// it into geometry texels. Fields that only one method reads say so.
///
/// ```toml
/// [extract]
/// method = "planar"
/// size = 64
/// region = { shape = "sphere", center = [0.1, 0.4, 0.0], radius = 0.05 }
/// ```
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ExtractParams {
    /// "bilateral" (§4.1.1), "planar" (§4.1.2) or "height_field" (§4.1.3). Default: "planar".
    pub method: ExtractMethod,
    /// Texels per side of the extracted (square) texel image, 8..=1024. The bilateral method
    /// samples the patch's geometry image at the smallest 2^k + 1 ≥ size and keeps its central
    /// size × size samples. Image height fields keep the image's own size. Default: 64.
    pub size: u32,
    /// The part of the sample model to take the texture from (its largest connected piece is
    /// used). Default: none (the whole model's largest connected piece).
    pub region: Option<Region>,
    /// Seed of the random surface samples and RANSAC draws. Default: 1.
    pub seed: u64,
    /// Bilateral: σ1 of eq. 2, in grid units (samples of the geometry image), 0.5..=size; the
    /// window is cut at 3σ1. Larger values take larger bumps for texture. Default: size / 12.
    pub sigma_grid: Option<f32>,
    /// Bilateral: σ2 of eq. 3, in object units, > 0: positions farther apart than about 2σ2
    /// hardly smooth each other. Default: 0.1 × the patch's size (the square root of its
    /// area).
    pub sigma_space: Option<f32>,
    /// Planar and height field: RANSAC iterations (planes through 3 random surface samples),
    /// 1..=1000000. Default: 500.
    pub ransac_iterations: u32,
    /// Planar and height field: RANSAC inlier distance δ, in object units, > 0. It should
    /// exceed the texture's relief and stay below the distance of what is not on the plane.
    /// Default: 0.01 × the patch's size (the square root of its area: 0.018 × the radius of a
    /// flat disc).
    pub inlier_distance: Option<f32>,
    /// Planar and height field: how many area-uniform random surface samples RANSAC fits,
    /// 16..=1000000. Default: 4096.
    pub surface_samples: u32,
    /// Image height fields (§5): object units of height per unit of grey (black 0, white 1),
    /// finite, may be negative to invert the relief. Default: 0.02.
    pub height_scale: f32,
    /// Image height fields: refuse a colour image (naming a colour pixel) instead of reading
    /// it by its luma with a warning. Default: false. (Left out of the parameters' key when
    /// false, so configs without it keep their keys.)
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub strict_grey: bool,
}

impl Default for ExtractParams {
    fn default() -> Self {
        let r = planar_ransac::RansacParams::default();
        ExtractParams {
            method: ExtractMethod::Planar,
            size: 64,
            region: None,
            seed: r.seed,
            sigma_grid: None,
            sigma_space: None,
            ransac_iterations: r.iterations,
            inlier_distance: r.inlier_distance,
            surface_samples: r.samples,
            height_scale: 0.02,
            strict_grey: false,
        }
    }
}

pub(crate) use crate::check::{ParamError, check_range};

pub(crate) fn check_positive(name: &str, v: f32) -> Result<(), ParamError> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(ParamError::invalid(
            name,
            format!("must be a finite number > 0, got {v}"),
        ))
    }
}

impl ExtractParams {
    /// Checks every field; the error names the field, its range and the value.
    pub fn validate(&self) -> Result<(), ParamError> {
        check_range("size", self.size, 8, 1024)?;
        if let Some(r) = &self.region {
            r.validate().map_err(|e| e.within("region"))?;
        }
        self.bilateral().validate()?;
        self.ransac().validate()?;
        if !self.height_scale.is_finite() {
            return Err(ParamError::invalid(
                "height_scale",
                format!("must be a finite number, got {}", self.height_scale),
            ));
        }
        Ok(())
    }

    /// The bilateral extractor's parameters.
    pub fn bilateral(&self) -> bilateral_difference::BilateralParams {
        bilateral_difference::BilateralParams {
            sigma_grid: self.sigma_grid,
            sigma_space: self.sigma_space,
        }
    }

    /// The plane fit's parameters (planar and height-field extractors).
    pub fn ransac(&self) -> planar_ransac::RansacParams {
        planar_ransac::RansacParams {
            iterations: self.ransac_iterations,
            inlier_distance: self.inlier_distance,
            samples: self.surface_samples,
            seed: self.seed,
        }
    }
}

/// Number of texel channels for a sample with or without vertex colours.
pub(crate) fn channels_for(mesh: &Mesh) -> u32 {
    if mesh.colors.is_some() { 6 } else { 3 }
}

/// Fails on a vertex with a non-finite position that a triangle uses.
pub(crate) fn check_finite(mesh: &Mesh) -> Result<(), ExtractError> {
    for t in &mesh.triangles {
        for &v in t {
            let p =
                mesh.positions
                    .get(v as usize)
                    .ok_or_else(|| ExtractError::DegeneratePatch {
                        faces: mesh.triangles.len(),
                        message: format!(
                            "a triangle names vertex {v}, but there are {} vertices",
                            mesh.positions.len()
                        ),
                    })?;
            if !p.is_finite() {
                return Err(ExtractError::NonFinite {
                    vertex: v as usize,
                    position: format!("{p}"),
                });
            }
        }
    }
    Ok(())
}

/// A texture extracted from a sample mesh by [`extract_mesh_texture`].
#[derive(Clone, Debug, PartialEq)]
pub struct Extraction {
    /// `size`×`size` texels (dx, dy, dn[, r, g, b]), row-major.
    pub texels: TexelImage,
    /// Per texel, the point of the base surface (the plane, or the smoothed patch) it is
    /// measured from, and the frame it is measured in: the sample's surface point is
    /// `base + dx·frame.x + dy·frame.y + dn·frame.n` (§4.4 applied to the base itself).
    pub base: Vec<Vec3>,
    pub frames: Vec<Frame>,
    /// Vertices and triangles of the sample patch cut out of the mesh.
    pub patch_vertices: usize,
    pub patch_faces: usize,
}

impl Extraction {
    /// The texels in units of the sample's texel spacing ([`texel_spacing`] of the base
    /// points): the geometric channels divided by it, colour kept. Stored this way, a relief
    /// keeps its proportions when it moves to a mesh of another size (the displacement scales
    /// them by the target's spacing, see `reconstruct::displacement`). Image height fields
    /// are in these units already (one pixel is one spacing).
    pub fn texels_in_spacing_units(self) -> TexelImage {
        let (w, h) = (self.texels.width as usize, self.texels.height as usize);
        let spacing = texel_spacing(&self.base, w, h);
        normalize(self.texels, spacing.max(1e-30))
    }
}

/// Mean distance between grid-neighbouring base points: the sample's texel spacing (1 for a
/// grid of one point).
pub fn texel_spacing(base: &[Vec3], width: usize, height: usize) -> f32 {
    let mut sum = 0.0f64;
    let mut n = 0u64;
    for y in 0..height {
        for x in 0..width {
            let p = base[y * width + x];
            if x + 1 < width {
                sum += p.distance(base[y * width + x + 1]) as f64;
                n += 1;
            }
            if y + 1 < height {
                sum += p.distance(base[(y + 1) * width + x]) as f64;
                n += 1;
            }
        }
    }
    if n == 0 { 1.0 } else { (sum / n as f64) as f32 }
}

/// Divides the geometric channels (dx, dy, dn) by `spacing`; colour channels stay.
pub fn normalize(mut t: TexelImage, spacing: f32) -> TexelImage {
    let c = t.channels as usize;
    for texel in t.data.chunks_mut(c) {
        for v in &mut texel[..3] {
            *v /= spacing;
        }
    }
    t
}

/// §4.1 on a sample mesh: cuts the sample patch out with [`ExtractParams::region`]
/// ([`sample_region::select_region`]) and runs [`ExtractParams::method`] on it.
///
/// The bilateral method builds the patch's geometry image at the smallest valid resolution
/// 2^k + 1 ≥ `size` (one coarse level: the sample needs no synthesis pyramid) and keeps the
/// central `size`×`size` texels (for size 64, all but the last row and column of the 65×65
/// image). `progress` receives fractions of the work done.
pub fn extract_mesh_texture(
    mesh: &Mesh,
    params: &ExtractParams,
    progress: &(dyn Fn(f32) + Sync),
) -> Result<Extraction, ExtractError> {
    params.validate()?;
    let patch = sample_region::select_region(mesh, params.region.as_ref())?;
    let (patch_vertices, patch_faces) = (patch.positions.len(), patch.triangles.len());
    let size = params.size;
    let planar = |e: planar_ransac::PlanarExtraction| {
        let frame = Frame {
            x: e.plane.e1,
            y: e.plane.e2,
            n: e.plane.normal,
        };
        let base = (0..size * size)
            .map(|k| e.sample_point(k / size, k % size))
            .collect();
        Extraction {
            base,
            frames: vec![frame; (size * size) as usize],
            texels: e.texels,
            patch_vertices,
            patch_faces,
        }
    };
    match params.method {
        ExtractMethod::Planar => {
            let e = planar_ransac::planar_extract(&patch, size, &params.ransac(), progress)?;
            Ok(planar(e))
        }
        ExtractMethod::HeightField => {
            let e = height_field::mesh_height_field(&patch, size, &params.ransac(), progress)?;
            Ok(planar(e))
        }
        ExtractMethod::Bilateral => {
            let gi_size = (size - 1).next_power_of_two().max(4) + 1;
            let gi_params = GeometryImageParams {
                size: gi_size,
                coarse_levels: 1,
                // The patch is a disk already; its extraction predates stretch cuts and
                // its results are locked (dragon_*.lock).
                stretch_cuts: 0,
                ..GeometryImageParams::default()
            };
            let build = build_geometry_image(&patch, &gi_params, &|f| progress(0.6 * f))
                .map_err(|e| ExtractError::GeometryImage(e.to_string()))?;
            let colors = patch.colors.as_ref().map(|c| {
                bilateral_difference::geometry_image_colors(
                    gi_size,
                    &build.disk,
                    &build.disk_uv,
                    &build.original_vertex,
                    c,
                )
            });
            let e = bilateral_difference::bilateral_difference(
                &build.image,
                colors.as_deref(),
                &params.bilateral(),
                &|f| progress(0.6 + 0.4 * f),
            )?;
            // The central size×size texels.
            let off = (gi_size - size) / 2;
            let channels = e.texels.channels;
            let mut texels = TexelImage::new(size, size, channels);
            let mut base = Vec::with_capacity((size * size) as usize);
            let mut frames = Vec::with_capacity((size * size) as usize);
            for i in 0..size {
                for j in 0..size {
                    let k = ((i + off) * gi_size + j + off) as usize;
                    texels
                        .texel_mut(j, i)
                        .copy_from_slice(e.texels.texel(j + off, i + off));
                    base.push(e.smoothed[k]);
                    frames.push(e.frames[k]);
                }
            }
            Ok(Extraction {
                texels,
                base,
                frames,
                patch_vertices,
                patch_faces,
            })
        }
    }
}

/// The extract node of a mesh sample: its relief as texels, in units of the texel spacing.
pub fn mesh_texture_node(
    mesh: &Mesh,
    params: &ExtractParams,
    progress: &(dyn Fn(f32) + Sync),
) -> Result<TexelImage, Failure> {
    let e = extract_mesh_texture(mesh, params, progress).map_err(Failure::input)?;
    Ok(e.texels_in_spacing_units())
}
