//! Method `feature_aligned`: the texture's own feature lines laid along the shape's feature
//! lines (Xu, Cohen-Or, Ju, Liu, Zhang, Zhou & Xiong, "Feature-Aligned Shape Texturing",
//! SIGGRAPH Asia 2009 sketches).
//!
//! ```text
//! inputs.mesh ─ import.mesh ─┬─ extract (crest lines, creases or user curves) ─ field (§4: greedy orientation, harmonic field) ─┐
//!  extract.curves_file ──────┘                                                                                                  │
//!                            └─ parameterize (edge refinement to texel spacing) ───────────────────────────────────────────────┤
//! inputs.exemplar ─ import.exemplar ─ analyse_exemplar (texture feature lines, distance map) ───────────────────────────────────┤
//! inputs.feature_mask ─ import.feature_mask ─┘                                                                                  │
//!                                                  synthesize (§5, with the feature constraint), synthesize.unaligned ─ reconstruct ─ files
//! ```
//!
//! The field is solved and oriented on the input mesh (§4 works on the model as given) and
//! carried to the refined mesh by averaging along split edges; synthesis (§5) runs on the
//! refined mesh, whose vertices are about one exemplar texel apart. `compare = true` (the
//! default) also synthesizes without the feature constraint on the same field, the middle
//! column of the paper's Fig. 7.

use super::{Method, MethodError, Planned, import};
use crate::artifact::Bundle;
use crate::artifact::feature_aligned::OrientedField;
use crate::config::Config;
use crate::geom::Mesh;
use crate::geom::edge_refine::{Refined, refine_edges};
use crate::image::Image;
use crate::pipeline::{Dag, Handle, NodeError, NodeSpec, Stage};
use crate::score::surface::FeatureAlignedNodes;
use crate::score::{Item, Run, ScoreFailure};
use crate::stages::analyse_exemplar::texture_feature_lines::{
    TextureFeatureParams, TextureFeatures, detect_texture_features, feature_overlay,
    features_from_mask,
};
use crate::stages::extract::shape_features::{
    ShapeFeatureParams, ShapeFeatures, read_curves_file, shape_features,
};
use crate::stages::field::feature_field::{FeatureFieldParams, Orientation, feature_field};
use crate::stages::reconstruct::feature_aligned_export::{
    DrawnCurve, FeatureAlignedExportParams, FeatureAlignedResult, export_feature_aligned,
};
use crate::stages::synthesize::texture_optimization::{
    FeatureConstraint, SurfaceSynthesis, SurfaceSynthesisInput, TextureOptimizationParams,
    curve_distance, texture_optimization,
};
use glam::Vec3;
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

/// `[parameterize]`: how fine the mesh is made for synthesis.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct RefineParams {
    /// Exemplar texels per object unit (required): sets the texture's size on the mesh.
    pub scale: f32,
    /// Longest edge after refinement, in exemplar texels, 0.25..=8. Default: 1 (a vertex per
    /// texel, what §5's per-vertex optimization needs to show the texture's detail).
    pub edge: f32,
    /// Most vertices the refined mesh may have, 1000..=20,000,000. Default: 1,000,000.
    pub max_vertices: u32,
}

impl Default for RefineParams {
    fn default() -> Self {
        RefineParams {
            scale: 0.0,
            edge: 1.0,
            max_vertices: 1_000_000,
        }
    }
}

/// What the shape-feature node reads besides its inputs.
#[derive(Serialize)]
struct ExtractParams {
    features: ShapeFeatureParams,
    curves_format: Option<String>,
}

/// What synthesis reads besides its inputs.
#[derive(Serialize)]
struct SynthParams {
    scale: f32,
    aligned: bool,
    optimization: TextureOptimizationParams,
}

/// The `feature_aligned` method.
pub struct FeatureAligned;

impl Method for FeatureAligned {
    fn name(&self) -> &'static str {
        "feature_aligned"
    }

    fn plan(&self, config: &Config) -> Result<(Dag, Box<dyn Planned>), MethodError> {
        let (dag, planned) = build(config)?;
        Ok((dag, Box::new(planned)))
    }
}

/// What the feature-aligned score reads: its nodes and the texture scale.
struct FeatureAlignedScore {
    nodes: FeatureAlignedNodes,
    scale: f32,
}

impl Planned for FeatureAlignedScore {
    fn score(&self, run: &Run<'_>, _: &mut Vec<String>) -> Result<Vec<Item>, ScoreFailure> {
        crate::score::surface::feature_aligned(run, &self.nodes, self.scale, |r, v| {
            carry_field(r, v).map_err(|e| e.to_string())
        })
    }
}

fn build(config: &Config) -> Result<(Dag, FeatureAlignedScore), MethodError> {
    let c: FeatureAlignedConfig = config.parse()?;
    if !config.gives("parameterize", "scale") {
        return Err(config
            .invalid(
                "parameterize.scale",
                "is required: exemplar texels per object unit (the texture's size on the mesh)",
            )
            .into());
    }
    let r = &c.parameterize;
    if !(r.scale.is_finite() && r.scale > 0.0) {
        let msg = format!("must be a positive number, got {}", r.scale);
        return Err(config.invalid("parameterize.scale", &msg).into());
    }
    crate::check::check_range("parameterize.edge", r.edge, 0.25, 8.0)
        .map_err(|e| config.param(e))?;
    crate::check::check_range(
        "parameterize.max_vertices",
        r.max_vertices,
        1000,
        20_000_000,
    )
    .map_err(|e| config.param(e))?;
    c.extract.validate().map_err(|e| config.param(e))?;
    c.analyse_exemplar.validate().map_err(|e| config.param(e))?;
    c.field.validate().map_err(|e| config.param(e))?;
    c.synthesize.validate().map_err(|e| config.param(e))?;
    c.reconstruct.validate().map_err(|e| config.param(e))?;

    let mut dag = Dag::default();
    let mesh_path = config.resolve(&c.inputs.mesh);
    let mesh = import::<Mesh>(&mut dag, "import.mesh", &mesh_path, "inputs.mesh")?;
    let exemplar_path = config.resolve(&c.inputs.exemplar);
    let exemplar = import::<Image>(
        &mut dag,
        "import.exemplar",
        &exemplar_path,
        "inputs.exemplar",
    )?;
    check_patch_fits(config, &exemplar_path, &c.synthesize)?;
    if c.reconstruct.atlas_size > 0 {
        super::check_atlas_memory(config, c.reconstruct.atlas_size)?;
    }
    let mask = match &c.inputs.feature_mask {
        Some(m) => Some(import::<Image>(
            &mut dag,
            "import.feature_mask",
            &config.resolve(m),
            "inputs.feature_mask",
        )?),
        None => None,
    };
    let curves_file = match &c.extract.curves_file {
        Some(f) => Some(dag.file(&config.resolve(f), "extract.curves_file")?),
        None => None,
    };

    // The file's path is not a parameter (its bytes are the input), but its format is: the
    // same bytes read as OBJ or TOML mean different curves.
    let extract_params = ExtractParams {
        features: ShapeFeatureParams {
            curves_file: None,
            ..c.extract.clone()
        },
        curves_format: c.extract.curves_file.as_deref().map(super::extension),
    };
    let shape = dag.node(
        NodeSpec::of(Stage::Extract, crate::stages::extract::shape_features::NODE),
        extract_params,
        (mesh, curves_file),
        |_, ExtractParams { features: p, .. }, (mesh, file)| {
            if let Some(w) = crate::geom::mesh_check::mesh_health(&mesh).warning("feature_aligned")
            {
                tracing::warn!("{w}");
            }
            let more = match file {
                Some(f) => read_curves_file(&f.path.display().to_string(), &f.bytes)
                    .map_err(NodeError::input)?,
                None => Vec::new(),
            };
            let s = shape_features(&mesh, p, &more).map_err(NodeError::input)?;
            tracing::info!(
                "extract: {} feature curves ({:?})",
                s.curves.len(),
                s.source
            );
            Ok(s)
        },
    );
    let features = dag.node(
        NodeSpec::of(
            Stage::AnalyseExemplar,
            crate::stages::analyse_exemplar::texture_feature_lines::NODE,
        ),
        c.analyse_exemplar.clone(),
        (exemplar, mask),
        |_, p, (img, mask)| {
            let f = match mask {
                Some(m) => features_from_mask(&img.to_owned(), &m.to_owned(), p),
                None => detect_texture_features(&img.to_owned(), p),
            }
            .map_err(NodeError::input)?;
            tracing::info!(
                "analyse_exemplar: {} texture feature lines, principal at {:.1}°",
                f.lines.len(),
                f.principal_angle.to_degrees()
            );
            Ok(f)
        },
    );
    let field = dag.node(
        NodeSpec::of(Stage::Field, crate::stages::field::feature_field::NODE),
        c.field.clone(),
        (mesh, shape),
        |_, p, (mesh, shape)| {
            let (field, t) = feature_field(&mesh, &shape.curves, p).map_err(NodeError::input)?;
            let mut steps = t.step_secs.clone();
            steps.sort_by(f64::total_cmp);
            let median = steps.get(steps.len() / 2).copied().unwrap_or(0.0);
            // The paper's comparison (Fig. 3, Fig. 6): the same curves, arbitrarily oriented.
            let other = match p.orientation {
                Orientation::Arbitrary => field.singularities,
                Orientation::Greedy => {
                    let arbitrary = FeatureFieldParams {
                        orientation: Orientation::Arbitrary,
                        ..p.clone()
                    };
                    feature_field(&mesh, &shape.curves, &arbitrary)
                        .map_err(NodeError::input)?
                        .0
                        .singularities
                }
            };
            tracing::info!(
                "field: {} curves oriented ({:?}); setup (Laplacian, symbolic analysis) {:.2} s, first factorization {:.2} s, {} steps, median {:.3} s; \
                 {} singular triangles ({} with arbitrary orientation)",
                field.curves.len(),
                p.orientation,
                t.setup_secs,
                t.factorization_secs,
                t.step_secs.len(),
                median,
                field.singularities,
                other
            );
            Ok(OrientedField {
                field,
                arbitrary_singularities: other,
            })
        },
    );
    let refined = dag.node(
        NodeSpec::of(Stage::Parameterize, crate::geom::edge_refine::NODE),
        c.parameterize.clone(),
        mesh,
        |_, p, mesh| {
            let r =
                refine_edges(&mesh, p.edge / p.scale, p.max_vertices as usize).map_err(|e| {
                    NodeError::input(format!(
                        "parameterize: {e}; lower parameterize.scale or raise parameterize.edge \
                         or parameterize.max_vertices"
                    ))
                })?;
            tracing::info!(
                "parameterize: {} → {} vertices",
                mesh.vertex_count(),
                r.mesh.vertex_count()
            );
            Ok(r)
        },
    );
    let synthesis = |dag: &mut Dag, aligned: bool| {
        let name = if aligned {
            "synthesize"
        } else {
            "synthesize.unaligned"
        };
        let params = SynthParams {
            scale: c.parameterize.scale,
            aligned,
            optimization: c.synthesize.clone(),
        };
        let spec = NodeSpec::of(
            Stage::Synthesize,
            crate::stages::synthesize::texture_optimization::NODE,
        );
        dag.node(
            spec.named(name),
            params,
            (refined, field, exemplar, features),
            |ctx, p, (refined, field, img, tf)| {
                if tf.width != img.width || tf.height != img.height {
                    return Err(NodeError::internal("texture features and exemplar disagree"));
                }
                let vectors = carry_field(&refined, &field.field.vectors)?;
                // The constraint's d(p, C) of §5.2, on the refined mesh.
                let distance = if p.aligned {
                    let paths = refined.refine_paths(
                        field.field.curves.iter().map(|(c, _)| (c.vertices.as_slice(), c.closed)),
                    );
                    let sources: Vec<u32> = paths.into_iter().flatten().collect();
                    curve_distance(&refined.mesh, &sources)
                } else {
                    Vec::new()
                };
                let img = img.to_owned();
                let input = SurfaceSynthesisInput {
                    mesh: &refined.mesh,
                    field: &vectors,
                    exemplar: &img,
                    texel_size: 1.0 / p.scale,
                    exemplar_angle: tf.principal_angle,
                    features: p.aligned.then_some(FeatureConstraint {
                        curve_distance: &distance,
                        texture_distance: &tf.distance,
                    }),
                };
                let out = texture_optimization(&input, &p.optimization, &|f| ctx.progress.set(f))
                    .map_err(NodeError::input)?;
                let s = &out.stats;
                tracing::info!(
                    "{}: {} samples ({} constrained, {} without a matching feature distance), {} iterations, energy {:.4}",
                    if p.aligned { "synthesize" } else { "synthesize.unaligned" },
                    s.samples,
                    s.constrained_samples,
                    s.unconstrained_fallbacks,
                    s.iterations_run,
                    s.final_energy
                );
                Ok(out)
            },
        )
    };
    let aligned = synthesis(&mut dag, true);
    let unaligned: Option<Handle<SurfaceSynthesis>> = c.compare.then(|| synthesis(&mut dag, false));
    dag.node(
        NodeSpec::of(
            Stage::Reconstruct,
            crate::stages::reconstruct::feature_aligned_export::NODE,
        ),
        c.reconstruct.clone(),
        (
            mesh, shape, refined, field, aligned, unaligned, exemplar, features,
        ),
        |ctx, p, (mesh, shape, refined, field, aligned, unaligned, img, tf)| {
            let n = refined.mesh.vertex_count();
            if refined.input_vertices as usize != mesh.vertex_count()
                || refined
                    .face_origin
                    .iter()
                    .any(|&o| o as usize >= mesh.face_count())
            {
                return Err(NodeError::internal("refined and input mesh disagree"));
            }
            if aligned.colours.len() != n
                || unaligned.as_ref().is_some_and(|u| u.colours.len() != n)
            {
                return Err(NodeError::internal("colours and refined mesh disagree"));
            }
            let vectors = carry_field(&refined, &field.field.vectors)?;
            let curves = drawn_curves(&shape, &field.field);
            let report = report(&shape, &field, &refined, &aligned, unaligned.as_ref(), &tf);
            let overlay = crate::export::encode_png(&feature_overlay(&img.to_owned(), &tf), false);
            let result = FeatureAlignedResult {
                input: &mesh,
                refined: &refined,
                colours: &aligned.colours,
                unaligned: unaligned.as_ref().map(|u| u.colours.as_slice()),
                field: &vectors,
                curves,
                texture_features_png: overlay,
                report,
            };
            let files = export_feature_aligned(&result, p, &|f| ctx.progress.set(f))
                .map_err(NodeError::input)?;
            Ok(Bundle::from(files))
        },
    );
    let mut synthesize = vec![(aligned, "the refined mesh's colours")];
    synthesize.extend(unaligned.map(|u| (u, "the unaligned comparison's colours")));
    let nodes = FeatureAlignedNodes {
        parameterize: refined,
        field,
        analyse_exemplar: features,
        exemplar,
        synthesize,
    };
    let scale = c.parameterize.scale;
    Ok((dag, FeatureAlignedScore { nodes, scale }))
}

/// The input mesh's field on the refined mesh: each new vertex the mean of its parents',
/// then projected to its tangent plane and normalized (zero stays zero).
pub(crate) fn carry_field(refined: &Refined, vectors: &[Vec3]) -> Result<Vec<Vec3>, NodeError> {
    if vectors.len() != refined.input_vertices as usize {
        return Err(NodeError::internal("the field and the mesh disagree"));
    }
    let carried = refined.carry(vectors, |a, b| (a + b) * 0.5);
    let normals = refined.mesh.vertex_normals();
    Ok(carried
        .iter()
        .zip(normals)
        .map(|(v, n)| (*v - *n * v.dot(*n)).normalize_or_zero())
        .collect())
}

/// The oriented curves with a kind each: the kind of the extracted curve their first vertex
/// lay on (preprocessing joins and breaks curves but keeps their vertices).
fn drawn_curves<'a>(
    shape: &ShapeFeatures,
    field: &'a crate::stages::field::feature_field::FeatureField,
) -> Vec<DrawnCurve<'a>> {
    let mut kind_of = std::collections::BTreeMap::new();
    for (c, k) in shape.curves.iter().zip(&shape.kinds) {
        for &v in &c.vertices {
            kind_of.entry(v).or_insert(*k as u8);
        }
    }
    field
        .curves
        .iter()
        .map(|(c, sign)| DrawnCurve {
            vertices: &c.vertices,
            closed: c.closed,
            kind: c
                .vertices
                .iter()
                .find_map(|v| kind_of.get(v).copied())
                .unwrap_or(3),
            sign: *sign,
        })
        .collect()
}

/// `report.json`: the numbers a user compares between runs.
fn report(
    shape: &ShapeFeatures,
    field: &OrientedField,
    refined: &Refined,
    aligned: &SurfaceSynthesis,
    unaligned: Option<&SurfaceSynthesis>,
    tf: &TextureFeatures,
) -> String {
    let stats = |s: &SurfaceSynthesis| {
        serde_json::json!({
            "samples": s.stats.samples,
            "constrained_samples": s.stats.constrained_samples,
            "unconstrained_fallbacks": s.stats.unconstrained_fallbacks,
            "iterations": s.stats.iterations_run,
            "final_energy": s.stats.final_energy,
        })
    };
    let r = serde_json::json!({
        "shape_features": {
            "source": shape.source,
            "curves": shape.curves.len(),
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
        "refined_vertices": refined.mesh.vertex_count(),
        "synthesis": stats(aligned),
        "synthesis_unaligned": unaligned.map(stats),
    });
    serde_json::to_string_pretty(&r).expect("json") + "\n"
}

/// The patch must fit the exemplar: checked from the image header before any node runs (an
/// unreadable header is left to the import node, which names the problem).
fn check_patch_fits(
    config: &Config,
    path: &std::path::Path,
    p: &TextureOptimizationParams,
) -> Result<(), MethodError> {
    let patch = p.patch;
    let Ok(reader) = image::ImageReader::open(path).and_then(|r| r.with_guessed_format()) else {
        return Ok(());
    };
    let Ok((w, h)) = reader.into_dimensions() else {
        return Ok(());
    };
    // A rotated w×w patch needs w·√2 texels in both directions.
    let need = (patch as f32 * std::f32::consts::SQRT_2).ceil() as u32 + 2;
    if w.min(h) < need {
        let msg = format!(
            "{patch} texels does not fit the {w}×{h} exemplar {} at every rotation (that needs {need}×{need}): use a smaller patch or a larger exemplar",
            path.display()
        );
        return Err(config.invalid("synthesize.patch", &msg).into());
    }
    let texels = w as u64 * h as u64;
    super::check_memory(
        config,
        "synthesize.patch",
        patch as u64,
        |w| {
            crate::stages::synthesize::texture_optimization::memory_estimate(
                texels,
                w,
                p.levels as u64,
            )
        },
        |w| w.to_string(),
    )
}
