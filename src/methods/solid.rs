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
use crate::pipeline::shard::{self, ShardMode};
use crate::pipeline::{Dag, Handle, Keyed, NodeError, NodeSpec, PieceStore, WithTail};
use crate::score::solid::{PlaneExemplar, SolidNodes, SolidSetup};
use crate::score::{Item, Run, ScoreFailure};
use crate::stages::analyse_exemplar::candidate_triples::{self as triples, SolidAnalysis};
use crate::stages::field::quaternion_field::{self as sketch, RotationField};
use crate::stages::parameterize::volume_embedding as volume;
use crate::stages::parameterize::volume_embedding::{RequestParams, RequestedVoxels as Request};
use crate::stages::reconstruct::solid_colour::{self as colour, SolidExportParams};
use crate::stages::synthesize::solid::solid_synthesis::{
    self as synthesis, Brick, BrickStore, SolidError, VoxelRequest,
};
use serde::{Deserialize, Serialize};
use std::path::PathBuf;
use std::sync::Arc;

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
        NodeSpec::of(Field, crate::stages::field::quaternion_field::NODE),
        c.field.solid_field(c.parameterize.margin),
        (mesh, curves_file),
        |_, p, (mesh, file)| {
            // A curves file's curves come after the config's, and are checked on reading.
            let more = match file {
                None => Vec::new(),
                Some(f) => sketch::CurvesFile::read(&f.bytes, p.curves.len())
                    .map_err(|e| NodeError::input(format!("{}: {e}", f.path.display())))?,
            };
            sketch::solid_rotation_field(&mesh, p, more).map_err(NodeError::input)
        },
    );
    let regions = (!depths.is_empty()).then_some(depths);
    let request = dag.node(
        NodeSpec::of(
            Parameterize,
            crate::stages::parameterize::volume_embedding::NODE,
        ),
        WithTail(c.parameterize.clone(), regions.clone()),
        mesh,
        |_, WithTail(p, depths), mesh| {
            let depths = depths.as_deref().unwrap_or_default();
            volume::request_voxels(&mesh, p, depths).map_err(NodeError::input)
        },
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
    let reconstruct = dag.node(
        NodeSpec::of(Reconstruct, crate::stages::reconstruct::solid_colour::NODE),
        ReconstructParams {
            export: c.reconstruct.clone(),
            request: c.parameterize.request.clone(),
        },
        // The core's samples and analysis, the request and mesh, then each region's pair.
        (samples, core_analysis, request, mesh, pairs),
        |ctx, ReconstructParams { export, request }, (samples, analysis, req, mesh, pairs)| {
            let mut colours = colour::VoxelColours::default();
            for (s, a) in std::iter::once((samples, analysis)).chain(pairs) {
                colours.add(s.voxels, s.triples, &a);
            }
            let output = colour::SolidOutput::of(request, &mesh, req.section.as_ref(), req.voxels)
                .ok_or_else(|| NodeError::internal("section request without its grid"))?;
            let progress = |f| ctx.progress.set(f);
            let files = colour::export_solid(output, &req.volume, &colours, export, &progress);
            Ok(Bundle::from(files.map_err(NodeError::input)?))
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
    Ok(dag.node(
        NodeSpec::of(
            AnalyseExemplar,
            crate::stages::analyse_exemplar::candidate_triples::NODE,
        )
        .named(name),
        AnalysisParams {
            analysis: params,
            transpose: [tx, ty, tz],
        },
        [xy, yz, zx],
        |_, p, planes| {
            triples::analyse_transposed(planes, p.transpose, &p.analysis).map_err(NodeError::input)
        },
    ))
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
                return Err(ctx.shard_done(&synthesize_share(&synth, &voxels, &bricks, mode)?));
            }
            let run = synth.synthesize_voxels(&voxels, &bricks);
            let run = run.map_err(|e| NodeError::classify(e, SolidError::is_internal));
            Ok(SolidSamples::new(voxels, run?.0))
        },
    )
}

/// One shard's share of a solid synthesis (`texsyn run --shard`, `src/pipeline/shard.rs`).
#[derive(Serialize)]
struct BrickShare {
    /// The finest bricks of the whole request, over all shards.
    finest_bricks: usize,
    /// This shard's finest bricks, sorted.
    assigned: Vec<[i32; 3]>,
    /// Bricks needed, computed and reused per level, coarsest first (planning: what a run
    /// would compute with the cache as it is).
    levels: Vec<synthesis::LevelReport>,
    /// Planning only: the bricks per level the share depends on, all computed from an empty
    /// cache (what a shard on its own machine, sharing nothing, computes).
    #[serde(skip_serializing_if = "Option::is_none")]
    from_empty_cache: Option<Vec<usize>>,
}

/// Synthesizes (or, planning, plans) this shard's finest bricks among those `voxels` touch
/// and the coarser bricks they depend on, into `store`.
fn synthesize_share(
    synth: &synthesis::SolidSynthesis,
    voxels: &[[i32; 3]],
    store: &dyn BrickStore,
    mode: ShardMode,
) -> Result<BrickShare, NodeError> {
    let all = synth.request_bricks(&VoxelRequest::from_voxels(voxels));
    let assigned = shard::assign(&all, mode.shard);
    let mine: std::collections::HashSet<[i32; 3]> = assigned.iter().copied().collect();
    let share: Vec<[i32; 3]> = voxels
        .iter()
        .filter(|v| mine.contains(&synth.brick_of(**v)))
        .copied()
        .collect();
    let request = VoxelRequest::from_voxels(&share);
    let (levels, from_empty_cache) = if mode.plan_only {
        let fresh = synth.bricks_needed(&request).iter().map(Vec::len).collect();
        (synth.plan_report(&request, store), Some(fresh))
    } else {
        let report = synth.synthesize(&request, store);
        let report = report.map_err(|e| NodeError::classify(e, SolidError::is_internal))?;
        (report.levels, None)
    };
    Ok(BrickShare {
        finest_bricks: all.len(),
        assigned,
        levels,
        from_empty_cache,
    })
}

/// The synthesis' bricks are its node's pieces, by (level, brick coordinates).
impl BrickStore for PieceStore<'_, (u32, [i32; 3]), Brick> {
    fn get(&self, level: u32, brick: [i32; 3]) -> Option<Arc<Brick>> {
        PieceStore::get(self, &(level, brick))
    }
    fn put(&self, level: u32, brick: [i32; 3], b: Arc<Brick>) {
        PieceStore::put(self, &(level, brick), b)
    }
    /// The level's bricks are in the cache: only the copies in memory go.
    fn release(&self, level: u32) {
        self.forget(|(l, _)| *l == level)
    }
}

/// The analysis node's key: its parameters and which planes' images are transposed.
#[derive(Serialize)]
struct AnalysisParams {
    analysis: triples::CandidateParams,
    transpose: [bool; 3],
}

/// The reconstruct node's key: the export settings and the kind of request it renders.
#[derive(Serialize)]
struct ReconstructParams {
    export: SolidExportParams,
    request: volume::Request,
}
