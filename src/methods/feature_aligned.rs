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

use super::{Method, MethodError, Planned, input};
use crate::artifact::Bundle;
use crate::config::Config;
use crate::geom::Mesh;
use crate::image::Image;
use crate::pipeline::{Dag, Handle, NodeSpec, Stage};
use crate::score::surface::FeatureAlignedNodes;
use crate::score::{Item, Run, ScoreFailure};
use crate::stages::analyse_exemplar::texture_feature_lines::{self, TextureFeatureParams};
use crate::stages::extract::shape_features::{self, ShapeFeatureKey, ShapeFeatureParams};
use crate::stages::field::feature_field::{self, FeatureFieldParams, carry_field};
use crate::stages::parameterize::edge_refinement::{self, RefineParams};
use crate::stages::reconstruct::feature_aligned_export::{self, FeatureAlignedExportParams};
use crate::stages::reconstruct::feature_aligned_report as report;
use crate::stages::synthesize::texture_optimization::{
    self as opt, SurfaceSynthesis, TextureOptimizationParams,
};
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

/// The `feature_aligned` method.
pub struct FeatureAligned;

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

impl Method for FeatureAligned {
    fn name(&self) -> &'static str {
        "feature_aligned"
    }

    fn plan(&self, config: &Config) -> Result<(Dag, Box<dyn Planned>), MethodError> {
        let c: FeatureAlignedConfig = config.parse()?;
        let what = "exemplar texels per object unit (the texture's size on the mesh)";
        super::require_scale(config, c.parameterize.scale, what)?;
        c.parameterize.validate().map_err(|e| config.param(e))?;
        c.extract.validate().map_err(|e| config.param(e))?;
        c.analyse_exemplar.validate().map_err(|e| config.param(e))?;
        c.field.validate().map_err(|e| config.param(e))?;
        c.synthesize.validate().map_err(|e| config.param(e))?;
        c.reconstruct.validate().map_err(|e| config.param(e))?;
        let mut dag = Dag::default();
        let mesh = input::<Mesh>(&mut dag, config, "mesh", &c.inputs.mesh)?;
        let exemplar = input::<Image>(&mut dag, config, "exemplar", &c.inputs.exemplar)?;
        if let Some((size, path)) = super::exemplar_size(config, &c.inputs.exemplar) {
            let p = &c.synthesize;
            config.check("synthesize.patch", opt::check_patch_fits(size, &path, p))?;
            let texels = size.0 as u64 * size.1 as u64;
            let estimate = |w| opt::memory_estimate(texels, w, p.levels as u64);
            let show = |w: u64| w.to_string();
            super::check_memory(config, "synthesize.patch", p.patch as u64, estimate, show)?;
        }
        if c.reconstruct.atlas_size > 0 {
            super::check_atlas_memory(config, c.reconstruct.atlas_size)?;
        }
        let mask = c.inputs.feature_mask.as_ref();
        let mask = mask
            .map(|m| input::<Image>(&mut dag, config, "feature_mask", m))
            .transpose()?;
        let file = |f: &PathBuf| dag.file(&config.resolve(f), "extract.curves_file");
        let curves_file = c.extract.curves_file.as_ref().map(file).transpose()?;
        let shape = dag.node(
            NodeSpec::of(Stage::Extract, shape_features::NODE),
            ShapeFeatureKey::new(&c.extract),
            (mesh, curves_file),
            |_, p, (mesh, f)| {
                Ok(shape_features::node(
                    &mesh,
                    p,
                    f.map(|f| (&*f.path, &*f.bytes)),
                    "feature_aligned",
                )?)
            },
        );
        let features = dag.node(
            NodeSpec::of(Stage::AnalyseExemplar, texture_feature_lines::NODE),
            c.analyse_exemplar.clone(),
            (exemplar, mask),
            |_, p, (img, mask)| {
                let mask = mask.map(|m| m.to_owned());
                Ok(texture_feature_lines::node(
                    &img.to_owned(),
                    mask.as_ref(),
                    p,
                )?)
            },
        );
        let field = dag.node(
            NodeSpec::of(Stage::Field, feature_field::NODE),
            c.field.clone(),
            (mesh, shape),
            |_, p, (mesh, shape)| Ok(feature_field::node(&mesh, &shape.curves, p)?),
        );
        let refined = dag.node(
            NodeSpec::of(Stage::Parameterize, edge_refinement::NODE),
            c.parameterize.clone(),
            mesh,
            |_, p, mesh| Ok(edge_refinement::node(&mesh, p)?),
        );
        let mut synthesis = |aligned: bool| {
            let name = if aligned {
                "synthesize"
            } else {
                "synthesize.unaligned"
            };
            let (scale, optimization) = (c.parameterize.scale, c.synthesize.clone());
            let key = opt::SynthesisKey {
                scale,
                aligned,
                optimization,
            };
            dag.node(
                NodeSpec::of(Stage::Synthesize, opt::NODE).named(name),
                key,
                (refined, field, exemplar, features),
                |ctx, key, (refined, field, img, tf)| {
                    let progress = |f| ctx.progress.set(f);
                    Ok(opt::node(
                        &refined,
                        &field,
                        &img.to_owned(),
                        &tf,
                        key,
                        &progress,
                    )?)
                },
            )
        };
        let aligned = synthesis(true);
        let unaligned: Option<Handle<SurfaceSynthesis>> = c.compare.then(|| synthesis(false));
        dag.node(
            NodeSpec::of(Stage::Reconstruct, feature_aligned_export::NODE),
            c.reconstruct.clone(),
            (
                mesh, shape, refined, field, aligned, unaligned, exemplar, features,
            ),
            |ctx, p, (input, shape, refined, field, aligned, unaligned, img, features)| {
                let exemplar = &img.to_owned();
                let (shape, refined, field, aligned) = (&shape, &refined, &field, &aligned);
                let unaligned = unaligned.as_ref();
                let run = report::FeatureAlignedRun {
                    input: &input,
                    shape,
                    refined,
                    field,
                    aligned,
                    unaligned,
                    exemplar,
                    features: &features,
                };
                Ok(Bundle::from(report::node(&run, p, &|f| {
                    ctx.progress.set(f)
                })?))
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
        Ok((dag, Box::new(FeatureAlignedScore { nodes, scale })))
    }
}
