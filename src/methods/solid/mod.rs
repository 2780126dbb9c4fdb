//! Method `solid`: sketch-guided solid texturing, synthesized on demand (Zhang, Du, Lai, Ni &
//! Hu 2011).
//!
//! ```text
//! inputs.xy/yz/zx ─ import.* ─ analyse_exemplar (stacks, PCA, candidate triples and slabs) ─┐
//! inputs.mesh ─ import.mesh ─┬─ field (quaternion field from the sketch curves) ───────────┼─ synthesize ─ reconstruct ─ files
//!                            └─ parameterize (volume, requested voxels) ───────────────────┘
//! ```
//!
//! `synthesize` caches every pyramid level as bricks, keyed pieces of the node that depend on
//! the analysis, the field, the volume and the synthesis parameters but never on the request:
//! a second request (another cut through the same solid) reuses every brick the first made.
//! Each `[[regions]]` entry adds its own analysis and synthesis, at the voxels it owns.
//!
//! Coupled parameters: the pyramid depth is `analyse_exemplar.levels`, or the length of
//! `[[synthesize.levels]]` when only that is given; without `[[synthesize.levels]]` every level
//! gets the paper's settings. The field's grid covers the volume's box, so the field node's
//! key holds `parameterize.margin` too.

mod config;
mod nodes;

pub use config::{SolidConfig, SolidInputs, SolidRegion};

use super::{Imports, Method, MethodError, Planned, import};
use crate::artifact::Bundle;
use crate::config::Config;
use crate::geom::Mesh;
use crate::pipeline::Stage::{Field, Parameterize, Reconstruct};
use crate::pipeline::{Dag, NodeSpec, WithTail};
use crate::score::solid::{SolidNodes, SolidScore, SolidSetup};
use crate::stages::field::quaternion_field::{self as sketch};
use crate::stages::parameterize::volume_embedding as volume;
use crate::stages::reconstruct::solid_colour::{self as colour};
use std::path::PathBuf;

/// The `solid` method.
pub struct Solid;

impl Method for Solid {
    fn name(&self) -> &'static str {
        "solid"
    }

    fn plan(&self, config: &Config) -> Result<(Dag, Box<dyn Planned>), MethodError> {
        let (dag, planned) = build(config)?;
        Ok((dag, Box::new(planned)))
    }
}

fn build(config: &Config) -> Result<(Dag, SolidScore), MethodError> {
    let c = config::checked(config)?;
    let depths: Vec<f32> = c.regions.iter().map(|r| r.depth).collect();
    let mut dag = Dag::default();
    let mesh_path = config.resolve(&c.inputs.mesh);
    let mesh = import::<Mesh>(&mut dag, "import.mesh", &mesh_path, "inputs.mesh")?;
    let mut images = Imports::new("import.exemplar");
    let mut analysis = |dag: &mut Dag, name: &str, key: &str, planes, params| {
        nodes::add_analysis(dag, config, &mut images, (name, key), planes, params)
    };
    let i = &c.inputs;
    let core_planes = [&i.exemplar, &i.xy, &i.yz, &i.zx];
    let core_analysis = analysis(
        &mut dag,
        "analyse_exemplar",
        "inputs",
        core_planes,
        c.analyse_exemplar.clone(),
    )?;
    let mut region_analyses = Vec::new();
    for (k, r) in c.regions.iter().enumerate() {
        let key = format!("regions[{k}]");
        let mut p = c.analyse_exemplar.clone();
        if let Some(w) = r.plane_weights {
            p.plane_weights = w;
            config.check(&format!("{key}.plane_weights"), p.validate())?;
        }
        let name = format!("analyse_exemplar.region{}", k + 1);
        let planes = [&r.exemplar, &r.xy, &r.yz, &r.zx];
        region_analyses.push(analysis(&mut dag, &name, &key, planes, p)?);
    }
    let file = |f: &PathBuf| dag.file(&config.resolve(f), "field.curves_file");
    let curves_file = c.field.curves_file.as_ref().map(file).transpose()?;
    let field = dag.node(
        NodeSpec::of(Field, sketch::NODE),
        c.field.solid_field(c.parameterize.margin),
        (mesh, curves_file),
        |ctx, p, (mesh, f)| {
            let file = f.map(|f| (&*f.path, &*f.bytes));
            Ok(sketch::node(&mesh, p, file, &|f| ctx.progress.set(f))?)
        },
    );
    let regions = (!depths.is_empty()).then_some(depths);
    let request = dag.node(
        NodeSpec::of(Parameterize, volume::NODE),
        WithTail(c.parameterize.clone(), regions.clone()),
        mesh,
        |_, WithTail(p, depths), mesh| Ok(volume::node(&mesh, p, depths.as_deref())?),
    );
    let synthesis = |dag: &mut Dag, name: String, analysis, region| {
        let params = WithTail(c.synthesize.clone(), region);
        nodes::add_synthesis(dag, name, analysis, (field, request), params)
    };
    // The core owns the voxels below every region (index: the number of regions).
    let core = regions.map(|d| d.len() as u8);
    let samples = synthesis(&mut dag, "synthesize".into(), core_analysis, core);
    let mut pairs = Vec::new();
    for (k, a) in region_analyses.into_iter().enumerate() {
        let name = format!("synthesize.region{}", k + 1);
        pairs.push((synthesis(&mut dag, name, a, Some(k as u8)), a));
    }
    let key = colour::SolidColourKey {
        export: c.reconstruct.clone(),
        request: c.parameterize.request.clone(),
    };
    // The core's samples and analysis, the request, mesh and field (the voxels' frames, for
    // the planes facing a surface), then each region's pair.
    let reconstruct = dag.node(
        NodeSpec::of(Reconstruct, colour::NODE),
        key,
        (samples, core_analysis, request, mesh, field, pairs),
        |ctx, key, (samples, analysis, req, mesh, field, pairs)| {
            let sets = std::iter::once((samples, analysis)).chain(pairs);
            let sets = sets.map(|(s, a)| (s.voxels, s.triples, a));
            let (volume, voxels, section) = (&req.volume, req.voxels, req.section.as_ref());
            let request = colour::RequestView {
                volume,
                voxels,
                section,
                field: &field,
            };
            let files = colour::node(key, &mesh, request, sets, &|f| ctx.progress.set(f))?;
            Ok(Bundle::from(files))
        },
    );
    let i = &c.inputs;
    let setup = SolidSetup {
        request: c.parameterize.request.clone(),
        xy: i.xy.clone(),
        yz: i.yz.clone(),
        zx: i.zx.clone(),
        exemplar: i.exemplar.clone(),
        regions: c.regions.len(),
        sketched: !c.field.curves.is_empty() || c.field.curves_file.is_some(),
    };
    let nodes = SolidNodes { mesh, reconstruct };
    Ok((dag, SolidScore { nodes, setup }))
}
