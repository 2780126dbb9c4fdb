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
pub mod plan_memo;
pub mod solid;
pub mod synth2d;

mod checks;
mod import;
mod plan;

pub use crate::score::Planned;
pub(crate) use checks::{
    AutoMesh, check_atlas_memory, check_memory, check_solid_memory, check_variant_memory,
    exemplar_size, resolve_scale,
};
pub use import::{Import, import};
pub(crate) use import::{Imports, input};
pub use plan::{Plan, plan};

use crate::config::{Config, ConfigError};
use crate::pipeline::Dag;
use std::path::PathBuf;
use std::sync::RwLock;

/// One published method.
pub trait Method: Send + Sync + 'static {
    /// The name a config gives it (`method = "…"`).
    fn name(&self) -> &'static str;
    /// Parses and validates the config's sections (the config comes without `[score]`),
    /// refuses parameters over the memory budget, and wires the DAG.
    fn plan(&self, config: &Config) -> Result<(Dag, Box<dyn Planned>), MethodError>;
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
