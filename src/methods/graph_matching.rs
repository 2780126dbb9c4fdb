//! Method `graph_matching`: vertex colours grown coarse to fine on a √2-subdivision hierarchy,
//! each vertex's region matched against a Gaussian stack of the exemplar and copied in by a
//! graph cut (Bangay & Morkel, "Graph Matching with Subdivision Surfaces for Texture Synthesis
//! on Surfaces", AFRIGRAPH 2006).
//!
//! ```text
//! inputs.exemplar ─ import.exemplar ─ analyse_exemplar (Gaussian stack) ──────────────┐
//! inputs.mesh ─ import.mesh ─ field.keys ───────────────────┐                         │
//!                          └─ parameterize (√2 hierarchy) ─ field (orientation, sweep) ─ synthesize
//!                                                       └───────────────────────────────── reconstruct ─ files
//! ```
//!
//! The keys are resolved on the input mesh in their own small node, declared before the
//! subdivision, so a key on a vertex that does not exist is reported before any work starts;
//! so is a region larger than the exemplar (read from the image header when the plan is made).

use super::{Method, MethodError, Planned, input};
use crate::artifact::Bundle;
use crate::config::Config;
use crate::geom::Mesh;
use crate::image::Image;
use crate::pipeline::{Dag, NodeSpec, Stage};
use crate::score::surface::{BakedAtlas, GraphMatchingNodes};
use crate::stages::analyse_exemplar::gaussian_stack::{self, StackParams};
use crate::stages::field::sweep_field::{self, SweepFieldParams};
use crate::stages::parameterize::sqrt2_subdivision::{self, SubdivisionParams};
use crate::stages::reconstruct::vertex_colour_export::{self, VertexColourExportParams};
use crate::stages::synthesize::graph_matching::{self as gm, MatchParams};
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// A `graph_matching` config.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct GraphMatchingConfig {
    pub method: String,
    pub inputs: Inputs,
    #[serde(default)]
    pub analyse_exemplar: StackParams,
    #[serde(default)]
    pub field: SweepFieldParams,
    #[serde(default)]
    pub parameterize: SubdivisionParams,
    #[serde(default)]
    pub synthesize: MatchParams,
    #[serde(default)]
    pub reconstruct: VertexColourExportParams,
}

#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Inputs {
    /// The mesh to colour (.obj, .off, .ply, .stl): any genus, open or closed.
    pub mesh: PathBuf,
    /// The exemplar (.png, .jpg, .exr): colour, or grey values for displacement.
    pub exemplar: PathBuf,
}

/// The `graph_matching` method.
pub struct GraphMatchingMethod;

impl Method for GraphMatchingMethod {
    fn name(&self) -> &'static str {
        "graph_matching"
    }

    fn plan(&self, config: &Config) -> Result<(Dag, Box<dyn Planned>), MethodError> {
        let mut c: GraphMatchingConfig = config.parse()?;
        let (mesh, exemplar) = (&c.inputs.mesh, &c.inputs.exemplar);
        super::resolve_scale(config, &mut c.parameterize.scale, mesh, exemplar);
        c.analyse_exemplar.validate().map_err(|e| config.param(e))?;
        c.parameterize.validate().map_err(|e| config.param(e))?;
        c.field.validate().map_err(|e| config.param(e))?;
        c.synthesize.validate().map_err(|e| config.param(e))?;
        c.reconstruct.validate().map_err(|e| config.param(e))?;
        super::checks::check_preview_memory(config, c.reconstruct.preview_size)?;
        if c.reconstruct.atlas_size > 0 {
            super::check_atlas_memory(config, c.reconstruct.atlas_size)?;
        }

        let mut dag = Dag::default();
        let mesh = input::<Mesh>(&mut dag, config, "mesh", &c.inputs.mesh)?;
        let exemplar = input::<Image>(&mut dag, config, "exemplar", &c.inputs.exemplar)?;
        if let Some((size, path)) = super::exemplar_size(config, &c.inputs.exemplar) {
            let (key, verdict) = gm::check_exemplar_fits(size, &path, &c.synthesize);
            config.check(key, verdict)?;
        }
        let spec = NodeSpec::of(Stage::Field, sweep_field::KEYS_NODE).named("field.keys");
        let keys = dag.node(spec, c.field.key_points(), mesh, |_, points, mesh| {
            Ok(sweep_field::keys_node(&mesh, points)?)
        });
        let stack = dag.node(
            NodeSpec::of(Stage::AnalyseExemplar, gaussian_stack::NODE),
            c.analyse_exemplar.clone(),
            exemplar,
            |_, p, img| Ok(gaussian_stack::node(img, p)?),
        );
        let hierarchy = dag.node(
            NodeSpec::of(Stage::Parameterize, sqrt2_subdivision::NODE),
            c.parameterize.clone(),
            mesh,
            |_, p, mesh| Ok(sqrt2_subdivision::node(&mesh, p, "graph_matching")?),
        );
        let field = dag.node(
            NodeSpec::of(Stage::Field, sweep_field::NODE),
            c.field.clone(),
            (hierarchy, keys),
            |_, p, (h, keys)| Ok(sweep_field::node(&h, &keys, p)?),
        );
        let key = gm::MatchKey {
            scale: c.parameterize.scale,
            matching: c.synthesize.clone(),
        };
        let colours = dag.node(
            NodeSpec::of(Stage::Synthesize, gm::NODE),
            key,
            (hierarchy, field, stack),
            |ctx, key, (h, field, stack)| {
                Ok(gm::node(&h, &field, stack.view(), key, &|f| {
                    ctx.progress.set(f)
                })?)
            },
        );
        dag.node(
            NodeSpec::of(Stage::Reconstruct, vertex_colour_export::NODE),
            vertex_colour_export::ExportKey {
                scale: c.parameterize.scale,
                reconstruct: c.reconstruct.clone(),
            },
            (mesh, hierarchy, colours, exemplar, field),
            |ctx, key, (mesh, h, out, exemplar, field)| {
                let progress = |f| ctx.progress.set(f);
                let colours = &out.level_colours;
                let copied = vertex_colour_export::CopiedFrom {
                    sources: &out.sources,
                    exemplar,
                    field: &field.orientation,
                    scale: key.scale,
                };
                let files = vertex_colour_export::node(
                    &mesh,
                    &h,
                    colours,
                    Some(copied),
                    &key.reconstruct,
                    &progress,
                )?;
                Ok(Bundle::from(files))
            },
        );
        let nodes = GraphMatchingNodes {
            mesh,
            parameterize: hierarchy,
            field,
            synthesize: colours,
            exemplar,
            scale: c.parameterize.scale,
            atlas: (c.reconstruct.atlas_size > 0).then_some(BakedAtlas {
                size: c.reconstruct.atlas_size,
                sampling: c.reconstruct.lookup,
            }),
        };
        Ok((dag, Box::new(nodes)))
    }
}
