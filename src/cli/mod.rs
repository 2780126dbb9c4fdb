//! The commands of the `texsyn` binary, one file each, and what several of them share:
//! the resolved global options, loading and running a config's plan, scoring a run, the
//! shard summary and atomic file writes.

pub mod gc;
pub mod graph;
pub mod hashes;
pub mod pack;
pub mod render;
pub mod report;
pub mod run;
pub mod score;
pub mod status;
pub mod sweep;
pub mod verify;
pub mod watch;

use anyhow::{Context, Result, bail};
use std::path::{Path, PathBuf};
use texsyn::cache::Cache;
use texsyn::config::Config;
use texsyn::methods::Plan;
use texsyn::pipeline::{self, ProgressMode, RunOptions, RunResult};

/// The global options every command reads, resolved from the command line and the
/// environment.
pub struct Globals {
    /// The cache directory (`--cache`, else $TEXSYN_CACHE, else ./cache).
    pub cache_dir: PathBuf,
    /// Progress bars, unless `--quiet` or `--json`.
    pub progress: ProgressMode,
    /// `--quiet`: print nothing but errors.
    pub quiet: bool,
    /// `--json`: machine-readable output on stdout.
    pub json: bool,
    /// `-j`: worker threads, when given.
    pub jobs: Option<usize>,
}

/// Loads `config` with the `--set` overrides and plans its DAG.
pub fn load_plan(config: &Path, sets: &[String]) -> Result<Plan> {
    let cfg = Config::load(config, sets)?;
    Ok(texsyn::methods::plan(&cfg)?)
}

/// [`load_plan`], for a run split into shards: only a config with a node that splits its
/// work into pieces (the `solid` method's synthesis) can be.
pub fn load_shardable_plan(config: &Path, sets: &[String]) -> Result<Plan> {
    let plan = load_plan(config, sets)?;
    if !plan.splits_into_shards() {
        bail!(
            "{}: --shard splits the bricks of a `solid` run among machines; method `{}` has no \
             work that can be split (run it without --shard)",
            config.display(),
            plan.method
        );
    }
    Ok(plan)
}

/// Plans `config` and runs it in the cache at `cache_dir`, computing what is not cached.
pub fn run_config(
    config: &Path,
    sets: &[String],
    cache_dir: &Path,
    progress: ProgressMode,
) -> Result<(Plan, RunResult)> {
    let plan = load_plan(config, sets)?;
    let result = run_plan(&plan, cache_dir, progress)?;
    Ok((plan, result))
}

/// Runs a planned DAG in the cache at `cache_dir`, computing what is not cached.
pub fn run_plan(plan: &Plan, cache_dir: &Path, progress: ProgressMode) -> Result<RunResult> {
    run_plan_with(
        plan,
        cache_dir,
        RunOptions {
            progress,
            ..RunOptions::default()
        },
    )
}

/// [`run_plan`] with every option given.
pub fn run_plan_with(plan: &Plan, cache_dir: &Path, opts: RunOptions) -> Result<RunResult> {
    let cache = Cache::open(cache_dir)?;
    Ok(pipeline::run(&plan.dag, &cache, opts)?)
}

/// Scores a run of `config` planned as `plan` (its method's score hook; `texsyn::score`).
pub fn score_plan(
    config: &Path,
    plan: &Plan,
    result: &RunResult,
    section: &texsyn::score::ScoreSection,
) -> Result<texsyn::score::Report> {
    plan.score_run(result, section)
        .with_context(|| format!("scoring {}", config.display()))
}

/// What a shard did (or, from `status`, would do), after the node table.
pub fn print_shard(result: &pipeline::ShardResult, config: &Path, planning: bool) {
    let shard = result.shard;
    if result.sharded.is_empty() {
        println!(
            "shard {shard}: the inputs of the synthesis are not all cached yet; the shard \
             computes them first, and its share of bricks is known then"
        );
    }
    for s in &result.sharded {
        let share = &s.share;
        let n = |k: &str| share[k].as_u64().unwrap_or(0);
        let assigned = share["assigned"].as_array().map_or(0, Vec::len);
        let levels = share["levels"].as_array().cloned().unwrap_or_default();
        let per_level = |k: &str| {
            levels
                .iter()
                .map(|l| l[k].as_u64().unwrap_or(0).to_string())
                .collect::<Vec<_>>()
                .join(" ")
        };
        println!(
            "{}: shard {shard}: {assigned} of {} finest bricks; bricks per level, coarsest \
             first: needed {}, {} {}, {} in the cache",
            s.node,
            n("finest_bricks"),
            per_level("bricks_needed"),
            if share["from_empty_cache"].is_null() {
                "computed"
            } else {
                "to compute"
            },
            per_level("bricks_computed"),
            per_level("bricks_reused"),
        );
        if let Some(fresh) = share["from_empty_cache"].as_array() {
            let fresh: Vec<String> = fresh.iter().map(|v| v.to_string()).collect();
            println!(
                "{}: shard {shard} from an empty cache: {} bricks per level",
                s.node,
                fresh.join(" ")
            );
        }
    }
    // Planning, the skipped nodes include those not cached yet (the table above says which).
    if !result.skipped.is_empty() && !planning {
        println!(
            "left to the gather run (`texsyn run {}` without --shard, after all {} shards): {}",
            config.display(),
            shard.count,
            result.skipped.join(", ")
        );
    }
}

/// Writes `bytes` to `path` through a temporary file beside it and a rename, creating the
/// folder: a reader sees the old file or the new one, never part of one. The temporaries
/// killed writers of `path` left are removed first ([`texsyn::owner::remove_stale_beside`]).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    texsyn::owner::remove_stale_beside(path);
    let tmp = texsyn::owner::temporary_beside(path);
    let written = std::fs::write(&tmp, bytes)
        .with_context(|| format!("writing {}", tmp.display()))
        .and_then(|()| {
            std::fs::rename(&tmp, path).with_context(|| format!("writing {}", path.display()))
        });
    if written.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    written
}

/// Prints `value` as pretty JSON on stdout (`--json`).
pub fn print_json(value: &impl serde::Serialize) -> Result<()> {
    println!("{}", serde_json::to_string_pretty(value)?);
    Ok(())
}
