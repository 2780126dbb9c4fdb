//! The synthesize node of feature-aligned texturing: §5's optimization on the refined mesh,
//! with or without the feature constraint of §5.2, and the check that its patch fits the
//! exemplar.

use super::{
    FeatureConstraint, SurfaceSynthesis, SurfaceSynthesisInput, TextureOptimizationParams,
    curve_distance, texture_optimization,
};
use crate::analyse_exemplar::texture_feature_lines::TextureFeatures;
use crate::field::feature_field::{OrientedField, carry_field};
use crate::geom::edge_refine::Refined;
use crate::image::Image;
use serde::Serialize;
use texsyn_core::algorithm::Failure;

/// What synthesis reads besides its inputs.
#[derive(Debug, Clone, Serialize)]
pub struct SynthesisKey {
    /// Exemplar texels per object unit.
    pub scale: f32,
    /// With the feature constraint (§5.2); without it, the paper's Fig. 7 middle column.
    pub aligned: bool,
    pub optimization: TextureOptimizationParams,
}

/// The synthesize node: colours for the refined mesh's vertices, logged.
pub fn node(
    refined: &Refined,
    field: &OrientedField,
    exemplar: &Image,
    features: &TextureFeatures,
    key: &SynthesisKey,
    progress: &(dyn Fn(f32) + Sync),
) -> Result<SurfaceSynthesis, Failure> {
    if features.width != exemplar.width || features.height != exemplar.height {
        return Err(Failure::internal("texture features and exemplar disagree"));
    }
    let vectors = carry_field(refined, &field.field.vectors)?;
    // The constraint's d(p, C) of §5.2, on the refined mesh.
    let distance = if key.aligned {
        let curves = field.field.curves.iter();
        let paths = refined.refine_paths(curves.map(|(c, _)| (c.vertices.as_slice(), c.closed)));
        let sources: Vec<u32> = paths.into_iter().flatten().collect();
        curve_distance(&refined.mesh, &sources)
    } else {
        Vec::new()
    };
    let input = SurfaceSynthesisInput {
        mesh: &refined.mesh,
        field: &vectors,
        exemplar,
        texel_size: 1.0 / key.scale,
        exemplar_angle: features.principal_angle,
        features: key.aligned.then_some(FeatureConstraint {
            curve_distance: &distance,
            texture_distance: &features.distance,
        }),
    };
    let out = texture_optimization(&input, &key.optimization, progress).map_err(Failure::input)?;
    let s = &out.stats;
    tracing::info!(
        "{}: {} samples ({} constrained, {} without a matching feature distance), {} iterations, energy {:.4}",
        if key.aligned {
            "synthesize"
        } else {
            "synthesize.unaligned"
        },
        s.samples,
        s.constrained_samples,
        s.unconstrained_fallbacks,
        s.iterations_run,
        s.final_energy
    );
    Ok(out)
}

/// Whether the patch fits an exemplar of `width × height` texels at every rotation (a rotated
/// w×w patch needs w·√2 texels in both directions); the message names the exemplar `path`.
pub fn check_patch_fits(
    (w, h): (u32, u32),
    path: &std::path::Path,
    p: &TextureOptimizationParams,
) -> Result<(), String> {
    let patch = p.patch;
    let need = (patch as f32 * std::f32::consts::SQRT_2).ceil() as u32 + 2;
    if w.min(h) < need {
        return Err(format!(
            "{patch} texels does not fit the {w}×{h} exemplar {} at every rotation (that needs {need}×{need}): use a smaller patch or a larger exemplar",
            path.display()
        ));
    }
    Ok(())
}
