//! `texsyn report CONFIG|SWEEP`: one self-contained HTML page of a run or of a sweep
//! ([`texsyn::report`]). For a config it runs it first, as `run` does (nothing to do when it
//! is cached), so the page always shows the config as it is now.

use super::Globals;
use super::run::{Outcome, run_and_write};
use anyhow::{Context, Result};
use std::path::{Path, PathBuf};
use std::time::Instant;
use texsyn::ops::lockfile::{Difference, LockFile};
use texsyn::ops::sweep::{Sweep, SweepDir};
use texsyn::report::{LockStatus, Reload, RunView, run_page, sweep_page};

#[derive(clap::Args)]
pub struct ReportArgs {
    /// A config (runs it, computing what is not cached) or a sweep file (reads the sweep's
    /// folder as `texsyn sweep` left it).
    config: PathBuf,
    /// Override a config value, as `run --set` (configs only).
    #[arg(long = "set", value_name = "STAGE.KEY=VALUE")]
    sets: Vec<String>,
    /// The run's output folder (default: out/<config name>), or the sweep's folder (default:
    /// out/<sweep name>).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Where to write the page. Default: report.html in the output folder.
    #[arg(short = 'o', long = "output", value_name = "FILE.html")]
    output: Option<PathBuf>,
}

/// `texsyn report`.
pub fn report(args: &ReportArgs, g: &Globals) -> Result<i32> {
    let start = Instant::now();
    let (html, default) = if Sweep::is_sweep_file(&args.config) {
        if !args.sets.is_empty() {
            anyhow::bail!(
                "{}: --set applies to a config; a sweep's page shows its points as `texsyn \
                 sweep` ran them (change the sweep file instead)",
                args.config.display()
            );
        }
        let sweep = Sweep::load_saying(&args.config, true)?;
        let root = match &args.out {
            Some(out) => out.clone(),
            None => sweep.default_out()?,
        };
        let html = sweep_page(&sweep, &SweepDir::new(&root), None);
        (html, root.join("report.html"))
    } else {
        let o = run_and_write(&args.config, &args.sets, args.out.as_deref(), false, g)?;
        let html = run_html(&args.config, &args.sets, &o, None)?;
        (html, o.out_dir.join("report.html"))
    };
    let file = args.output.clone().unwrap_or(default);
    super::write_atomic(&file, html.as_bytes())
        .with_context(|| format!("writing the report {}", file.display()))?;
    if !g.quiet && !g.json {
        println!(
            "report: {} ({}) in {:.3} s",
            file.display(),
            texsyn::memory::human(html.len() as u64),
            start.elapsed().as_secs_f64()
        );
    }
    Ok(0)
}

/// The page of a run that `run_and_write` made; `reload`: the URL the page polls to reload
/// itself (`watch --serve`).
pub fn run_html(
    config: &Path,
    sets: &[String],
    o: &Outcome,
    reload: Option<Reload<'_>>,
) -> Result<String> {
    let config_text =
        std::fs::read_to_string(config).with_context(|| format!("reading {}", config.display()))?;
    let view = RunView {
        config,
        config_text: &config_text,
        method: &o.plan.method,
        sets,
        dag: &o.plan.dag,
        reports: &o.result.reports,
        out_dir: &o.out_dir,
        outputs: &o.written,
        scores: o.scores.as_ref().map(texsyn::score::report_text),
        lock: lock_status(config, sets, o),
        seconds: o.seconds,
        peak_memory_bytes: texsyn::memory::peak_resident(),
        reload,
        up: texsyn::config::Config::load(config, sets)
            .ok()
            .and_then(|c| texsyn::report::preview_up(&c)),
    };
    Ok(run_page(&view))
}

/// Whether `NAME.lock` beside the config verifies this run (when it was made with the same
/// overrides).
fn lock_status(config: &Path, sets: &[String], o: &Outcome) -> LockStatus {
    let path = config.with_extension("lock");
    if !path.is_file() {
        return LockStatus::Missing(path);
    }
    let lock = match LockFile::read(&path) {
        Ok(l) => l,
        Err(e) => {
            return LockStatus::Unreadable {
                path,
                error: e.to_string(),
            };
        }
    };
    if lock.sets != sets {
        return LockStatus::OtherOverrides {
            path,
            sets: lock.sets,
        };
    }
    let now = LockFile::of_reports(&o.result.reports, sets);
    let diffs = lock.compare(&now);
    if diffs.is_empty() {
        return LockStatus::Verifies {
            path,
            entries: lock.entries.len(),
        };
    }
    let lines = diffs
        .iter()
        .map(|d| match d {
            Difference::NotProduced { node } => format!("{node}: in the lock, not in this run"),
            Difference::NotLocked { node } => format!("{node}: not in the lock"),
            Difference::KeyChanged { node, locked, now } => {
                format!("{node}: key {} in the lock, {} now", locked.key, now.key)
            }
            Difference::ContentChangedUnderSameKey { node, locked, now } => {
                format!("{node}: same key, content {locked} in the lock, {now} now")
            }
        })
        .collect();
    LockStatus::Differs { path, lines }
}
