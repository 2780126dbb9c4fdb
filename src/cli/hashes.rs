//! `texsyn hashes`: the lock file of a config (one line per artifact: node, key, content hash,
//! and the `--set` overrides), computing what is missing; printed, or written with `-o`
//! unless it would change a line's content under an unchanged key. Given a sweep file, the
//! sweep's lock: every point's lines.

use super::{Globals, run_config, write_atomic};
use anyhow::{Context, Result, bail};
use std::path::{Path, PathBuf};
use texsyn::ops::lockfile::LockFile;
use texsyn::ops::sweep::Sweep;
use texsyn::pipeline::ProgressMode;

#[derive(clap::Args)]
pub struct HashesArgs {
    config: PathBuf,
    #[arg(long = "set", value_name = "STAGE.KEY=VALUE")]
    sets: Vec<String>,
    /// Write the lock file here (atomically) instead of printing it. An existing lock whose
    /// line for a node has the same key but another content hash (a code change without
    /// a version bump) is not overwritten unless `--accept-unbumped` is given.
    #[arg(short, long, value_name = "LOCKFILE")]
    output: Option<PathBuf>,
    /// With `-o`: overwrite lines whose content changed under an unchanged key, and replace a
    /// file that is not a lock at all.
    #[arg(long, requires = "output")]
    accept_unbumped: bool,
}

/// `texsyn hashes`.
pub fn hashes(args: &HashesArgs, g: &Globals) -> Result<i32> {
    let HashesArgs {
        config,
        sets,
        output,
        accept_unbumped,
    } = args;
    if Sweep::is_sweep_file(config) {
        return sweep_hashes(config, sets, output.as_deref(), &g.cache_dir, g.progress);
    }
    let (_, result) = run_config(config, sets, &g.cache_dir, g.progress)?;
    let now = LockFile::of_reports(&result.reports, sets);
    match output {
        Some(output) => write_lock(output, &now, *accept_unbumped)?,
        None => print!("{}", now.to_text()),
    }
    Ok(0)
}

/// Writes the lock `now` to `output` (atomically). When `output` holds a lock already, each
/// of its lines whose content would change under an unchanged key is named on stderr, and
/// unless `accept_unbumped`, nothing is written and that is the error. A file there that does
/// not parse as a lock is replaced only with `accept_unbumped`.
fn write_lock(output: &Path, now: &LockFile, accept_unbumped: bool) -> Result<()> {
    if output.exists() {
        let old = match LockFile::read(output) {
            Ok(old) => old,
            // A malformed lock is replaced only when asked: the file might not be a lock at
            // all (a config named by mistake).
            Err(e) if accept_unbumped => {
                tracing::warn!(
                    "replacing {}, which is not a lock file: {e:#}",
                    output.display()
                );
                return write_atomic(output, now.to_text().as_bytes());
            }
            Err(e) => bail!(
                "{e:#}\n{} is not a lock file, so it was not overwritten; remove it, or pass \
                 --accept-unbumped to replace it",
                output.display()
            ),
        };
        let unbumped: Vec<_> = old
            .compare(now)
            .into_iter()
            .filter(|d| d.is_unbumped())
            .collect();
        for d in &unbumped {
            eprintln!("unbumped: {d}");
        }
        if !unbumped.is_empty() && !accept_unbumped {
            bail!(
                "{} line(s) of {} would change content under an unchanged key; bump the \
                 version of each node's algorithm (README, \"When to bump a version\"), \
                 or pass --accept-unbumped if the change is meant (the lock was not \
                 written)",
                unbumped.len(),
                output.display()
            );
        }
    }
    write_atomic(output, now.to_text().as_bytes())
}

/// `texsyn hashes SWEEP.toml`: every point's lines, computed in this process, as a sweep lock.
fn sweep_hashes(
    path: &Path,
    sets: &[String],
    output: Option<&Path>,
    cache_dir: &Path,
    progress: ProgressMode,
) -> Result<i32> {
    use texsyn::ops::sweep::lock::{PointLock, SweepLock};
    let sweep = Sweep::load(path)?;
    let mut lock = SweepLock::default();
    for p in &sweep.points {
        let point_sets: Vec<String> = p.sets.iter().chain(sets).cloned().collect();
        let (_, result) = run_config(&sweep.base, &point_sets, cache_dir, progress)
            .with_context(|| format!("point {} ({})", p.index, p.label()))?;
        lock.points.push(PointLock {
            index: p.index,
            label: p.label(),
            lock: LockFile::of_reports(&result.reports, &[]),
        });
    }
    let text = lock.to_text(path);
    match output {
        Some(o) => write_atomic(o, text.as_bytes())?,
        None => print!("{text}"),
    }
    Ok(0)
}
