//! The `jump_maps` method's config schema and the checks made on it before any node runs.

use crate::config::Config;
use crate::methods::MethodError;
use crate::stages::analyse_exemplar::jump_map::JumpMapParams;
use crate::stages::field::orientation_field::FieldParams;
use crate::stages::parameterize::jump_parameterization::ParameterizeParams;
use crate::stages::reconstruct::jump_export::check_map_name;
use crate::stages::reconstruct::textured_export::ExportParams;
use crate::stages::synthesize::jump_walk::WalkParams;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::PathBuf;

/// A `jump_maps` config.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct JumpMapsConfig {
    pub method: String,
    pub inputs: Inputs,
    #[serde(default)]
    pub analyse_exemplar: JumpMapParams,
    #[serde(default)]
    pub field: FieldParams,
    #[serde(default)]
    pub parameterize: ParameterizeParams,
    #[serde(default)]
    pub synthesize: WalkParams,
    #[serde(default)]
    pub reconstruct: ExportParams,
}

#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Inputs {
    /// The mesh to texture (.obj, .off, .ply, .stl).
    pub mesh: PathBuf,
    /// The exemplar image (.png, .jpg, .exr).
    pub exemplar: PathBuf,
    /// Further maps aligned with the exemplar (same size), textured with the same
    /// coordinates: `normal`, `roughness`, `height`, or any other name. Default: none.
    #[serde(default)]
    pub maps: BTreeMap<String, PathBuf>,
}

/// Parses the config and checks every section and the extra maps' names, naming the keys.
pub(super) fn checked(config: &Config) -> Result<JumpMapsConfig, MethodError> {
    let c: JumpMapsConfig = config.parse()?;
    config.check("analyse_exemplar", c.analyse_exemplar.validate())?;
    config.check("field", c.field.validate())?;
    config.check("parameterize", c.parameterize.validate())?;
    config.check("synthesize", c.synthesize.validate())?;
    config.check("reconstruct", c.reconstruct.validate())?;
    crate::methods::checks::check_preview_memory(config, c.reconstruct.preview_size)?;
    // No up-front memory check on `reconstruct.atlas_size`: it caps a page's side, and
    // pages are only as big as the charts they hold (the need follows the surface's area).
    for name in c.inputs.maps.keys() {
        let verdict = check_map_name(name, c.inputs.maps.keys());
        config.check(&format!("inputs.maps.{name}"), verdict)?;
    }
    Ok(c)
}
