//! `texsyn verify`: checks a config's artifacts against a lock file written by `hashes`,
//! re-hashing every cached object (or recomputing everything in an empty cache with
//! `--fresh`); given a sweep file and its lock, every point against its section. The exit
//! status says whether all matched and whether damaged cache objects were found.

use super::{Globals, load_plan};
use anyhow::{Context, Result, bail};
use serde::Serialize;
use std::path::{Path, PathBuf};
use texsyn::cache::Cache;
use texsyn::ops::lockfile::{Difference, LockFile};
use texsyn::ops::sweep::Sweep;
use texsyn::pipeline::executor::Damage;
use texsyn::pipeline::{self, RunOptions, RunResult, outputs};

#[derive(clap::Args)]
pub struct VerifyArgs {
    config: PathBuf,
    lockfile: PathBuf,
    #[arg(long = "set", value_name = "STAGE.KEY=VALUE")]
    sets: Vec<String>,
    /// Recompute everything in an empty temporary cache instead of re-reading the cache.
    #[arg(long)]
    fresh: bool,
}

/// `verify`'s exit status when an artifact differs from the lock file.
const VERIFY_MISMATCH: i32 = 1;
/// `verify`'s exit status when every artifact matches but damaged cache objects were found
/// (and recomputed and replaced).
const VERIFY_DAMAGED: i32 = 3;

/// `texsyn verify`.
pub fn verify(args: &VerifyArgs, g: &Globals) -> Result<i32> {
    let VerifyArgs {
        config,
        lockfile,
        sets,
        fresh,
    } = args;
    if Sweep::is_sweep_file(config) {
        return sweep_verify(config, lockfile, sets, *fresh, g);
    }
    let text = texsyn::ops::lockfile::read_text(lockfile)?;
    if texsyn::ops::sweep::lock::SweepLock::is_sweep_lock(&text) {
        bail!(
            "{} is a sweep's lock, and {} is not a sweep: verify the sweep file with it",
            lockfile.display(),
            config.display()
        );
    }
    let lock = LockFile::parse(&text, lockfile)?;
    // The lock's recorded overrides first, so the command line's own win.
    let sets: Vec<String> = lock.sets.iter().chain(sets.iter()).cloned().collect();
    let plan = load_plan(config, &sets)?;
    let temp = fresh.then(|| outputs::TempDir::new("texsyn-verify"));
    let cache = verify_cache(temp.as_ref(), g)?;
    let result = rerun(&plan, &cache, g)?;
    let differences = lock.compare(&LockFile::of_reports(&result.reports, &sets));
    // Nodes whose content changed under an unchanged key (a missing version bump).
    let unbumped: Vec<String> = differences
        .iter()
        .filter_map(|d| match d {
            Difference::ContentChangedUnderSameKey { node, .. } => Some(node.clone()),
            _ => None,
        })
        .collect();
    let findings = Findings {
        lockfile,
        points: None,
        artifacts: result.reports.len(),
        mismatches: differences.iter().map(|d| d.to_string()).collect(),
        unbumped: Some(unbumped),
        damaged: result.damaged,
    };
    report_verify(&findings, g)
}

/// `texsyn verify SWEEP.toml SWEEP.lock`: every point against its section of the lock.
fn sweep_verify(
    path: &Path,
    lockfile: &Path,
    sets: &[String],
    fresh: bool,
    g: &Globals,
) -> Result<i32> {
    use texsyn::ops::sweep::lock::SweepLock;
    let sweep = Sweep::load(path)?;
    let lock = SweepLock::read(lockfile)?;
    let temp = fresh.then(|| outputs::TempDir::new("texsyn-verify"));
    let cache = verify_cache(temp.as_ref(), g)?;
    let mut problems = Vec::new();
    let mut damaged = Vec::new();
    let mut artifacts = 0;
    for p in &sweep.points {
        let section = match lock.section(p) {
            Ok(s) => s,
            Err(e) => {
                problems.push(e);
                continue;
            }
        };
        let point_sets: Vec<String> = p.sets.iter().chain(sets).cloned().collect();
        let plan = load_plan(&sweep.base, &point_sets)
            .with_context(|| format!("point {} ({})", p.index, p.label()))?;
        let result = rerun(&plan, &cache, g)?;
        artifacts += result.reports.len();
        for d in section
            .lock
            .compare(&LockFile::of_reports(&result.reports, &[]))
        {
            problems.push(format!("point {} ({}): {d}", p.index, p.label()));
        }
        damaged.extend(result.damaged);
    }
    for extra in lock
        .points
        .iter()
        .filter(|l| !sweep.points.iter().any(|p| p.index == l.index))
    {
        problems.push(format!(
            "point {} ({}) is in the lock file but not in the sweep",
            extra.index, extra.label
        ));
    }
    let findings = Findings {
        lockfile,
        points: Some(sweep.points.len()),
        artifacts,
        mismatches: problems,
        unbumped: None,
        damaged,
    };
    report_verify(&findings, g)
}

/// The cache to verify: the empty temporary one with `--fresh`, else the existing cache
/// (verifying a cache that is not there, a mistyped --cache, is an error, not a new cache).
fn verify_cache(temp: Option<&outputs::TempDir>, g: &Globals) -> Result<Cache> {
    Ok(match temp {
        Some(t) => Cache::open(t.path())?,
        None => Cache::open_existing(&g.cache_dir)?,
    })
}

/// Runs the plan, re-hashing every cached object it reads.
fn rerun(plan: &texsyn::methods::Plan, cache: &Cache, g: &Globals) -> Result<RunResult> {
    Ok(pipeline::run(
        &plan.dag,
        cache,
        RunOptions {
            progress: g.progress,
            verify_all: true,
            defer_export_checks: false,
        },
    )?)
}

/// What a verify found against a lock file: a config's artifacts, or those of every point
/// of a sweep. Serialized, it is the `--json` report without the exit status.
#[derive(Serialize)]
struct Findings<'a> {
    lockfile: &'a Path,
    /// A sweep's number of points; none for a config.
    #[serde(skip_serializing_if = "Option::is_none")]
    points: Option<usize>,
    /// Artifacts compared with the lock.
    artifacts: usize,
    /// Each difference from the lock, as text.
    mismatches: Vec<String>,
    /// A config's nodes whose content changed under an unchanged key (a missing version
    /// bump); a sweep's report has none.
    #[serde(skip_serializing_if = "Option::is_none")]
    unbumped: Option<Vec<String>>,
    /// Damaged cache objects met, each recomputed and replaced.
    damaged: Vec<Damage>,
}

/// Chooses `verify`'s exit status (0, [`VERIFY_MISMATCH`] or [`VERIFY_DAMAGED`]) and reports
/// the findings: the `--json` report on stdout, each damaged object and mismatch on stderr,
/// then one closing line.
fn report_verify(findings: &Findings, g: &Globals) -> Result<i32> {
    let Findings {
        lockfile,
        points,
        artifacts,
        mismatches,
        damaged,
        ..
    } = findings;
    let code = if !mismatches.is_empty() {
        VERIFY_MISMATCH
    } else if !damaged.is_empty() {
        VERIFY_DAMAGED
    } else {
        0
    };
    if g.json {
        let mut report = serde_json::to_value(findings)?;
        report["exit_code"] = serde_json::json!(code);
        super::print_json(&report)?;
    }
    print_verify_problems(damaged, mismatches, lockfile);
    match points {
        // A config: a damaged object recomputed to match is said on stderr.
        None => {
            if !mismatches.is_empty() {
                // Named above.
            } else if !damaged.is_empty() {
                eprintln!(
                    "{} damaged cache object(s), recomputed and replaced; all {artifacts} \
                     artifacts now match {}",
                    damaged.len(),
                    lockfile.display()
                );
            } else if !g.quiet && !g.json {
                println!(
                    "verified: {artifacts} artifacts match {}",
                    lockfile.display()
                );
            }
        }
        // A sweep: with no mismatch, the points and artifacts verified (the damaged objects
        // are named above).
        Some(points) => {
            if mismatches.is_empty() && !g.quiet && !g.json {
                println!(
                    "verified: {points} points, {artifacts} artifacts match {}",
                    lockfile.display()
                );
            }
        }
    }
    Ok(code)
}

/// `verify`'s report on stderr: each damaged object (already recomputed and replaced), each
/// mismatch, and how many mismatches there were.
fn print_verify_problems(damaged: &[Damage], problems: &[String], lockfile: &Path) {
    for d in damaged {
        eprintln!(
            "damaged: {}: {} ({}); recomputed and replaced",
            d.node,
            d.path.display(),
            d.problem
        );
    }
    for p in problems {
        eprintln!("mismatch: {p}");
    }
    if !problems.is_empty() {
        eprintln!(
            "{} mismatch(es) against {}",
            problems.len(),
            lockfile.display()
        );
    }
}
