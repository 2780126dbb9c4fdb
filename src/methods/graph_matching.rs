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

use super::{Method, MethodError, Planned, import};
use crate::artifact::Bundle;
use crate::config::Config;
use crate::geom::Mesh;
use crate::image::Image;
use crate::pipeline::{Dag, NodeError, NodeSpec, Stage};
use crate::score::surface::GraphMatchingNodes;
use crate::score::{Item, Run, ScoreFailure};
use crate::stages::analyse_exemplar::gaussian_stack::{StackParams, build_stack};
use crate::stages::field::sweep_field::{SweepFieldParams, resolve_keys, sweep_field};
use crate::stages::parameterize::sqrt2_subdivision::{SubdivisionParams, build_hierarchy};
use crate::stages::reconstruct::vertex_colour_export::{
    ColouredLevel, VertexColourExportParams, export_vertex_colours,
};
use crate::stages::synthesize::graph_matching::{MatchInput, MatchParams, graph_matching};
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

/// What synthesis reads besides its inputs: its own parameters and the texture scale.
#[derive(Serialize)]
struct SynthParams {
    scale: f32,
    matching: MatchParams,
}

/// The `graph_matching` method.
pub struct GraphMatchingMethod;

impl Method for GraphMatchingMethod {
    fn name(&self) -> &'static str {
        "graph_matching"
    }

    fn plan(&self, config: &Config) -> Result<(Dag, Box<dyn Planned>), MethodError> {
        let (dag, planned) = build(config)?;
        Ok((dag, Box::new(planned)))
    }
}

/// What graph matching's score reads: its nodes and the texture scale.
struct GraphMatchingScore {
    nodes: GraphMatchingNodes,
    scale: f32,
}

impl Planned for GraphMatchingScore {
    fn score(&self, run: &Run<'_>, _: &mut Vec<String>) -> Result<Vec<Item>, ScoreFailure> {
        Ok(vec![crate::score::surface::graph_matching(
            run,
            &self.nodes,
            self.scale,
        )?])
    }
}

fn build(config: &Config) -> Result<(Dag, GraphMatchingScore), MethodError> {
    let c: GraphMatchingConfig = config.parse()?;
    if !config.gives("parameterize", "scale") {
        return Err(config
            .invalid(
                "parameterize.scale",
                "is required: level-0 exemplar texels per object unit (it sets how far the mesh is subdivided)",
            )
            .into());
    }
    if c.parameterize.scale.is_nan() || c.parameterize.scale <= 0.0 {
        return Err(config
            .invalid(
                "parameterize.scale",
                &format!("must be a positive number, got {}", c.parameterize.scale),
            )
            .into());
    }
    c.analyse_exemplar.validate().map_err(|e| config.param(e))?;
    c.parameterize.validate().map_err(|e| config.param(e))?;
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
    check_region_fits(config, &exemplar_path, &c.synthesize)?;

    let keys = dag.node(
        NodeSpec::of(Stage::Field, crate::stages::field::sweep_field::KEYS_NODE)
            .named("field.keys"),
        c.field.keys.clone(),
        mesh,
        |_, keys, mesh| {
            let p = SweepFieldParams {
                keys: keys.clone(),
                ..Default::default()
            };
            resolve_keys(&mesh, &p).map_err(NodeError::input)
        },
    );
    let stack = dag.node(
        NodeSpec::of(
            Stage::AnalyseExemplar,
            crate::stages::analyse_exemplar::gaussian_stack::NODE,
        ),
        c.analyse_exemplar.clone(),
        exemplar,
        |_, p, img| build_stack(img, p).map_err(NodeError::input),
    );
    let hierarchy = dag.node(
        NodeSpec::of(
            Stage::Parameterize,
            crate::stages::parameterize::sqrt2_subdivision::NODE,
        ),
        c.parameterize.clone(),
        mesh,
        |_, p, mesh| {
            if let Some(w) = crate::geom::mesh_check::mesh_health(&mesh).warning("graph_matching") {
                tracing::warn!("{w}");
            }
            let h = build_hierarchy(&mesh, p.scale, p).map_err(NodeError::input)?;
            tracing::info!(
                "parameterize: {} levels, {} → {} vertices",
                h.levels(),
                h.level_vertices[0],
                h.level_vertices.last().copied().unwrap_or(0)
            );
            Ok(h)
        },
    );
    let field = dag.node(
        NodeSpec::of(Stage::Field, crate::stages::field::sweep_field::NODE),
        c.field.clone(),
        (hierarchy, keys),
        |_, p, (h, keys)| {
            if keys.vertices.iter().any(|&v| v >= h.level_vertices[0]) {
                return Err(NodeError::internal(
                    "a field key names a vertex level 0 lacks",
                ));
            }
            sweep_field(&h, &keys, p).map_err(NodeError::input)
        },
    );
    let params = SynthParams {
        scale: c.parameterize.scale,
        matching: c.synthesize.clone(),
    };
    let colours = dag.node(
        NodeSpec::of(Stage::Synthesize, crate::stages::synthesize::graph_matching::NODE),
        params,
        (hierarchy, field, stack),
        |ctx, p, (h, field, stack)| {
            if field.orientation.len() != h.positions.len()
                || field.sweep.len() != h.level_vertices[0] as usize
            {
                return Err(NodeError::internal("the field and the hierarchy disagree"));
            }
            let input = MatchInput {
                hierarchy: &h,
                field: &field,
                stack: stack.view(),
                scale: p.scale,
            };
            let out = graph_matching(&input, &p.matching, &|f| ctx.progress.set(f))
                .map_err(NodeError::input)?;
            let s = &out.stats;
            tracing::info!(
                "synthesize: {} matches, {} comparisons ({} without averaging), {} vertices transferred, {} random starts",
                s.matches,
                s.comparisons,
                s.comparisons_without_averaging,
                s.transferred,
                s.random_starts
            );
            Ok(out)
        },
    );
    dag.node(
        NodeSpec::of(
            Stage::Reconstruct,
            crate::stages::reconstruct::vertex_colour_export::NODE,
        ),
        c.reconstruct.clone(),
        (hierarchy, colours),
        |ctx, p, (h, out)| {
            let mut start = 0;
            let mut levels = Vec::new();
            for l in 0..h.levels() {
                let n = h.level_vertices[l] as usize;
                if out.level_colours.len() < start + n {
                    return Err(NodeError::internal("colours and hierarchy disagree"));
                }
                levels.push(ColouredLevel {
                    mesh: h.level(l),
                    colours: &out.level_colours[start..start + n],
                });
                start += n;
            }
            Ok(Bundle::from(export_vertex_colours(&levels, p, &|f| {
                ctx.progress.set(f)
            })))
        },
    );
    let nodes = GraphMatchingNodes {
        parameterize: hierarchy,
        field,
        synthesize: colours,
        exemplar,
    };
    let scale = c.parameterize.scale;
    Ok((dag, GraphMatchingScore { nodes, scale }))
}

/// The region must fit the exemplar: checked from the image header, before any node runs. An
/// unreadable header is left to the import node, which names the problem.
fn check_region_fits(
    config: &Config,
    path: &std::path::Path,
    p: &MatchParams,
) -> Result<(), MethodError> {
    let Ok(reader) = image::ImageReader::open(path).and_then(|r| r.with_guessed_format()) else {
        return Ok(());
    };
    let Ok((w, h)) = reader.into_dimensions() else {
        return Ok(());
    };
    if w.min(h) < 8 {
        return Err(config
            .invalid(
                "inputs.exemplar",
                &format!(
                    "{} is {w}×{h} texels; graph matching needs at least 8×8",
                    path.display()
                ),
            )
            .into());
    }
    let max = w.min(h) / 2;
    if p.region > max {
        return Err(config
            .invalid(
                "synthesize.region",
                &format!(
                    "{} texels does not fit the {w}×{h} exemplar {}: use at most {max}, or a larger exemplar",
                    p.region,
                    path.display()
                ),
            )
            .into());
    }
    Ok(())
}
