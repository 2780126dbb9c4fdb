//! Methods: each expands its config section into a DAG of pipeline nodes (DESIGN.md, "A run").

pub mod feature_aligned;
pub mod geometry_images;
pub mod graph_matching;
pub mod jump_maps;
pub mod solid;
pub mod synth2d;

use crate::artifact::Format;
use crate::config::{Config, ConfigError};
use crate::pipeline::{Dag, Handle, NodeError, NodeSpec, Stage};
use std::path::{Path, PathBuf};

/// The methods a config may name.
pub const METHODS: &[&str] = &[
    "jump_maps",
    "synth2d",
    "geometry_images",
    "solid",
    "graph_matching",
    "feature_aligned",
];

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
}

/// A config turned into work: the DAG and the nodes whose bundles are the run's outputs.
pub struct Plan {
    pub dag: Dag,
    /// The config's `method`.
    pub method: String,
    /// The config's `[score]` section, when it has one (validated).
    pub score: Option<crate::score::ScoreSection>,
    /// Default output directory (`out/<config stem>`), used unless `--out` is given.
    pub default_out: PathBuf,
}

pub fn plan(config: &Config) -> Result<Plan, MethodError> {
    let method = config.method()?.to_owned();
    // `[score]` reads the run's artifacts after it and never reaches a node, so it is taken
    // out before the method parses its sections (and adding it changes no key).
    let score = crate::score::ScoreSection::from_config(config)?;
    let config = &without_score(config);
    let dag = match method.as_str() {
        "jump_maps" => jump_maps::build(config)?,
        "synth2d" => synth2d::build(config)?,
        "geometry_images" => geometry_images::build(config)?,
        "solid" => solid::build(config)?,
        "graph_matching" => graph_matching::build(config)?,
        "feature_aligned" => feature_aligned::build(config)?,
        other => {
            return Err(MethodError::UnknownMethod {
                path: config.path.clone(),
                method: other.to_owned(),
                known: METHODS.join(", "),
            });
        }
    };
    Ok(Plan {
        dag,
        method,
        score,
        default_out: Path::new("out").join(&config.stem),
    })
}

/// The config without its `[score]` section: what a method parses.
pub fn without_score(config: &Config) -> Config {
    let mut c = config.clone();
    c.table.remove("score");
    c
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

/// The texel variants of a geometry-image sample of `extract.size`² texels (issue 11, item 9):
/// `orientations × scales` resampled copies, scale `j` steps from the middle holding `4^j`
/// times the sample's texels, with their pyramids, feature vectors and trees. Measured on
/// `configs/dragon_knot.toml` (a geometry-only sample; 8 orientations): peak 0.42 GB at
/// 128² with 3 scales, 1.62 GB at 128² with 5, 5.93 GB at 256² with 5; about 580 bytes per
/// texel of the unscaled variants' total. A sample with colour has twice the channels and up
/// to twice the need. Without the per-texel search structures (`per_texel` false, the default
/// k-coherence search) the variants are their pyramids' texels (12 bytes each, 16 with the
/// pyramid) and the resampling's copies: estimated at 40 bytes per texel.
pub(crate) fn check_variant_memory(
    config: &Config,
    size: u32,
    p: &crate::stages::analyse_exemplar::texel_variants::TexelVariantParams,
    per_texel: bool,
) -> Result<(), MethodError> {
    let mid = (p.scales as i32 - 1) / 2;
    let spread: f64 = (-mid..=mid).map(|j| 4f64.powi(j)).sum();
    let bytes = if per_texel { 580.0 } else { 40.0 };
    let per_texel = (bytes * p.orientations as f64 * spread) as u64;
    check_memory(
        config,
        "extract.size",
        size as u64,
        |s| per_texel * s * s + (64 << 20),
        |s| s.to_string(),
    )
}

/// A solid of `parameterize.resolution` voxels on its longest side (issue 11, item 9): the
/// volume's voxel masks and their prefix sums are dense over the volume's box (at most
/// `resolution³` voxels). A box request keeps its finest bricks (12 bytes a voxel) and needs
/// about 16 bytes per voxel of that cube bound and 180 MB besides (the exemplar analysis);
/// a section needs about half a byte per voxel and 48 MB (since its dependent sets are kept in
/// chunks with no per-voxel lists: 72 MB measured at 384, 163 MB before). Measured
/// (solid_trivial, elephant): surface 119 MB at 128, 272 MB at 256, 523 MB at 384. The elephant's box fills about half its cube, so the cube bound stays within 2× for
/// slim and cubic shapes alike.
///
/// A surface request synthesizes each level in batches whose working set is bounded
/// (`BatchLimits` in `solid_synthesis/plan.rs`: about 1.2 GiB with the resident bricks of two
/// levels) and keeps only the surface's bricks: the same 16 bytes per voxel while that is
/// smaller, never more than the batch bound, plus half a byte per voxel for the volume's
/// masks. Measured on the cow (issue 15): 529 MB at 512, and at 1024 2.77 GB before
/// batching, see BENCHMARKS.md for after.
pub(crate) fn check_solid_memory(
    config: &Config,
    resolution: u32,
    request: &crate::stages::parameterize::volume_embedding::Request,
) -> Result<(), MethodError> {
    use crate::stages::parameterize::volume_embedding::Request;
    let estimate: fn(u64) -> u64 = match request {
        Request::Section { .. } => |r| r * r * r / 2 + (48 << 20),
        Request::Box { .. } => |r| 16 * r * r * r + (180 << 20),
        Request::Surface => |r| (16 * r * r * r).min(1_200 << 20) + r * r * r / 2 + (180 << 20),
    };
    check_memory(
        config,
        "parameterize.resolution",
        resolution as u64,
        estimate,
        |r| r.to_string(),
    )
}

/// The baked atlas of `reconstruct.atlas_size` texels per side: about 9 bytes per texel
/// (the float image, its 8-bit copy and the PNG) and the mesh besides (measured: 152 MB at
/// 4096², 547 MB at 8192² for the demo).
pub(crate) fn check_atlas_memory(config: &Config, side: u32) -> Result<(), MethodError> {
    check_memory(
        config,
        "reconstruct.atlas_size",
        side as u64,
        |a| 9 * a * a + (48 << 20),
        |a| a.to_string(),
    )
}
