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

use super::{Imports, Method, MethodError, Planned, import};
use crate::artifact::Bundle;
use crate::artifact::solid::SolidSamples;
use crate::check::ParamError;
use crate::config::Config;
use crate::geom::Mesh;
use crate::image::Image;
use crate::pipeline::RunResult;
use crate::pipeline::Stage::{AnalyseExemplar, Field, Parameterize, Reconstruct, Synthesize};
use crate::pipeline::shard;
use crate::pipeline::{Dag, Handle, Keyed, NodeError, NodeSpec, WithTail};
use crate::score::solid::{PlaneExemplar, SolidNodes, SolidSetup};
use crate::score::{Item, Run, ScoreFailure};
use crate::stages::analyse_exemplar::candidate_triples::{self as triples, SolidAnalysis};
use crate::stages::field::quaternion_field::{self as sketch, RotationField};
use crate::stages::parameterize::volume_embedding as volume;
use crate::stages::parameterize::volume_embedding::{RequestParams, RequestedVoxels as Request};
use crate::stages::reconstruct::solid_colour::{self as colour, SolidExportParams};
use crate::stages::synthesize::solid::solid_synthesis::{self as synthesis, Brick, SolidError};
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

/// An exemplar image, optionally transposed (so one image can show the same layers in two
/// planes whose axes run the other way round).
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(untagged)]
pub enum ExemplarSpec {
    Path(PathBuf),
    Spec {
        path: PathBuf,
        #[serde(default)]
        transpose: bool,
    },
}

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

/// What the solid's score reads: its nodes and the request and exemplars of its config.
struct SolidScore {
    nodes: SolidNodes,
    setup: SolidSetup,
}

impl Planned for SolidScore {
    fn score(
        &self,
        run: &Run<'_>,
        not_scored: &mut Vec<String>,
    ) -> Result<Vec<Item>, ScoreFailure> {
        crate::score::solid::solid(run, &self.nodes, &self.setup, not_scored)
    }

    fn score_substitute(&self, result: &RunResult) -> Option<String> {
        crate::score::solid::substitute_section(result, &self.nodes, &self.setup.request)
    }
}

impl ExemplarSpec {
    fn plane(&self) -> PlaneExemplar {
        match self {
            ExemplarSpec::Path(p) => PlaneExemplar {
                path: p.clone(),
                transpose: false,
            },
            ExemplarSpec::Spec { path, transpose } => PlaneExemplar {
                path: path.clone(),
                transpose: *transpose,
            },
        }
    }
}

fn build(config: &Config) -> Result<(Dag, SolidScore), MethodError> {
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
    super::check_atlas_memory(config, c.reconstruct.atlas_size)?;
    super::check_solid_memory(config, c.parameterize.resolution, &c.parameterize.request)?;
    config.check("synthesize", c.synthesize.validate())?;
    let depths: Vec<f32> = c.regions.iter().map(|r| r.depth).collect();
    volume::validate_region_depths(&depths).map_err(param)?;
    let mut dag = Dag::default();
    let mesh_path = config.resolve(&c.inputs.mesh);
    let mesh = import::<Mesh>(&mut dag, "import.mesh", &mesh_path, "inputs.mesh")?;
    let mut images = Imports::new("import.exemplar");
    let mut analysis = |dag: &mut Dag, name: &str, key: &str, planes, params| {
        add_analysis(dag, config, &mut images, (name, key), planes, params)
    };
    let i = &c.inputs;
    let core_planes = [&i.exemplar, &i.xy, &i.yz, &i.zx];
    let core_analysis = analysis(&mut dag, "analyse_exemplar", "inputs", core_planes, p)?;
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
        |_, p, (mesh, f)| Ok(sketch::node(&mesh, p, f.map(|f| (&*f.path, &*f.bytes)))?),
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
        add_synthesis(dag, name, analysis, (field, request), params)
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
    // The core's samples and analysis, the request and mesh, then each region's pair.
    let reconstruct = dag.node(
        NodeSpec::of(Reconstruct, colour::NODE),
        key,
        (samples, core_analysis, request, mesh, pairs),
        |ctx, key, (samples, analysis, req, mesh, pairs)| {
            let sets = std::iter::once((samples, analysis)).chain(pairs);
            let sets = sets.map(|(s, a)| (s.voxels, s.triples, a));
            let (volume, voxels, section) = (&req.volume, req.voxels, req.section.as_ref());
            let request = colour::RequestView {
                volume,
                voxels,
                section,
            };
            let files = colour::node(key, &mesh, request, sets, &|f| ctx.progress.set(f))?;
            Ok(Bundle::from(files))
        },
    );
    let i = &c.inputs;
    let setup = SolidSetup {
        request: c.parameterize.request.clone(),
        xy: i.xy.as_ref().map(ExemplarSpec::plane),
        yz: i.yz.as_ref().map(ExemplarSpec::plane),
        zx: i.zx.as_ref().map(ExemplarSpec::plane),
        exemplar: i.exemplar.as_ref().map(ExemplarSpec::plane),
        regions: c.regions.len(),
        sketched: !c.field.curves.is_empty() || c.field.curves_file.is_some(),
    };
    let nodes = SolidNodes { mesh, reconstruct };
    Ok((dag, SolidScore { nodes, setup }))
}

/// The candidate-triple analysis of one exemplar set: `[exemplar, xy, yz, zx]` of the config
/// table `key`, each plane's image falling back to the shared one.
fn add_analysis(
    dag: &mut Dag,
    config: &Config,
    images: &mut Imports<Image>,
    (name, key): (&str, &str),
    [shared, xy, yz, zx]: [&Option<ExemplarSpec>; 4],
    params: triples::CandidateParams,
) -> Result<Handle<SolidAnalysis>, MethodError> {
    // Each plane's image (imported once per file) and whether it is transposed.
    let planes = [("xy", xy), ("yz", yz), ("zx", zx)].map(|(plane, spec)| {
        let (spec, role) = match (spec, shared) {
            (Some(s), _) => (s, format!("{key}.{plane}")),
            (None, Some(s)) => (s, format!("{key}.exemplar")),
            (None, None) => {
                let m = "missing: give `exemplar` for all planes or one per plane";
                return Err(config.invalid(&format!("{key}.{plane}"), m).into());
            }
        };
        let (path, transpose) = match spec {
            ExemplarSpec::Path(path) => (path, false),
            ExemplarSpec::Spec { path, transpose } => (path, *transpose),
        };
        Ok::<_, MethodError>((images.get(dag, &config.resolve(path), &role)?, transpose))
    });
    let [xy, yz, zx] = planes;
    let [(xy, tx), (yz, ty), (zx, tz)] = [xy?, yz?, zx?];
    let key = triples::AnalysisKey {
        analysis: params,
        transpose: [tx, ty, tz],
    };
    let spec = NodeSpec::of(AnalyseExemplar, triples::NODE).named(name);
    Ok(dag.node(spec, key, [xy, yz, zx], |_, key, planes| {
        Ok(triples::node(planes, key)?)
    }))
}

/// The synthesis of one exemplar set's solid at the requested voxels that `region` owns
/// (`None`: all of them), its bricks cached as the node's pieces.
fn add_synthesis(
    dag: &mut Dag,
    name: String,
    analysis: Handle<SolidAnalysis>,
    (field, request): (Handle<RotationField>, Handle<Request>),
    params: WithTail<synthesis::SolidParams, u8>,
) -> Handle<SolidSamples> {
    let spec = NodeSpec::of(Synthesize, crate::stages::synthesize::solid::NODE).named(name);
    dag.node(
        spec.pieces("solid brick", &params.0),
        params,
        (Keyed(analysis), Keyed(field), request),
        |ctx, WithTail(p, region), (analysis, field, req)| {
            let synth = synthesis::SolidSynthesis::new(analysis, &field, req.volume, p.clone());
            let synth = synth.map_err(NodeError::input)?;
            let voxels = volume::region_voxels(req.voxels, req.regions, *region)
                .ok_or_else(|| NodeError::internal("a region's synthesis without voxel regions"))?;
            let bricks = ctx.pieces::<(u32, [i32; 3]), Brick>(synth.pyramid())?;
            if let Some(mode) = ctx.shard() {
                let assign = |all: &[[i32; 3]]| shard::assign(all, mode.shard);
                let share =
                    synthesis::synthesize_share(&synth, &voxels, &bricks, &assign, mode.plan_only);
                return Err(ctx.shard_done(&share?));
            }
            let run = synth.synthesize_voxels(&voxels, &bricks);
            let run = run.map_err(|e| NodeError::classify(e, SolidError::is_internal));
            Ok(SolidSamples::new(voxels, run?.0))
        },
    )
}
