//! The reconstruct node of feature-aligned texturing: what the run exports besides the
//! meshes (the curves drawn with their kinds, the exemplar's feature overlay, `report.json`,
//! the numbers a user compares between runs), handed to [`export_feature_aligned`].

use crate::analyse_exemplar::texture_feature_lines::{TextureFeatures, feature_overlay};
use crate::extract::shape_features::ShapeFeatures;
use crate::field::feature_field::{FeatureField, OrientedField, carry_field};
use crate::geom::Mesh;
use crate::geom::edge_refine::Refined;
use crate::image::Image;
use crate::reconstruct::feature_aligned_export::{
    DrawnCurve, FeatureAlignedExportParams, FeatureAlignedResult, export_feature_aligned,
};
use crate::synthesize::texture_optimization::SurfaceSynthesis;
use texsyn_core::algorithm::Failure;

/// Everything the node reads.
pub struct FeatureAlignedRun<'a> {
    pub input: &'a Mesh,
    pub shape: &'a ShapeFeatures,
    pub refined: &'a Refined,
    pub field: &'a OrientedField,
    pub aligned: &'a SurfaceSynthesis,
    pub unaligned: Option<&'a SurfaceSynthesis>,
    pub exemplar: &'a Image,
    pub features: &'a TextureFeatures,
}

/// The reconstruct node: the run's files.
pub fn node(
    run: &FeatureAlignedRun,
    p: &FeatureAlignedExportParams,
    progress: &dyn Fn(f32),
) -> Result<Vec<(String, Vec<u8>)>, Failure> {
    let (mesh, refined) = (run.input, run.refined);
    let n = refined.mesh.vertex_count();
    let faces_fit = refined
        .face_origin
        .iter()
        .all(|&o| (o as usize) < mesh.face_count());
    if refined.input_vertices as usize != mesh.vertex_count() || !faces_fit {
        return Err(Failure::internal("refined and input mesh disagree"));
    }
    if run.aligned.colours.len() != n || run.unaligned.is_some_and(|u| u.colours.len() != n) {
        return Err(Failure::internal("colours and refined mesh disagree"));
    }
    let vectors = carry_field(refined, &run.field.field.vectors)?;
    let overlay = feature_overlay(run.exemplar, run.features);
    let result = FeatureAlignedResult {
        input: mesh,
        refined,
        colours: &run.aligned.colours,
        source: &run.aligned.source,
        exemplar: run.exemplar,
        unaligned: run.unaligned.map(|u| u.colours.as_slice()),
        field: &vectors,
        curves: drawn_curves(run.shape, &run.field.field),
        texture_features_png: crate::export::encode_png(&overlay, false),
        report: report(run),
    };
    export_feature_aligned(&result, p, progress).map_err(Failure::input)
}

/// The oriented curves with a kind each: the kind of the extracted curve their first vertex
/// lay on (preprocessing joins and breaks curves but keeps their vertices); fixed where they
/// hold a curve the user fixed.
fn drawn_curves<'a>(shape: &ShapeFeatures, field: &'a FeatureField) -> Vec<DrawnCurve<'a>> {
    let mut kind_of = std::collections::BTreeMap::new();
    for (c, k) in shape.curves.iter().zip(&shape.kinds) {
        for &v in &c.vertices {
            kind_of.entry(v).or_insert(*k as u8);
        }
    }
    let kind = |vertices: &[u32]| vertices.iter().find_map(|v| kind_of.get(v).copied());
    field
        .curves
        .iter()
        .zip(&field.fixed)
        .map(|((c, sign), &fixed)| DrawnCurve {
            vertices: &c.vertices,
            closed: c.closed,
            kind: kind(&c.vertices).unwrap_or(3),
            sign: *sign,
            fixed,
        })
        .collect()
}

/// `report.json`: the numbers a user compares between runs.
fn report(run: &FeatureAlignedRun) -> String {
    let stats = |s: &SurfaceSynthesis| {
        serde_json::json!({
            "samples": s.stats.samples,
            "constrained_samples": s.stats.constrained_samples,
            "unconstrained_fallbacks": s.stats.unconstrained_fallbacks,
            "iterations": s.stats.iterations_run,
            "final_energy": s.stats.final_energy,
        })
    };
    let (field, tf) = (run.field, run.features);
    let r = serde_json::json!({
        "shape_features": {
            "source": run.shape.source,
            "curves": run.shape.curves.len(),
            "curves_after_preprocessing": field.field.curves.len(),
        },
        "texture_features": {
            "lines": tf.lines.len(),
            "principal_angle_degrees": tf.principal_angle.to_degrees(),
        },
        "field": {
            "singular_triangles": field.field.singularities,
            "singular_triangles_arbitrary_orientation": field.arbitrary_singularities,
        },
        "refined_vertices": run.refined.mesh.vertex_count(),
        "synthesis": stats(run.aligned),
        "synthesis_unaligned": run.unaligned.map(stats),
    });
    serde_json::to_string_pretty(&r).expect("json") + "\n"
}
