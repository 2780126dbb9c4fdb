//! The `solid` method's config schema and the checks made on it before any node runs.

use crate::check::ParamError;
use crate::config::Config;
use crate::methods::MethodError;
use crate::stages::analyse_exemplar::candidate_triples::{self as triples, ExemplarSpec};
use crate::stages::field::quaternion_field as sketch;
use crate::stages::parameterize::volume_embedding::{self as volume, RequestParams};
use crate::stages::reconstruct::solid_colour::SolidExportParams;
use crate::stages::synthesize::solid::solid_synthesis as synthesis;
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// A `solid` config. `[inputs]` and each of `[[regions]]` name an exemplar set: one image for
/// all three planes (`exemplar`), or one per plane of the local frame (`xy`, `yz`, `zx`; any
/// may be left out if `exemplar` is given); the images of one set must have the same size.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct SolidConfig {
    pub method: String,
    pub inputs: SolidInputs,
    #[serde(default)]
    pub analyse_exemplar: triples::CandidateParams,
    #[serde(default)]
    pub field: sketch::SketchParams,
    #[serde(default)]
    pub parameterize: RequestParams,
    #[serde(default)]
    pub synthesize: synthesis::SolidParams,
    #[serde(default)]
    pub reconstruct: SolidExportParams,
    /// Exemplar sets for shells under the surface (§6, Fig. 15: bark over wood), from the
    /// surface inwards: each a solid in the same field, synthesized only at the voxels it
    /// owns. The voxels deeper than the last take `[inputs]`'s.
    #[serde(default)]
    pub regions: Vec<SolidRegion>,
}

#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct SolidInputs {
    /// The shape the solid is embedded around and whose surface is coloured.
    pub mesh: PathBuf,
    pub exemplar: Option<ExemplarSpec>,
    pub xy: Option<ExemplarSpec>,
    pub yz: Option<ExemplarSpec>,
    pub zx: Option<ExemplarSpec>,
}

#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct SolidRegion {
    /// How deep under the surface the region reaches, in the mesh's units: it holds the
    /// voxels whose centres are less deep than this and at least as deep as the previous
    /// region's `depth`. Voxels outside the mesh count as depth 0. Depths must increase.
    pub depth: f32,
    pub exemplar: Option<ExemplarSpec>,
    pub xy: Option<ExemplarSpec>,
    pub yz: Option<ExemplarSpec>,
    pub zx: Option<ExemplarSpec>,
    /// This region's plane weights. Default: those of `[analyse_exemplar]`.
    pub plane_weights: Option<[f32; 3]>,
}

/// Parses the config, couples the pyramid depth with `[[synthesize.levels]]`, and checks
/// every section and the memory the request needs, naming the keys.
pub(super) fn checked(config: &Config) -> Result<SolidConfig, MethodError> {
    let mut c: SolidConfig = config.parse()?;
    let param = |e: ParamError| MethodError::from(config.param(e));
    let given = ["analyse_exemplar", "synthesize"].map(|t| config.gives(t, "levels"));
    let (depth, levels) = (&mut c.analyse_exemplar.levels, &mut c.synthesize.levels);
    synthesis::couple_levels(depth, levels, given).map_err(param)?;
    let p = c.analyse_exemplar.clone();
    config.check("analyse_exemplar", p.validate())?;
    config.check("field", c.field.validate())?;
    c.parameterize.validate().map_err(param)?;
    c.reconstruct.validate().map_err(param)?;
    crate::methods::checks::check_preview_memory(config, c.reconstruct.preview_size)?;
    crate::methods::check_atlas_memory(config, c.reconstruct.atlas_size)?;
    crate::methods::check_solid_memory(config, c.parameterize.resolution, &c.parameterize.request)?;
    config.check("synthesize", c.synthesize.validate())?;
    let depths: Vec<f32> = c.regions.iter().map(|r| r.depth).collect();
    volume::validate_region_depths(&depths).map_err(param)?;
    Ok(c)
}
