//! Helpers shared by the integration tests (`mod common;` in each file that uses them).
#![allow(dead_code)] // each test file uses a different part of them

use std::path::{Path, PathBuf};
use texsyn::artifact::Artifact;
use texsyn::cache::Cache;
use texsyn::config::Config;
use texsyn::image::{Image, decode_image};
use texsyn::pipeline::{self, NodeStatus, RunOptions, RunResult};

pub fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The path of an exemplar image in `tests/data/exemplars`.
pub fn exemplar_path(name: &str) -> PathBuf {
    repo().join("tests/data/exemplars").join(name)
}

/// An exemplar image of `tests/data/exemplars`, decoded.
pub fn load_exemplar(name: &str) -> Image {
    let path = exemplar_path(name);
    let bytes = std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    decode_image(&path, &bytes).unwrap()
}

/// Loads `config` with the `base` settings and then `sets` (as `--set` would), and runs it
/// in the cache at `cache`. Errors are the messages a user would see.
pub fn run_config(
    config: &Path,
    base: &[&str],
    sets: &[&str],
    cache: &Path,
) -> Result<RunResult, String> {
    let all: Vec<String> = base.iter().chain(sets).map(|s| s.to_string()).collect();
    let cfg = Config::load(config, &all).map_err(|e| e.to_string())?;
    let plan = texsyn::methods::plan(&cfg).map_err(|e| e.to_string())?;
    let cache = Cache::open(cache).unwrap();
    pipeline::run(&plan.dag, &cache, RunOptions::default()).map_err(|e| e.to_string())
}

/// The error of a run that must fail.
pub fn err(r: Result<RunResult, String>) -> String {
    match r {
        Ok(_) => panic!("expected an error"),
        Err(e) => e,
    }
}

/// The nodes that ran (rather than being found in the cache).
pub fn ran(r: &RunResult) -> Vec<&str> {
    r.reports
        .iter()
        .filter(|n| n.status == NodeStatus::Ran)
        .map(|n| n.node.as_str())
        .collect()
}

pub fn artifact<'a>(r: &'a RunResult, node: &str) -> &'a Artifact {
    let i = r.reports.iter().position(|n| n.node == node).unwrap();
    &r.artifacts[i]
}

/// "node content-hash" for every node, in order.
pub fn node_hashes(r: &RunResult) -> Vec<String> {
    r.reports
        .iter()
        .map(|n| format!("{} {}", n.node, n.content_hash))
        .collect()
}

/// The node hashes of `run` on one thread and on two, each from an empty cache.
pub fn hashes_on_one_and_two_threads(run: impl Fn(&Path) -> RunResult + Sync) -> [Vec<String>; 2] {
    [1, 2].map(|threads| {
        let cache = tempfile::tempdir().unwrap();
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        node_hashes(&pool.install(|| run(cache.path())))
    })
}
