//! The `geometry_images` method's config schema and the checks made on it before any node
//! runs.

use crate::config::{Config, check_range};
use crate::methods::MethodError;
use crate::stages::analyse_exemplar::texel_variants::TexelVariantParams;
use crate::stages::extract::height_field::is_image_path;
use crate::stages::extract::{ExtractMethod, ExtractParams};
use crate::stages::field::param_field::ParamFieldParams;
use crate::stages::parameterize::geometry_image::GeometryImageParams;
use crate::stages::reconstruct::relief_export::ReliefExportParams;
use crate::stages::synthesize::geometry_texture::{GeometrySynthParams, Search};
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// A `geometry_images` config.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct GeometryImagesConfig {
    pub method: String,
    pub inputs: Inputs,
    #[serde(default)]
    pub parameterize: GeometryImageParams,
    #[serde(default)]
    pub extract: ExtractParams,
    #[serde(default)]
    pub analyse_exemplar: TexelVariantParams,
    #[serde(default)]
    pub field: ParamFieldParams,
    #[serde(default)]
    pub synthesize: GeometrySynthParams,
    #[serde(default)]
    pub reconstruct: ReliefExportParams,
}

#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Inputs {
    /// The model that gets the texture (.obj, .off, .ply, .stl).
    pub mesh: PathBuf,
    /// Where the texture comes from: a mesh (a region of it is used, see `[extract]`) or an
    /// image read as a height field, a colour one by its luma (.png, .jpg, .exr).
    pub sample: PathBuf,
}

/// Parses the config and checks every value, and the values that must agree with each other,
/// naming the keys; returns it with the parameterize node's parameters.
pub(super) fn checked(
    config: &Config,
) -> Result<(GeometryImagesConfig, GeometryImageParams), MethodError> {
    let c: GeometryImagesConfig = config.parse()?;
    config.check("analyse_exemplar", c.analyse_exemplar.validate())?;
    config.check("parameterize", c.parameterize.with_levels(1).map(drop))?;
    let levels = c.analyse_exemplar.levels;
    let gp = c
        .parameterize
        .with_levels(levels)
        .map_err(|e| config.param(e))?;
    config.check("extract", c.extract.validate())?;
    config.check("field", c.field.validate())?;
    config.check("synthesize", c.synthesize.validate())?;
    config.check("reconstruct", c.reconstruct.displacement().validate())?;
    crate::methods::checks::check_preview_memory(config, c.reconstruct.preview_size)?;
    let preview = c.reconstruct.preview_size;
    let range = check_range("reconstruct.preview_size", preview, 16, 4096);
    config.check("reconstruct.preview_size", range)?;
    if is_image_path(&c.inputs.sample) {
        if c.extract.method != ExtractMethod::HeightField {
            let m = "an image sample is read as a height field: set method = \"height_field\" (or give a mesh sample)";
            return Err(config.invalid("extract.method", m).into());
        }
    } else {
        // A mesh sample gives extract.size² texels: check them against the variants now.
        let size = c.extract.size;
        super::sample_fits(size, size, &c).map_err(|e| {
            let more = if super::counts_candidates(&c) {
                ", or lower analyse_exemplar.scales, .levels, .template or .boundary_template"
            } else {
                ""
            };
            let m = format!("{e} (extract.size = {size}: raise it{more})");
            config.invalid("extract.size", &m)
        })?;
        let per_texel = super::counts_candidates(&c) && c.synthesize.search == Search::PerTexel;
        crate::methods::check_variant_memory(config, size, &c.analyse_exemplar, per_texel)?;
    }
    Ok((c, gp))
}
