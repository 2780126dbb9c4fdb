//! Issue 15's first goal: jump maps end to end on a 1.4M-triangle mesh (refined_elephant.off
//! subdivided twice, written as ASCII OFF) in under 10 s cold, file to all outputs. Runs
//! `texsyn run` as a user does (the running binary) in a fresh cache, so the import, every node
//! and the writing of the outputs are counted; the run report gives the per-node seconds and
//! peak memory.

use super::{Row, median, subdivide, verdict_below};
use anyhow::{Context, Result, bail};
use std::io::Write;
use std::path::Path;
use std::time::Instant;
use texsyn::geom::Mesh;
use texsyn::ops::sweep::RunReport;
use texsyn::pipeline::outputs::TempDir;

/// ASCII OFF, as a modelling tool writes it (shortest round-trip decimals).
pub(crate) fn write_off(m: &Mesh, path: &Path) -> Result<()> {
    let mut out = std::io::BufWriter::new(
        std::fs::File::create(path).with_context(|| path.display().to_string())?,
    );
    writeln!(out, "OFF\n{} {} 0", m.positions.len(), m.triangles.len())?;
    for p in &m.positions {
        writeln!(out, "{} {} {}", p.x, p.y, p.z)?;
    }
    for t in &m.triangles {
        writeln!(out, "3 {} {} {}", t[0], t[1], t[2])?;
    }
    out.flush()?;
    Ok(())
}

/// The config of the big run: the demo's exemplar and settings with the automatic scale (a
/// user's first try on their own scan).
fn config(mesh: &Path, exemplar: &Path) -> String {
    format!(
        "method = \"jump_maps\"\n[inputs]\nmesh = {:?}\nexemplar = {:?}\n\
         [synthesize]\nseed = 1\n[reconstruct]\npreview_size = 512\n",
        mesh.to_string_lossy(),
        exemplar.to_string_lossy()
    )
}

pub(crate) fn rows(repo: &Path, data: &Path, runs: usize, rows: &mut Vec<Row>) -> Result<()> {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let dir = TempDir::create("texsyn-bench-big-jump-maps")
        .map_err(|(p, e)| anyhow::anyhow!("{}: {e}", p.display()))?;
    // TEXSYN_BENCH_KEEP=DIR keeps the mesh, config and outputs there (to look at the pages).
    let keep = std::env::var_os("TEXSYN_BENCH_KEEP").map(std::path::PathBuf::from);
    let dir_path = match &keep {
        Some(k) => {
            std::fs::create_dir_all(k).with_context(|| k.display().to_string())?;
            k.clone()
        }
        None => dir.path().to_path_buf(),
    };
    let src = data.join("meshes/refined_elephant.off");
    let mesh = texsyn::geom::io::read_mesh(&src).with_context(|| src.display().to_string())?;
    let big = subdivide(&subdivide(&mesh));
    let off = dir_path.join("elephant_x16.off");
    write_off(&big, &off)?;
    let file_mb = std::fs::metadata(&off)?.len() as f64 / 1e6;
    let cfg = dir_path.join("big.toml");
    std::fs::write(&cfg, config(&off, &repo.join("configs/assets/wood1.png")))?;
    let exe = super::texsyn_exe()?;
    let mut walls = Vec::new();
    let mut last = None;
    for k in 0..runs {
        let run_dir = dir_path.join(format!("run{k}"));
        let report = run_dir.join("report.json");
        let start = Instant::now();
        let o = std::process::Command::new(&exe)
            .arg("run")
            .arg(&cfg)
            .arg("--cache")
            .arg(run_dir.join("cache"))
            .arg("--out")
            .arg(run_dir.join("out"))
            .arg("--report")
            .arg(&report)
            .arg("-q")
            .output()
            .with_context(|| format!("running {}", exe.display()))?;
        walls.push(start.elapsed().as_secs_f64());
        if !o.status.success() {
            bail!(
                "texsyn run on the 1.4M-triangle elephant failed: {}",
                String::from_utf8_lossy(&o.stderr)
            );
        }
        last = Some((
            RunReport::read(&report).context("the run wrote no report")?,
            run_dir,
        ));
    }
    let wall = median(walls);
    let (report, run_dir) = last.expect("at least one run");
    let nodes: Vec<String> = report
        .nodes
        .iter()
        .map(|n| format!("{} {:.2} s", n.node, n.seconds))
        .collect();
    let pages = std::fs::read_dir(run_dir.join("out"))?
        .filter_map(|e| e.ok())
        .filter(|e| {
            let name = e.file_name().to_string_lossy().into_owned();
            name.starts_with("baked_basecolor") && name.ends_with(".png")
        })
        .count();
    rows.push(Row {
        what: format!(
            "jump maps end to end, cold: refined_elephant.off subdivided twice ({} vertices, {} triangles, {file_mb:.0} MB ASCII OFF), wood1.png, automatic scale; {cores} cores",
            big.positions.len(),
            big.triangles.len()
        ),
        measured: format!(
            "{wall:.2} s wall (median of {runs}), peak {:.0} MB, {pages} atlas page(s); {}",
            report.peak_memory_bytes.unwrap_or(0) as f64 / 1e6,
            nodes.join(", ")
        ),
        goal: "< 10 s".into(),
        verdict: verdict_below(wall, 10.0),
    });
    Ok(())
}
