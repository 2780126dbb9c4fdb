//! The sweep goals of BENCHMARKS.md (issue 13): the overhead a sweep adds per point, the local
//! executor's speedup with one worker per core, and a 100-point seed sweep of the demo with its jump
//! map computed once. Runs `texsyn sweep` as a user does (the running binary), in temporary
//! folders.

use super::{Row, median, verdict_below};
use anyhow::{Context, Result, bail};
use std::path::Path;
use std::time::Instant;
use texsyn::ops::sweep::{RunReport, Sweep, SweepDir};
use texsyn::pipeline::outputs::TempDir;

/// Writes a sweep of `base` with `axes` (TOML lines) into `dir`.
fn write_sweep(dir: &Path, base: &Path, workers: usize, axes: &str) -> Result<std::path::PathBuf> {
    let path = dir.join("bench.toml");
    let text = format!(
        "base = {:?}\nworkers = {workers}\n[axes]\n{axes}\n",
        base.to_string_lossy()
    );
    std::fs::write(&path, text).with_context(|| path.display().to_string())?;
    Ok(path)
}

/// Runs a sweep in a fresh cache; returns its wall seconds and the points' reports.
fn run_sweep(sweep: &Path, dir: &Path) -> Result<(f64, Vec<RunReport>)> {
    let exe = super::texsyn_exe()?;
    let start = Instant::now();
    let o = std::process::Command::new(&exe)
        .arg("sweep")
        .arg(sweep)
        .arg("--cache")
        .arg(dir.join("cache"))
        .arg("--out")
        .arg(dir.join("out"))
        .arg("-q")
        .output()
        .with_context(|| format!("running {}", exe.display()))?;
    let wall = start.elapsed().as_secs_f64();
    if !o.status.success() {
        bail!(
            "texsyn sweep {} failed: {}",
            sweep.display(),
            String::from_utf8_lossy(&o.stderr)
        );
    }
    let s = Sweep::load(sweep)?;
    let sd = SweepDir::new(&dir.join("out"));
    let reports = s
        .points
        .iter()
        .map(|p| RunReport::read(&sd.report(p)).context("a point's report is missing"))
        .collect::<Result<Vec<_>>>()?;
    Ok((wall, reports))
}

fn temp() -> Result<TempDir> {
    TempDir::create("texsyn-bench-sweep").map_err(|(p, e)| anyhow::anyhow!("{}: {e}", p.display()))
}

pub(crate) fn rows(repo: &Path, runs: usize, rows: &mut Vec<Row>) -> Result<()> {
    let cores = std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(1);
    // Overhead: 20 tiny points one at a time; what the sweep's wall time holds beyond the
    // points' own run time (process start, checking every point, the table and the lock).
    let synth = repo.join("configs/synth2d.toml");
    let axes = "\"synthesize.width\" = [64]\n\"synthesize.height\" = [64]\n\"synthesize.seed\" = { from = 1, to = 20, steps = 20 }";
    let mut overheads = Vec::new();
    for _ in 0..runs {
        let t = temp()?;
        let sweep = write_sweep(t.path(), &synth, 1, axes)?;
        let (wall, reports) = run_sweep(&sweep, t.path())?;
        let own: f64 = reports.iter().map(|r| r.seconds).sum();
        overheads.push((wall - own) / reports.len() as f64);
    }
    let overhead = median(overheads);
    rows.push(Row {
        what: "sweep: overhead per point beyond its own run (20 points of a 64² synth2d, one at a time)".into(),
        measured: format!("{:.1} ms", overhead * 1e3),
        goal: "< 50 ms".into(),
        verdict: verdict_below(overhead, 0.05),
    });

    // Speedup: 6 seeds of the demo (its reconstruct is mostly sequential), with one worker
    // holding every core, then one worker per core. The jump map is computed once either way.
    let demo = repo.join("configs/demo.toml");
    let axes = "\"synthesize.seed\" = { from = 1, to = 6, steps = 6 }";
    let mut times = [Vec::new(), Vec::new()];
    for _ in 0..runs.min(3) {
        for (k, workers) in [1, cores.max(2)].into_iter().enumerate() {
            let t = temp()?;
            let sweep = write_sweep(t.path(), &demo, workers, axes)?;
            times[k].push(run_sweep(&sweep, t.path())?.0);
        }
    }
    let (one, many) = (median(times[0].clone()), median(times[1].clone()));
    rows.push(Row {
        what: format!(
            "sweep: 6 seeds of configs/demo.toml, 1 worker × {cores} threads vs {} workers × 1 thread",
            cores.max(2)
        ),
        measured: format!("{one:.2} s vs {many:.2} s: speedup {:.2}×", one / many),
        goal: "faster with one worker per core".into(),
        verdict: if many < one {
            "met".into()
        } else {
            "missed".into()
        },
    });

    // The demo's seed sweep: 100 points, once (minutes); the jump map must be computed once.
    if std::env::var("TEXSYN_BENCH_SWEEP_POINTS").as_deref() != Ok("0") {
        let points: usize = std::env::var("TEXSYN_BENCH_SWEEP_POINTS")
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or(100);
        let t = temp()?;
        let axes = format!("\"synthesize.seed\" = {{ from = 1, to = {points}, steps = {points} }}");
        let sweep = write_sweep(t.path(), &repo.join("configs/demo.toml"), cores, &axes)?;
        let (wall, reports) = run_sweep(&sweep, t.path())?;
        let ran = |node: &str| {
            reports
                .iter()
                .filter(|r| r.nodes.iter().any(|n| n.node == node && n.status == "ran"))
                .count()
        };
        let jump_maps = ran("analyse_exemplar");
        rows.push(Row {
            what: format!(
                "sweep: {points}-point seed sweep of configs/demo.toml, {cores} workers (one run)"
            ),
            measured: format!(
                "{wall:.1} s ({:.2} s per point); jump map computed {jump_maps}×, synthesize {}×",
                wall / points as f64,
                ran("synthesize")
            ),
            goal: "jump map computed once".into(),
            verdict: if jump_maps == 1 {
                "met".into()
            } else {
                format!("missed: computed {jump_maps}×")
            },
        });
    }
    Ok(())
}
