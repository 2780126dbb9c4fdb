//! Methods: each expands its config into a DAG of pipeline nodes (DESIGN.md, "A run").
//!
//! A method is one type implementing [`Method`]: the name configs give it, its config schema
//! (one serde struct per section, parsed and validated once, in [`Method::plan`]) and the DAG
//! it wires from the stages' nodes. What it keeps for after the run, the typed handles of the
//! nodes its score reads, is its [`Planned`]. Every caller (the CLI, score, sweeps, packs, the
//! benchmarks and tests) finds methods through the registry here ([`find`], [`plan`]); a
//! library user adds one with [`register`].

pub mod feature_aligned;
pub mod geometry_images;
pub mod graph_matching;
pub mod jump_maps;
pub mod solid;
pub mod synth2d;

use crate::artifact::Format;
use crate::config::{Config, ConfigError};
use crate::pipeline::{Dag, Handle, NodeError, NodeSpec, RunResult, Stage};
use crate::score::{Item, Report, ScoreFailure, ScoreSection};
use std::path::{Path, PathBuf};
use std::sync::RwLock;

/// One published method.
pub trait Method: Send + Sync + 'static {
    /// The name a config gives it (`method = "…"`).
    fn name(&self) -> &'static str;
    /// Parses and validates the config's sections (the config comes without `[score]`),
    /// refuses parameters over the memory budget, and wires the DAG.
    fn plan(&self, config: &Config) -> Result<(Dag, Box<dyn Planned>), MethodError>;
}

/// What a planned method keeps for after its run.
pub trait Planned: Send + Sync {
    /// Scores the run's results against their exemplars (README, "Scoring"), reading the
    /// nodes it kept handles to. An output with no exemplar-aligned image goes to
    /// `not_scored` with the reason.
    fn score(
        &self,
        run: &crate::score::Run<'_>,
        not_scored: &mut Vec<String>,
    ) -> Result<Vec<Item>, ScoreFailure>;

    /// For a run with nothing to score as it is (a solid's surface request): the `--set`
    /// that asks for a scoreable variant, which `texsyn score` runs and scores instead.
    fn score_substitute(&self, _result: &RunResult) -> Option<String> {
        None
    }
}

/// The methods texsyn ships.
static BUILT_IN: [&dyn Method; 6] = [
    &jump_maps::JumpMaps,
    &synth2d::Synth2d,
    &geometry_images::GeometryImages,
    &solid::Solid,
    &graph_matching::GraphMatchingMethod,
    &feature_aligned::FeatureAligned,
];

/// Methods added at run time by a library user.
static REGISTERED: RwLock<Vec<&'static dyn Method>> = RwLock::new(Vec::new());

/// Adds a method that configs can then name; a name already taken is refused.
pub fn register(method: &'static dyn Method) -> Result<(), MethodError> {
    let mut registered = REGISTERED.write().unwrap_or_else(|e| e.into_inner());
    if BUILT_IN
        .iter()
        .chain(registered.iter())
        .any(|m| m.name() == method.name())
    {
        return Err(MethodError::Taken(method.name()));
    }
    registered.push(method);
    Ok(())
}

/// The method a config names.
pub fn find(name: &str) -> Option<&'static dyn Method> {
    let registered = REGISTERED.read().unwrap_or_else(|e| e.into_inner());
    BUILT_IN
        .iter()
        .chain(registered.iter())
        .find(|m| m.name() == name)
        .copied()
}

/// The names of every method, built in first.
pub fn names() -> Vec<&'static str> {
    let registered = REGISTERED.read().unwrap_or_else(|e| e.into_inner());
    BUILT_IN
        .iter()
        .chain(registered.iter())
        .map(|m| m.name())
        .collect()
}

#[derive(Debug, thiserror::Error)]
pub enum MethodError {
    #[error(transparent)]
    Config(#[from] ConfigError),
    #[error("{0}")]
    Input(#[from] std::io::Error),
    #[error("{path}: method {method:?} is not implemented (known: {known})")]
    UnknownMethod {
        path: PathBuf,
        method: String,
        known: String,
    },
    #[error("a method named {0:?} is registered already")]
    Taken(&'static str),
}

/// A config turned into work: the DAG, and what the method keeps for after the run.
pub struct Plan {
    pub dag: Dag,
    /// The config's `method`.
    pub method: String,
    /// The config's `[score]` section, when it has one (validated).
    pub score: Option<ScoreSection>,
    /// The config the method planned from (without `[score]`).
    config: Config,
    planned: Box<dyn Planned>,
}

impl Plan {
    /// Default output directory (`out/<config stem>`), used unless `--out` is given; an error
    /// naming the config when its stem is not a plain folder name ([`crate::config::default_out`]).
    pub fn default_out(&self) -> Result<PathBuf, crate::config::ConfigError> {
        crate::config::default_out(&self.config.path, &self.config.stem)
    }

    /// Scores a run of this plan (its `result`) with `section`'s parameters.
    pub fn score_run(
        &self,
        result: &RunResult,
        section: &ScoreSection,
    ) -> Result<Report, ScoreFailure> {
        crate::score::report(&self.config, &self.method, section, |params, not_scored| {
            let run = crate::score::Run {
                config: &self.config,
                result,
                params: *params,
            };
            self.planned.score(&run, not_scored)
        })
    }

    /// See [`Planned::score_substitute`].
    pub fn score_substitute(&self, result: &RunResult) -> Option<String> {
        self.planned.score_substitute(result)
    }

    /// Whether some of its work can be split among machines (`--shard`).
    pub fn splits_into_shards(&self) -> bool {
        self.dag.nodes.iter().any(|n| n.splits_into_shards())
    }
}

pub fn plan(config: &Config) -> Result<Plan, MethodError> {
    let name = config.method()?.to_owned();
    // `[score]` reads the run's artifacts after it and never reaches a node, so it is taken
    // out before the method parses its sections (and adding it changes no key).
    let score = ScoreSection::from_config(config)?;
    let mut without_score = config.clone();
    without_score.table.remove("score");
    let method = find(&name).ok_or_else(|| MethodError::UnknownMethod {
        path: config.path.clone(),
        method: name.clone(),
        known: names().join(", "),
    })?;
    let (dag, planned) = method.plan(&without_score)?;
    Ok(Plan {
        dag,
        method: name,
        score,
        config: without_score,
        planned,
    })
}

/// A format that an input file is read into by an `import` node.
pub trait Import: Format + Sized {
    /// The reader's name (the node's algorithm, part of its key).
    const READER: &'static str;
    /// Bump when the reader's output for the same bytes changes.
    const VERSION: u32;
    fn read(path: &Path, bytes: &[u8]) -> Result<Self, Box<dyn std::error::Error + Send + Sync>>;
}

impl Import for crate::geom::Mesh {
    const READER: &'static str = "mesh_reader";
    const VERSION: u32 = 1;
    fn read(path: &Path, bytes: &[u8]) -> Result<Self, Box<dyn std::error::Error + Send + Sync>> {
        let mesh = crate::geom::io::read_mesh_bytes(path, bytes)?;
        // Past this, edge lengths and areas overflow f32 and every method's numbers turn to
        // infinities and zeros; no real model needs it (a light-year in millimetres is 1e19).
        const MAX_COORDINATE: f32 = 1e15;
        if let Some((v, p)) = mesh
            .positions
            .iter()
            .enumerate()
            .find(|(_, p)| p.abs().max_element() > MAX_COORDINATE)
        {
            return Err(format!(
                "{}: vertex {v} is at {p}: coordinates beyond ±{MAX_COORDINATE:e} overflow the geometry; scale the mesh down",
                path.display()
            )
            .into());
        }
        Ok(mesh)
    }
}

impl Import for crate::image::Image {
    const READER: &'static str = "image_reader";
    const VERSION: u32 = 1;
    fn read(path: &Path, bytes: &[u8]) -> Result<Self, Box<dyn std::error::Error + Send + Sync>> {
        Ok(crate::image::decode_image(path, bytes)?)
    }
}

/// The import node's parameters: the file's format, taken from its extension. It is part of
/// the key because the same bytes read as another format mean something else.
#[derive(serde::Serialize)]
struct ImportParams {
    format: String,
}

pub(super) fn extension(path: &Path) -> String {
    path.extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default()
}

/// Adds the node that parses and validates an input file. `role` is the config key that
/// named it, for errors.
pub fn import<F: Import>(
    dag: &mut Dag,
    name: &str,
    path: &Path,
    role: &str,
) -> Result<Handle<F>, MethodError> {
    let file = dag.file(path, role)?;
    let params = ImportParams {
        format: extension(path),
    };
    Ok(dag.node(
        NodeSpec::new(Stage::Import, F::READER, F::VERSION).named(name),
        params,
        file,
        |_, _, f| F::read(&f.path, &f.bytes).map_err(NodeError::Input),
    ))
}

/// Input files of one kind that several nodes use: each path is imported once, the first as
/// `name`, the next ones as `name.1`, `name.2`, … (in the order they are first asked for).
pub(crate) struct Imports<F> {
    name: &'static str,
    done: Vec<(PathBuf, Handle<F>)>,
}

impl<F: Import> Imports<F> {
    pub(crate) fn new(name: &'static str) -> Self {
        Imports {
            name,
            done: Vec::new(),
        }
    }

    /// The import of `path`; `role` is the config key that names it, for errors.
    pub(crate) fn get(
        &mut self,
        dag: &mut Dag,
        path: &Path,
        role: &str,
    ) -> Result<Handle<F>, MethodError> {
        if let Some((_, h)) = self.done.iter().find(|(p, _)| p == path) {
            return Ok(*h);
        }
        let name = match self.done.len() {
            0 => self.name.to_string(),
            n => format!("{}.{n}", self.name),
        };
        let h = import::<F>(dag, &name, path, role)?;
        self.done.push((path.to_owned(), h));
        Ok(h)
    }
}

/// Refuses, before any work, a parameter whose estimated memory is over the budget
/// (`--max-memory`), naming a value that fits. `estimate` gives bytes for a value; it must
/// grow with the value.
pub(crate) fn check_memory(
    config: &Config,
    key: &str,
    value: u64,
    estimate: impl Fn(u64) -> u64,
    show: impl Fn(u64) -> String,
) -> Result<(), MethodError> {
    crate::memory::check_budget(key, value, estimate, show)
        .map_err(|e| MethodError::Config(config.invalid(key, &e.to_string())))
}

/// The texel variants of a geometry-image sample of `extract.size`² texels
/// ([`TexelVariantParams::memory_estimate`]).
///
/// [`TexelVariantParams::memory_estimate`]: crate::stages::analyse_exemplar::texel_variants::TexelVariantParams::memory_estimate
pub(crate) fn check_variant_memory(
    config: &Config,
    size: u32,
    p: &crate::stages::analyse_exemplar::texel_variants::TexelVariantParams,
    per_texel: bool,
) -> Result<(), MethodError> {
    check_memory(
        config,
        "extract.size",
        size as u64,
        |s| p.memory_estimate(s, per_texel),
        |s| s.to_string(),
    )
}

/// A solid of `parameterize.resolution` voxels on its longest side
/// ([`crate::stages::synthesize::solid::memory_estimate`]).
pub(crate) fn check_solid_memory(
    config: &Config,
    resolution: u32,
    request: &crate::stages::parameterize::volume_embedding::Request,
) -> Result<(), MethodError> {
    check_memory(
        config,
        "parameterize.resolution",
        resolution as u64,
        |r| crate::stages::synthesize::solid::memory_estimate(request, r),
        |r| r.to_string(),
    )
}

/// The baked atlas of `reconstruct.atlas_size` texels per side
/// ([`crate::stages::reconstruct::textured_export::atlas_memory_estimate`]).
pub(crate) fn check_atlas_memory(config: &Config, side: u32) -> Result<(), MethodError> {
    check_memory(
        config,
        "reconstruct.atlas_size",
        side as u64,
        crate::stages::reconstruct::textured_export::atlas_memory_estimate,
        |a| a.to_string(),
    )
}
