//! The local executor: a sweep's points run side by side on this machine, each as its own
//! `texsyn run` process (the same binary), under one worker budget.
//!
//! `workers` processes run at once, each with `threads` rayon threads, so that workers ×
//! threads is the machine's cores (or `-j`). Points share nodes through the cache: the jump map
//! of a seed sweep is computed by the first point that needs it, while the others wait for it
//! on its key's lock and then read it (the cache's per-key locks). A process per point, rather
//! than a thread, gives each point its own peak memory and its own failure, and is exactly
//! what a Slurm task runs, so the two executors' tables agree.

use super::table::Failures;
use super::{CommonArgs, Point, Sweep, SweepDir, point_command};
use std::path::Path;
use std::process::{Command, Stdio};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};

/// One process to run: a point, or one shard of it.
#[derive(Debug, Clone)]
pub struct Task<'a> {
    pub point: &'a Point,
    pub shard: Option<(u32, u32)>,
}

/// Called as each task ends: the task, its outcome, its seconds.
pub type OnTaskDone<'a> = dyn Fn(&Task, &Result<(), String>, f64) + Sync + 'a;

/// Runs `tasks` with `workers` processes at once; calls `done` as each finishes (in
/// completion order) with its outcome. Returns the failures by point index.
pub fn run_tasks(
    exe: &Path,
    sweep: &Sweep,
    dir: &SweepDir,
    tasks: &[Task],
    workers: usize,
    common: &CommonArgs,
    done: &OnTaskDone,
) -> Failures {
    let next = AtomicUsize::new(0);
    let failures = Mutex::new(Failures::new());
    std::thread::scope(|s| {
        for _ in 0..workers.max(1).min(tasks.len().max(1)) {
            s.spawn(|| {
                loop {
                    let i = next.fetch_add(1, Ordering::Relaxed);
                    let Some(task) = tasks.get(i) else { break };
                    let start = std::time::Instant::now();
                    let outcome = run_one(exe, sweep, dir, task, common);
                    done(task, &outcome, start.elapsed().as_secs_f64());
                    if let Err(e) = outcome {
                        failures
                            .lock()
                            .unwrap_or_else(|e| e.into_inner())
                            .entry(task.point.index)
                            .or_insert(e);
                    }
                }
            });
        }
    });
    failures.into_inner().unwrap_or_else(|e| e.into_inner())
}

/// Runs one task's process, its stdout and stderr into its log.
fn run_one(
    exe: &Path,
    sweep: &Sweep,
    dir: &SweepDir,
    task: &Task,
    common: &CommonArgs,
) -> Result<(), String> {
    let point = task.point;
    let log = match task.shard {
        Some((i, _)) => dir.shard_log(point, i),
        None => dir.log(point),
    };
    let report = match task.shard {
        Some((i, _)) => dir.shard_report(point, i),
        None => dir.report(point),
    };
    for d in [log.parent(), report.parent()].into_iter().flatten() {
        std::fs::create_dir_all(d).map_err(|e| format!("creating {}: {e}", d.display()))?;
    }
    // A stale report of an earlier run must not pass for this one's.
    let _ = std::fs::remove_file(&report);
    let file = std::fs::File::create(&log).map_err(|e| format!("{}: {e}", log.display()))?;
    let err = file
        .try_clone()
        .map_err(|e| format!("{}: {e}", log.display()))?;
    let argv = point_command(exe, sweep, dir, point, task.shard, common);
    let status = Command::new(&argv[0])
        .args(&argv[1..])
        .stdin(Stdio::null())
        .stdout(file)
        .stderr(err)
        .status()
        .map_err(|e| format!("starting {}: {e}", argv[0].to_string_lossy()))?;
    if status.success() && report.is_file() {
        return Ok(());
    }
    Err(format!(
        "{} ({}; log: {})",
        last_error(&log).unwrap_or_else(|| "no error message".into()),
        match status.code() {
            Some(c) => format!("exit status {c}"),
            None => "killed by a signal".into(),
        },
        log.display()
    ))
}

/// The last `error:` line of a log, without its prefix.
pub fn last_error(log: &Path) -> Option<String> {
    let text = std::fs::read_to_string(log).ok()?;
    text.lines()
        .rev()
        .find_map(|l| l.strip_prefix("error: "))
        .map(str::to_owned)
}
