//! The `feature_aligned` method's config schema and the checks made on it before any node
//! runs.

use crate::config::Config;
use crate::methods::MethodError;
use crate::stages::analyse_exemplar::texture_feature_lines::TextureFeatureParams;
use crate::stages::extract::shape_features::ShapeFeatureParams;
use crate::stages::field::feature_field::FeatureFieldParams;
use crate::stages::parameterize::edge_refinement::{self, RefineParams};
use crate::stages::reconstruct::feature_aligned_export::FeatureAlignedExportParams;
use crate::stages::synthesize::texture_optimization::{self as opt, TextureOptimizationParams};
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// A `feature_aligned` config.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct FeatureAlignedConfig {
    pub method: String,
    pub inputs: Inputs,
    /// Also synthesize without the feature constraint, for comparison. Default: true.
    #[serde(default = "yes")]
    pub compare: bool,
    #[serde(default)]
    pub extract: ShapeFeatureParams,
    #[serde(default)]
    pub analyse_exemplar: TextureFeatureParams,
    #[serde(default)]
    pub field: FeatureFieldParams,
    #[serde(default)]
    pub parameterize: RefineParams,
    #[serde(default)]
    pub synthesize: TextureOptimizationParams,
    #[serde(default)]
    pub reconstruct: FeatureAlignedExportParams,
}

fn yes() -> bool {
    true
}

#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Inputs {
    /// The mesh to texture (.obj, .off, .ply, .stl).
    pub mesh: PathBuf,
    /// The exemplar (.png, .jpg, .exr), with feature lines of its own.
    pub exemplar: PathBuf,
    /// Optional: the exemplar's feature lines drawn by hand (white on black, the exemplar's
    /// size); replaces detection.
    #[serde(default)]
    pub feature_mask: Option<PathBuf>,
}

/// Parses the config and checks every section, naming the keys.
pub(super) fn checked(config: &Config) -> Result<FeatureAlignedConfig, MethodError> {
    let mut c: FeatureAlignedConfig = config.parse()?;
    let (mesh, exemplar) = (&c.inputs.mesh, &c.inputs.exemplar);
    let auto = crate::methods::resolve_scale(config, &mut c.parameterize.scale, mesh, exemplar);
    c.parameterize.validate().map_err(|e| config.param(e))?;
    if let Some(auto) = auto {
        fit_auto_scale(&auto, &mut c.parameterize);
    }
    c.extract.validate().map_err(|e| config.param(e))?;
    c.analyse_exemplar.validate().map_err(|e| config.param(e))?;
    c.field.validate().map_err(|e| config.param(e))?;
    c.synthesize.validate().map_err(|e| config.param(e))?;
    c.reconstruct.validate().map_err(|e| config.param(e))?;
    crate::methods::checks::check_preview_memory(config, c.reconstruct.preview_size)?;
    Ok(c)
}

/// The version of [`fit_auto_scale`]'s rule (with [`edge_refinement::largest_scale_within_budget`]'s):
/// change it when either changes what it answers, so no remembered answer outlives it.
const FIT_RULE: u32 = 1;

/// Lowers an automatic scale until the refined mesh fits `parameterize.max_vertices`
/// ([`edge_refinement::largest_scale_within_budget`]): "auto" asks for a texture of a sensible
/// size, and a refusal would leave the user to find the number "auto" stands for. A scale
/// the user gives is never changed; its refinement names the budget when it does not fit.
///
/// Near the budget the fit refines the mesh (up to seconds), so `texsyn run` remembers its
/// answer in the cache ([`plan_memo`]), keyed by the mesh's source (bytes, format and
/// reader), the parameters and the rules' versions: a rerun plans without refining.
///
/// [`plan_memo`]: crate::methods::plan_memo
fn fit_auto_scale(auto: &crate::methods::AutoMesh, p: &mut RefineParams) {
    let mut h = blake3::Hasher::new();
    h.update(b"feature_aligned auto-scale fit\0");
    h.update(&FIT_RULE.to_le_bytes());
    let refine = texsyn_core::geom::edge_refine::NODE;
    h.update(refine.name.as_bytes());
    h.update(&refine.version.to_le_bytes());
    h.update(&auto.source.0);
    for x in [p.scale.to_bits(), p.edge.to_bits(), p.max_vertices] {
        h.update(&x.to_le_bytes());
    }
    let key = crate::artifact::ContentHash(*h.finalize().as_bytes());
    // A fit is positive and never above the scale it lowers: anything else is damage.
    let valid = |s: f32| s.is_finite() && s > 0.0 && s <= p.scale;
    let fitted = crate::methods::plan_memo::number(&key, valid, || {
        edge_refinement::largest_scale_within_budget(&auto.mesh, p.scale, p).unwrap_or(p.scale)
    });
    if fitted < p.scale {
        tracing::info!(
            "parameterize.scale = \"auto\": lowered from {:.4} to {:.4} texels per unit, so the refined mesh fits parameterize.max_vertices = {} (the exemplar then spans more than a quarter of the diagonal)",
            p.scale,
            fitted,
            p.max_vertices
        );
        p.scale = fitted;
    }
}

/// Refuses a synthesis patch that does not fit the exemplar (read from its header; an
/// unreadable one is left to its import node to name), and a patch or atlas over the memory
/// budget.
pub(super) fn check_exemplar_fits(
    config: &Config,
    c: &FeatureAlignedConfig,
) -> Result<(), MethodError> {
    if let Some((size, path)) = crate::methods::exemplar_size(config, &c.inputs.exemplar) {
        let p = &c.synthesize;
        config.check("synthesize.patch", opt::check_patch_fits(size, &path, p))?;
        let texels = size.0 as u64 * size.1 as u64;
        let estimate = |w| opt::memory_estimate(texels, w, p.levels as u64);
        let show = |w: u64| w.to_string();
        crate::methods::check_memory(config, "synthesize.patch", p.patch as u64, estimate, show)?;
    }
    if c.reconstruct.atlas_size > 0 {
        crate::methods::check_atlas_memory(config, c.reconstruct.atlas_size)?;
    }
    Ok(())
}
