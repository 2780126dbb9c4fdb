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

mod config;

pub use config::{FeatureAlignedConfig, Inputs};

use super::{Method, MethodError, Planned, input};
use crate::artifact::Bundle;
use crate::config::Config;
use crate::geom::Mesh;
use crate::image::Image;
use crate::pipeline::{Dag, Handle, NodeSpec, Stage};
use crate::score::surface::FeatureAlignedNodes;
use crate::stages::analyse_exemplar::texture_feature_lines;
use crate::stages::extract::shape_features::{self, ShapeFeatureKey};
use crate::stages::field::feature_field;
use crate::stages::parameterize::edge_refinement;
use crate::stages::reconstruct::feature_aligned_export;
use crate::stages::reconstruct::feature_aligned_report as report;
use crate::stages::synthesize::texture_optimization::{self as opt, SurfaceSynthesis};
use std::path::PathBuf;

/// The node of the comparison synthesized without the feature constraint.
const UNALIGNED_NODE: &str = "synthesize.unaligned";

/// The `feature_aligned` method.
pub struct FeatureAligned;

impl Method for FeatureAligned {
    fn name(&self) -> &'static str {
        "feature_aligned"
    }

    fn plan(&self, config: &Config) -> Result<(Dag, Box<dyn Planned>), MethodError> {
        let c = config::checked(config)?;
        let mut dag = Dag::default();
        let mesh = input::<Mesh>(&mut dag, config, "mesh", &c.inputs.mesh)?;
        let exemplar = input::<Image>(&mut dag, config, "exemplar", &c.inputs.exemplar)?;
        config::check_exemplar_fits(config, &c)?;
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
                let curves = f.map(|f| (&*f.path, &*f.bytes));
                Ok(shape_features::node(&mesh, p, curves, "feature_aligned")?)
            },
        );
        let features = dag.node(
            NodeSpec::of(Stage::AnalyseExemplar, texture_feature_lines::NODE),
            c.analyse_exemplar.clone(),
            (exemplar, mask),
            |_, p, (img, mask)| {
                let (img, mask) = (img.to_owned(), mask.map(|m| m.to_owned()));
                Ok(texture_feature_lines::node(&img, mask.as_ref(), p)?)
            },
        );
        let field = dag.node(
            NodeSpec::of(Stage::Field, feature_field::NODE),
            c.field.clone(),
            (mesh, shape),
            |ctx, p, (mesh, shape)| {
                let progress = |f| ctx.progress.set(f);
                Ok(feature_field::node(
                    &mesh,
                    &shape.curves,
                    &shape.fixed,
                    p,
                    &progress,
                )?)
            },
        );
        let refined = dag.node(
            NodeSpec::of(Stage::Parameterize, edge_refinement::NODE),
            c.parameterize.clone(),
            mesh,
            |_, p, mesh| Ok(edge_refinement::node(&mesh, p)?),
        );
        let mut synthesis = |aligned: bool| {
            let name = [UNALIGNED_NODE, "synthesize"][aligned as usize];
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
                    let (img, progress) = (img.to_owned(), |f| ctx.progress.set(f));
                    Ok(opt::node(&refined, &field, &img, &tf, key, &progress)?)
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
                let files = report::node(&run, p, &|f| ctx.progress.set(f))?;
                Ok(Bundle::from(files))
            },
        );
        let mut synthesize = vec![(aligned, "the aligned texture")];
        synthesize.extend(unaligned.map(|u| (u, "the unaligned comparison's texture")));
        let nodes = FeatureAlignedNodes {
            parameterize: refined,
            field,
            analyse_exemplar: features,
            exemplar,
            synthesize,
            scale: c.parameterize.scale,
            lookup: c.reconstruct.lookup,
            mesh,
            atlas_size: c.reconstruct.atlas_size,
        };
        Ok((dag, Box::new(nodes)))
    }
}
