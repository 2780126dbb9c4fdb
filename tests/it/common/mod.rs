//! Helpers shared by the integration tests (`mod common;` in each file that uses them).
#![allow(dead_code)] // each test file uses a different part of them

use std::path::Path;
use texsyn::artifact::Artifact;
use texsyn::cache::Cache;
use texsyn::config::Config;
use texsyn::methods::Plan;
use texsyn::pipeline::{self, NodeStatus, RunOptions, RunResult};

// Helpers the examples share with the tests: each file stands alone, so an example includes
// just the one it needs with `#[path = "../../tests/it/common/NAME.rs"] mod NAME;`.
mod exemplars;
#[allow(unused_imports)] // the files that use none of them
pub use exemplars::*;
pub mod cli;
pub mod cluster;
pub mod geometry_image;
pub mod geometry_texture;
pub mod jump_map;
pub mod solid;

/// Whether the full test tier runs: `TEXSYN_TEST_TIER=full` (README, "Tests"; `.ci/run` sets
/// it).
pub fn full_tier() -> bool {
    std::env::var_os("TEXSYN_TEST_TIER").is_some_and(|v| v == "full")
}

/// Says on stderr, past the test harness's capture so that it shows in `cargo test`'s output,
/// that the running test skipped its body because it belongs to the full tier.
pub fn say_skipped(why: &str) {
    use std::io::Write;
    let thread = std::thread::current();
    let name = thread.name().unwrap_or("a test");
    let _ = writeln!(
        std::io::stderr().lock(),
        "SKIPPED {name}: full tier ({why}); TEXSYN_TEST_TIER=full runs it"
    );
}

/// Installs the headless Chromium and playwright-core of the full tier's browser checks
/// (`scripts/browser install`, idempotent).
pub fn install_browser() {
    let status = std::process::Command::new(repo().join("scripts/browser"))
        .arg("install")
        .current_dir(repo())
        .status()
        .unwrap();
    assert!(status.success(), "scripts/browser install failed");
}

/// The first line of a full-tier test: outside the full tier it says so and returns.
#[macro_export]
macro_rules! full_tier_only {
    ($why:expr) => {
        if !$crate::common::full_tier() {
            $crate::common::say_skipped($why);
            return;
        }
    };
}

/// Loads `config` with the `base` settings and then `sets` (as `--set` would), and plans it
/// (nothing runs). Errors are the messages a user would see.
pub fn plan_config(config: &Path, base: &[&str], sets: &[&str]) -> Result<Plan, String> {
    let all: Vec<String> = base.iter().chain(sets).map(|s| s.to_string()).collect();
    let cfg = Config::load(config, &all).map_err(|e| e.to_string())?;
    texsyn::methods::plan(&cfg).map_err(|e| e.to_string())
}

/// Plans `config` as [`plan_config`] does and runs it in the cache at `cache`. Errors are the
/// messages a user would see.
pub fn run_config(
    config: &Path,
    base: &[&str],
    sets: &[&str],
    cache: &Path,
) -> Result<RunResult, String> {
    let plan = plan_config(config, base, sets)?;
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

/// Runs each `(config, sets, words)` case with `run` (given the config's name, its `--set`s
/// and a cache the cases share) and asserts that it fails with a message containing every one
/// of `words`.
pub fn assert_runs_fail_naming(
    run: impl Fn(&str, &[&str], &Path) -> Result<RunResult, String>,
    cases: &[(&str, &[&str], &[&str])],
) {
    let cache = tempfile::tempdir().unwrap();
    for (config, sets, words) in cases {
        let e = err(run(config, sets, cache.path()));
        assert!(
            words.iter().all(|w| e.contains(w)),
            "{config} {sets:?}: expected {words:?} in {e}"
        );
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

/// The files of `node`'s bundle, written into a new temporary directory.
pub fn materialized(r: &RunResult, node: &str) -> tempfile::TempDir {
    let out = tempfile::tempdir().unwrap();
    pipeline::outputs::materialize(artifact(r, node), out.path()).unwrap();
    out
}

/// "node content-hash" for every node, in order.
pub fn node_hashes(r: &RunResult) -> Vec<String> {
    r.reports
        .iter()
        .map(|n| format!("{} {}", n.node, n.content_hash))
        .collect()
}

/// The thread counts every method's results are compared across: one thread, and a pool
/// larger than the machine's two cores (3), which changes how rayon splits the work; the full
/// tier adds 8.
pub fn thread_counts() -> &'static [usize] {
    if full_tier() { &[1, 3, 8] } else { &[1, 3] }
}

/// Runs `run` from an empty cache in a pool of each of [`thread_counts`] and asserts that
/// every node's content hash is the same for all of them.
pub fn assert_same_hashes_on_any_thread_count(run: impl Fn(&Path) -> RunResult + Sync) {
    let counts = thread_counts();
    let hashes: Vec<_> = counts
        .iter()
        .map(|&threads| {
            let cache = tempfile::tempdir().unwrap();
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            node_hashes(&pool.install(|| run(cache.path())))
        })
        .collect();
    for (threads, h) in counts.iter().zip(&hashes).skip(1) {
        assert_eq!(
            &hashes[0], h,
            "{threads} threads give other artifacts than {}",
            counts[0]
        );
    }
}
