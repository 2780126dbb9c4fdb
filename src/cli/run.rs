//! `texsyn run`: runs a config, computing what is not cached, and writes its outputs (all of
//! them or none) and, when asked, its scores and its JSON report. With `--shard i/N`, computes
//! only that shard's bricks of a `solid` run into the cache and writes no outputs.

use super::{
    Globals, load_plan, load_shardable_plan, print_json, print_shard, run_plan_with, score_plan,
    write_atomic,
};
use anyhow::{Context, Result};
use std::path::{Path, PathBuf};
use std::time::Instant;
use texsyn::cache::Cache;
use texsyn::pipeline::outputs::{OutputCheck, OutputError};
use texsyn::pipeline::{self, RunOptions, RunResult, Shard, ShardResult, outputs};

#[derive(clap::Args)]
pub struct RunArgs {
    config: PathBuf,
    /// Override a config value: --set synthesize.seed=2 (repeatable).
    #[arg(long = "set", value_name = "STAGE.KEY=VALUE")]
    sets: Vec<String>,
    /// Output directory. Default: out/<config name>.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Also write the `--json` report to this file (atomically): what a sweep's table is
    /// made from.
    #[arg(long, value_name = "FILE")]
    report: Option<PathBuf>,
    /// Compute only shard i of N of a `solid` run (counting from 0): its share of the
    /// finest bricks and the coarser bricks they depend on, into the cache; no outputs
    /// are written. A later run without --shard (the gather) assembles the outputs from
    /// the cached bricks (README, "Sharded solid runs").
    #[arg(long, value_name = "i/N", conflicts_with = "out")]
    shard: Option<String>,
    /// Read and hash every output file and re-hash the exported bundles, instead of trusting
    /// the files whose size, times and inode are the ones recorded when they were written
    /// (README, "Set up and run").
    #[arg(long)]
    recheck: bool,
}

/// `texsyn run`.
pub fn run(args: &RunArgs, g: &Globals) -> Result<i32> {
    match &args.shard {
        Some(shard) => run_shard(args, shard, g),
        None => run_whole(args, g),
    }
}

/// `texsyn run --shard i/N`: the shard's bricks into the cache, no outputs.
fn run_shard(args: &RunArgs, shard: &str, g: &Globals) -> Result<i32> {
    let start = Instant::now();
    let shard: Shard = shard.parse()?;
    let plan = load_shardable_plan(&args.config, &args.sets)?;
    let cache = Cache::open(&g.cache_dir)?;
    let opts = RunOptions {
        progress: g.progress,
        verify_all: false,
        defer_export_checks: false,
    };
    let result = pipeline::run_shard(&plan.dag, &cache, opts, shard, false)?;
    let seconds = start.elapsed().as_secs_f64();
    let report = shard_report(&result, seconds, &args.sets, shard)?;
    if let Some(f) = &args.report {
        write_report(f, &report)?;
    }
    if g.json {
        print_json(&report)?;
    } else if !g.quiet {
        print_table(&result.nodes);
        print_shard(&result, &args.config, false);
        println!("no outputs written (shard {shard}) in {seconds:.3} s");
    }
    Ok(0)
}

/// What a whole run did: the plan, the run, the outputs (and whether each was written),
/// the scores when the config asks for them, and the time it took.
pub struct Outcome {
    pub plan: texsyn::methods::Plan,
    pub result: RunResult,
    pub out_dir: PathBuf,
    pub written: Vec<(PathBuf, bool)>,
    pub scores: Option<texsyn::score::Report>,
    pub seconds: f64,
}

/// Runs `config` with `sets`, writes its outputs into `out` (default: out/<config name>) and
/// scores it when the config asks. `recheck`: read every output back and re-hash the
/// exported bundles instead of trusting the recorded stats.
pub fn run_and_write(
    config: &Path,
    sets: &[String],
    out: Option<&Path>,
    recheck: bool,
    g: &Globals,
) -> Result<Outcome> {
    let start = Instant::now();
    if !recheck {
        // `--recheck` trusts nothing remembered, as it trusts no output's stat.
        texsyn::methods::plan_memo::remember_in(
            g.cache_dir.join(texsyn::methods::plan_memo::MEMOS),
        );
    }
    let plan = load_plan(config, sets)?;
    let out_dir = match out {
        Some(out) => out.to_owned(),
        None => plan.default_out()?,
    };
    // A swap a killed run left half done is finished (or undone) before anything else.
    outputs::recover(&out_dir).context("recovering the output directory")?;
    let scored = plan.score.as_ref().is_some_and(|s| s.enabled);
    // Scoring reads the bundles' payloads: hand them out checked then.
    let defer = !recheck && !scored;
    let options = |defer_export_checks| RunOptions {
        progress: g.progress,
        verify_all: false,
        defer_export_checks,
    };
    let check = if recheck {
        OutputCheck::Rehash
    } else {
        OutputCheck::Stamps(g.cache_dir.join(texsyn::pipeline::stamps::RECORDS))
    };
    let mut result = run_plan_with(&plan, &g.cache_dir, options(defer))?;
    // One run's exports are written as one set: all of them, or none on an error.
    let mut written =
        outputs::materialize_exports(&plan.dag, &result.artifacts, &out_dir, check.clone());
    if defer && matches!(written, Err(OutputError::Bundle(_))) {
        // A cached bundle handed out unchecked was damaged and nothing was written: the
        // checked run finds it, recomputes and replaces it.
        result = run_plan_with(&plan, &g.cache_dir, options(false))?;
        written =
            outputs::materialize_exports(&plan.dag, &result.artifacts, &out_dir, check.clone());
    }
    let written = written.with_context(|| {
        format!(
            "writing the outputs into {} (it still holds the previous run's outputs)",
            out_dir.display()
        )
    })?;
    // Scores when the config asks for them (`[score]`, enabled).
    let scores = match plan.score.as_ref().filter(|s| s.enabled) {
        Some(section) => Some(score_plan(config, &plan, &result, section)?),
        None => None,
    };
    Ok(Outcome {
        plan,
        result,
        out_dir,
        written,
        scores,
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// `texsyn run` without `--shard`: the whole run, its outputs and (when the config asks)
/// its scores.
fn run_whole(args: &RunArgs, g: &Globals) -> Result<i32> {
    let o = run_and_write(
        &args.config,
        &args.sets,
        args.out.as_deref(),
        args.recheck,
        g,
    )?;
    let report = run_report(
        &o.result,
        &o.written,
        o.scores.as_ref(),
        o.seconds,
        &args.sets,
    )?;
    if let Some(f) = &args.report {
        write_report(f, &report)?;
    }
    if g.json {
        print_json(&report)?;
    } else if !g.quiet {
        print_table(&o.result.reports);
        if let Some(s) = &o.scores {
            print!("{}", texsyn::score::report_text(s));
        }
        let changed = o.written.iter().filter(|w| w.1).count();
        println!(
            "outputs: {} ({} written, {} unchanged) in {:.3} s",
            o.out_dir.display(),
            changed,
            o.written.len() - changed,
            o.seconds
        );
    }
    Ok(0)
}

/// A run's `--json` report (and `--report` file): its nodes, the outputs and whether each
/// was written, the cache's warnings, the time, the peak memory, the overrides and, when
/// scored, the scores.
fn run_report(
    result: &RunResult,
    written: &[(PathBuf, bool)],
    scores: Option<&texsyn::score::Report>,
    seconds: f64,
    sets: &[String],
) -> Result<serde_json::Value> {
    let outputs: Vec<_> = written
        .iter()
        .map(|(p, w)| serde_json::json!({ "path": p, "written": w }))
        .collect();
    let mut report = serde_json::json!({
        "nodes": result.reports,
        "outputs": outputs,
        "warnings": result.warnings,
        "seconds": seconds,
        "peak_memory_bytes": texsyn::memory::peak_resident(),
        "sets": sets,
    });
    if let Some(s) = scores {
        report["scores"] = serde_json::to_value(s)?;
    }
    Ok(report)
}

/// A shard's `--json` report (and `--report` file): what the shard did, no outputs, the
/// time, the peak memory, the overrides and which shard it was.
fn shard_report(
    result: &ShardResult,
    seconds: f64,
    sets: &[String],
    shard: Shard,
) -> Result<serde_json::Value> {
    let mut report = serde_json::to_value(result)?;
    report["outputs"] = serde_json::json!([]);
    report["seconds"] = serde_json::json!(seconds);
    report["peak_memory_bytes"] = serde_json::json!(texsyn::memory::peak_resident());
    report["sets"] = serde_json::json!(sets);
    report["shard"] = serde_json::json!(shard.to_string());
    Ok(report)
}

/// Writes the report to the `--report` file (atomically).
fn write_report(file: &Path, report: &serde_json::Value) -> Result<()> {
    write_atomic(file, serde_json::to_string_pretty(report)?.as_bytes())
}

/// The node table: each node's stage, whether it ran or was cached, its seconds and size,
/// and, when a node caches pieces (the solid's bricks), how many were computed and reused.
pub fn print_table(reports: &[pipeline::NodeReport]) {
    let pieces = reports.iter().any(|r| r.pieces.is_some());
    println!(
        "{:<24} {:<17} {:<7} {:>9} {:>11}{}",
        "node",
        "stage",
        "status",
        "seconds",
        "bytes",
        if pieces {
            "  pieces computed / reused"
        } else {
            ""
        }
    );
    for r in reports {
        let status = match r.status {
            pipeline::NodeStatus::Cached => "cached",
            pipeline::NodeStatus::Ran => "ran",
        };
        let piece_counts = r
            .pieces
            .map(|p| format!("  {} / {}", p.computed, p.reused))
            .unwrap_or_default();
        println!(
            "{:<24} {:<17} {:<7} {:>9.3} {:>11}{piece_counts}",
            r.node,
            r.stage,
            status,
            r.seconds,
            texsyn::memory::human(r.bytes)
        );
    }
}
