//! Stage: extract: texture or features taken out of a shape.
//!
//! Geometric texture (Lai et al., "Geometric Texture Synthesis and Transfer via Geometry
//! Images", §4.1): a sample model, or a region of it, becomes a [`TexelImage`](crate::geom::geometry_image::TexelImage) of geometry
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
//! [`sample_region::select_region`] cuts the sample patch out of the sample model first.

pub mod bilateral_difference;
pub mod height_field;
pub mod planar_ransac;
pub mod sample_region;
pub mod square_domain;

use crate::geom::Mesh;
use sample_region::Region;
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// Why a texture could not be extracted. Messages name the input and what was wrong.
#[derive(Debug, thiserror::Error)]
pub enum ExtractError {
    /// A parameter out of range; the message names the field, its range and the value.
    #[error("extract: {0}")]
    Params(String),
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
    #[error(
        "{path}: pixel ({x}, {y}) is not grey (r, g, b = {r:.3}, {g:.3}, {b:.3}): a height-field \
         image must be greyscale (channels equal within 2/255)"
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
    /// Texels per side of the extracted (square) texel image, 8..=1024. For the bilateral
    /// method it is also the resolution of the patch's geometry image. Image height fields keep
    /// the image's own size. Default: 64.
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
        }
    }
}

pub(crate) fn check_range<T: PartialOrd + std::fmt::Display>(
    name: &str,
    v: T,
    lo: T,
    hi: T,
) -> Result<(), String> {
    // Written so that NaN fails.
    if v >= lo && v <= hi {
        Ok(())
    } else {
        Err(format!("{name} must be in {lo}..={hi}, got {v}"))
    }
}

pub(crate) fn check_positive(name: &str, v: f32) -> Result<(), String> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(format!("{name} must be a finite number > 0, got {v}"))
    }
}

impl ExtractParams {
    /// Checks every field; the error names the field, its range and the value.
    pub fn validate(&self) -> Result<(), String> {
        check_range("size", self.size, 8, 1024)?;
        if let Some(r) = &self.region {
            r.validate().map_err(|m| format!("region: {m}"))?;
        }
        self.bilateral().validate()?;
        self.ransac().validate()?;
        if !self.height_scale.is_finite() {
            return Err(format!(
                "height_scale must be a finite number, got {}",
                self.height_scale
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
