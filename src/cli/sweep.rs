//! `texsyn sweep`: runs a sweep (a base config and axes over its values), one ordinary run
//! per point in its own folder, on one cache, side by side on this machine or as Slurm job
//! arrays; then writes the results table (OUT/results.csv, .md, .json) and, when every point
//! succeeded, the sweep's lock (OUT/sweep.lock). Points already done are not run again. With
//! `--status`, says what would run and runs nothing.

use super::{Globals, print_json, write_atomic};
use anyhow::{Context, Result, bail};
use std::path::PathBuf;
use std::time::Instant;
use texsyn::cache::{Cache, parse_size};
use texsyn::ops::slurm::{SlurmOptions, TaskOutcome, TaskStatus};
use texsyn::ops::sweep::table::{Failures, Table};
use texsyn::ops::sweep::{
    CommonArgs, Point, PointState, Sweep, SweepDir, local, lock::SweepLock, point_state,
    slurm_executor,
};

#[derive(clap::Args)]
pub struct SweepArgs {
    sweep: PathBuf,
    /// Say what would run, point by point, and run nothing (like `status`).
    #[arg(long)]
    status: bool,
    /// Where points run: `local` (processes side by side on this machine) or `slurm`
    /// (one job array; the cache must be on a filesystem the compute nodes see).
    #[arg(long, default_value = "local")]
    executor: String,
    /// Local executor: points run at once. Default: the sweep's `workers`, else one per
    /// core (at most the number of points); the cores are shared among them.
    #[arg(long)]
    workers: Option<usize>,
    /// The sweep's folder. Default: out/<sweep name>.
    #[arg(long)]
    out: Option<PathBuf>,
    #[command(flatten)]
    slurm: SlurmFlags,
}

/// `--executor slurm`'s options; each overrides the sweep's `[slurm]` value of that name.
#[derive(clap::Args, Debug, Default)]
struct SlurmFlags {
    /// Slurm partition.
    #[arg(long)]
    partition: Option<String>,
    /// Slurm time limit per task (e.g. 30, 1:00:00, 1-00:00).
    #[arg(long)]
    time: Option<String>,
    /// Slurm memory per task (e.g. 4G); also each task's memory budget (--max-memory).
    #[arg(long)]
    mem: Option<String>,
    /// Slurm CPUs per task; also each task's thread count.
    #[arg(long)]
    cpus_per_task: Option<u32>,
    /// Slurm account.
    #[arg(long)]
    account: Option<String>,
}

/// What either executor needs to run a sweep's points.
struct Launch<'a> {
    sweep: &'a Sweep,
    dir: &'a SweepDir,
    /// The texsyn binary each point runs.
    exe: PathBuf,
    /// The cache folder, absolute so that a task started anywhere finds it.
    cache: PathBuf,
    /// No progress lines (`--quiet` or `--json`).
    quiet: bool,
}

/// `texsyn sweep`: checks every point, says or runs what is not done, then writes the table
/// and the sweep's lock. Exit status 1 when a point failed.
pub fn sweep(args: &SweepArgs, g: &Globals) -> Result<i32> {
    let executor = args.executor.as_str();
    if !matches!(executor, "local" | "slurm") {
        bail!("--executor {executor:?}: expected `local` or `slurm`");
    }
    let sweep = Sweep::load_saying(&args.sweep, g.quiet || g.json)?;
    let out = match &args.out {
        Some(out) => out.clone(),
        None => sweep.default_out()?,
    };
    let dir = SweepDir::new(&out);
    let cache = Cache::open(&g.cache_dir)?;
    let mut states = Vec::new();
    for p in &sweep.points {
        states.push(point_state(&sweep, &dir, p, &cache)?);
    }
    let todo: Vec<&Point> = sweep
        .points
        .iter()
        .zip(&states)
        .filter(|(_, s)| **s != PointState::Done)
        .map(|(p, _)| p)
        .collect();
    if args.status {
        print_status(&sweep, &dir, &states, todo.len(), g)?;
        return Ok(0);
    }
    let launch = Launch {
        sweep: &sweep,
        dir: &dir,
        exe: std::env::current_exe().context("finding the texsyn binary")?,
        cache: std::path::absolute(&g.cache_dir).unwrap_or_else(|_| g.cache_dir.clone()),
        quiet: g.quiet || g.json,
    };
    let start = Instant::now();
    if !launch.quiet && todo.len() < sweep.points.len() {
        println!(
            "{} of {} points done already; running {}",
            sweep.points.len() - todo.len(),
            sweep.points.len(),
            todo.len()
        );
    }
    let failures = if executor == "slurm" {
        run_on_slurm(&launch, &cache, &args.slurm)?
    } else {
        run_locally(&launch, &todo, args.workers, g.jobs)
    };
    let table = write_results(&sweep, &dir, &failures)?;
    let failed: Vec<_> = table.failed().collect();
    if g.json {
        print_json(&table)?;
    } else if !g.quiet {
        println!(
            "{} points ({} run now) in {:.2} s; table: {}",
            sweep.points.len(),
            todo.len(),
            start.elapsed().as_secs_f64(),
            dir.root.join("results.md").display()
        );
    }
    if !failed.is_empty() {
        for r in &failed {
            eprintln!(
                "point {} failed: {}",
                r.index,
                r.error.as_deref().unwrap_or("no report")
            );
        }
        eprintln!(
            "{} of {} points failed; rerun the sweep to run only those",
            failed.len(),
            sweep.points.len()
        );
        return Ok(1);
    }
    Ok(0)
}

/// `texsyn sweep --status`: each point's state, then how many are to run.
fn print_status(
    sweep: &Sweep,
    dir: &SweepDir,
    states: &[PointState],
    todo: usize,
    g: &Globals,
) -> Result<()> {
    if g.json {
        let lines: Vec<_> = sweep
            .points
            .iter()
            .zip(states)
            .map(|(p, s)| {
                serde_json::json!({ "point": p.index, "values": p.label(), "out": dir.point_out(p), "status": s })
            })
            .collect();
        return print_json(&lines);
    }
    for (p, s) in sweep.points.iter().zip(states) {
        let what = match s {
            PointState::Done => "done".to_owned(),
            PointState::WouldRun { nodes } if nodes.is_empty() => {
                "would run (everything cached; writes its outputs)".to_owned()
            }
            PointState::WouldRun { nodes } => format!("would compute {}", nodes.join(", ")),
        };
        println!("{:>4}  {:<40} {what}", p.index, p.label());
    }
    println!(
        "{} of {} points to run, in {}",
        todo,
        sweep.points.len(),
        dir.root.display()
    );
    Ok(())
}

/// `--executor slurm`: waits for tasks an earlier `texsyn sweep` left in the queue, then
/// submits the points still not done as job arrays and waits for them. The failures, by
/// point.
fn run_on_slurm(l: &Launch, cache: &Cache, flags: &SlurmFlags) -> Result<Failures> {
    let (sweep, dir, quiet) = (l.sweep, l.dir, l.quiet);
    let opts = slurm_options(sweep, flags)?;
    let common = CommonArgs {
        cache: l.cache.clone(),
        threads: Some(opts.cpus_per_task.unwrap_or(1) as usize),
        // A task's budget is the job's memory, when the sweep says it.
        max_memory: opts.mem,
    };
    let list = slurm_executor::TaskList::new(&l.exe, sweep, dir, &common);
    let mut last = String::new();
    let mut progress = |s: &[TaskOutcome]| {
        if quiet {
            return;
        }
        let active = s
            .iter()
            .filter(|t| matches!(t.status, TaskStatus::Active(_)))
            .count();
        let ended = s
            .iter()
            .filter(|t| matches!(t.status, TaskStatus::Exited(_) | TaskStatus::Lost { .. }))
            .count();
        let line = format!("slurm: {active} tasks pending or running, {ended} ended");
        if line != last {
            println!("{line}");
            last = line;
        }
    };
    if slurm_executor::reattach(dir, &mut progress)? && !quiet {
        println!("re-attached to the tasks an earlier `texsyn sweep` left in the queue");
    }
    // What is still to do once those have ended.
    let mut todo = Vec::new();
    for p in &sweep.points {
        if point_state(sweep, dir, p, cache)? != PointState::Done {
            todo.push(p);
        }
    }
    if todo.is_empty() {
        return Ok(Default::default());
    }
    if !quiet {
        println!(
            "submitting {} points to Slurm ({} tasks); state in {}",
            todo.len(),
            todo.len() * list.per_point,
            slurm_executor::state_dir(dir).display()
        );
    }
    for p in &todo {
        dir.clear_reports(p, sweep.shards.unwrap_or(1));
    }
    Ok(slurm_executor::run(
        &list,
        dir,
        &todo,
        &l.cache,
        &opts,
        &mut progress,
    )?)
}

/// The sweep's `[slurm]` table with the command line's flags over it, checked.
fn slurm_options(sweep: &Sweep, flags: &SlurmFlags) -> Result<SlurmOptions> {
    use serde::Deserialize;
    let mut opts = match &sweep.slurm {
        Some(t) => SlurmOptions::deserialize(toml::Value::Table(t.clone())).map_err(|e| {
            anyhow::anyhow!(
                "{}: [slurm]: {}",
                sweep.path.display(),
                e.to_string().trim()
            )
        })?,
        None => Default::default(),
    };
    if let Some(p) = &flags.partition {
        opts.partition = Some(p.clone());
    }
    if let Some(t) = &flags.time {
        opts.time = Some(t.clone());
    }
    if let Some(m) = &flags.mem {
        opts.mem = Some(parse_size(m).map_err(|e| anyhow::anyhow!("--mem {m}: {e}"))?);
    }
    if let Some(c) = flags.cpus_per_task {
        opts.cpus_per_task = Some(c);
    }
    if let Some(a) = &flags.account {
        opts.account = Some(a.clone());
    }
    opts.check()?;
    Ok(opts)
}

/// `--executor local`: the points of `todo` as processes side by side on this machine,
/// `--workers` (else the sweep's `workers`, else one per core) at once, sharing the cores
/// (`-j`, else all) and the memory budget. A sharded sweep runs every point's shards first,
/// then the gather of each point whose shards all succeeded. The failures, by point.
fn run_locally(
    l: &Launch,
    todo: &[&Point],
    workers: Option<usize>,
    jobs: Option<usize>,
) -> Failures {
    let (sweep, dir, quiet) = (l.sweep, l.dir, l.quiet);
    let cores = jobs.unwrap_or_else(|| {
        std::thread::available_parallelism()
            .map(|n| n.get())
            .unwrap_or(1)
    });
    let shards = sweep.shards.unwrap_or(1).max(1);
    let width = if shards > 1 {
        todo.len() * shards as usize
    } else {
        todo.len()
    };
    let workers = workers
        .or(sweep.workers)
        .unwrap_or(cores)
        .clamp(1, width.max(1));
    let common = CommonArgs {
        cache: l.cache.clone(),
        threads: Some((cores / workers).max(1)),
        // One budget for the whole sweep, shared by the points running at once.
        max_memory: Some(texsyn::memory::budget() / workers as u64),
    };
    let finished = std::sync::atomic::AtomicUsize::new(0);
    let total = width + if shards > 1 { todo.len() } else { 0 };
    let report = |task: &local::Task, outcome: &Result<(), String>, seconds: f64| {
        let n = finished.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
        if quiet {
            return;
        }
        let what = match task.shard {
            Some((i, n)) => format!("shard {i}/{n} of point {}", task.point.index),
            None => format!("point {}", task.point.index),
        };
        match outcome {
            Ok(()) => println!(
                "[{n}/{total}] {what} ({}): done in {seconds:.2} s",
                task.point.label()
            ),
            Err(e) => eprintln!("[{n}/{total}] {what} ({}): failed: {e}", task.point.label()),
        }
    };
    for p in todo {
        dir.clear_reports(p, shards);
    }
    let mut failures = Failures::default();
    let mut ready: Vec<&Point> = todo.to_vec();
    if shards > 1 {
        // The shards of every point first, then each point whose shards all succeeded
        // gathers them.
        let tasks: Vec<local::Task> = todo
            .iter()
            .flat_map(|&point| {
                (0..shards).map(move |i| local::Task {
                    point,
                    shard: Some((i, shards)),
                })
            })
            .collect();
        failures = local::run_tasks(&l.exe, sweep, dir, &tasks, workers, &common, &report);
        ready.retain(|p| !failures.contains_key(&p.index));
    }
    let tasks: Vec<local::Task> = ready
        .iter()
        .map(|&point| local::Task { point, shard: None })
        .collect();
    failures.extend(local::run_tasks(
        &l.exe, sweep, dir, &tasks, workers, &common, &report,
    ));
    failures
}

/// Writes the results table (results.csv, .md and .json in the sweep's folder) and, when
/// every point succeeded, the sweep's lock (sweep.lock); after a failure an older lock would
/// mislead, so it is removed. Returns the table.
fn write_results(sweep: &Sweep, dir: &SweepDir, failures: &Failures) -> Result<Table> {
    let table = Table::collect(sweep, dir, failures);
    std::fs::create_dir_all(&dir.root)
        .with_context(|| format!("creating {}", dir.root.display()))?;
    write_atomic(&dir.root.join("results.csv"), table.to_csv().as_bytes())?;
    write_atomic(&dir.root.join("results.md"), table.to_markdown().as_bytes())?;
    write_atomic(
        &dir.root.join("results.json"),
        serde_json::to_string_pretty(&table)?.as_bytes(),
    )?;
    let lock = SweepLock::of_reports(sweep, dir).filter(|_| failures.is_empty());
    match &lock {
        Some(lock) => write_atomic(
            &dir.root.join("sweep.lock"),
            lock.to_text(&sweep.path).as_bytes(),
        )?,
        None => {
            let _ = std::fs::remove_file(dir.root.join("sweep.lock"));
        }
    }
    Ok(table)
}
