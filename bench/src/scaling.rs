//! How cost grows with size (issue 15, item 5): every method run by `texsyn run` at three sizes,
//! each four times the last (vertices, voxels or texels), from an empty cache each time, with
//! each stage's wall time and peak memory from the run report and the exponent of a power law
//! fitted to them, so that a user can predict a bigger run: t(n) ≈ t(n₀)·(n/n₀)^exponent.
//!
//! `TEXSYN_BENCH_ONLY=scaling cargo run --release -p texsyn-bench` prints the section; `TEXSYN_BENCH_SCALING=solid,synth2d`
//! measures only the methods named.

use anyhow::{Context, Result, bail};
use std::path::{Path, PathBuf};
use texsyn::geom::Mesh;
use texsyn::ops::sweep::RunReport;
use texsyn::pipeline::outputs::TempDir;

/// The least-squares slope of log(value) against log(size): the exponent k of value ≈ c·size^k.
/// None with fewer than two points, a size or value that is not positive and finite, or sizes
/// all equal (no slope to fit).
pub fn power_law_exponent(sizes: &[f64], values: &[f64]) -> Option<f64> {
    if sizes.len() != values.len() || sizes.len() < 2 {
        return None;
    }
    let ok = |v: f64| v.is_finite() && v > 0.0;
    if !sizes.iter().chain(values).all(|&v| ok(v)) {
        return None;
    }
    use texsyn_core::math::PureMath;
    let x: Vec<f64> = sizes.iter().map(|s| s.ln_pure()).collect();
    let y: Vec<f64> = values.iter().map(|v| v.ln_pure()).collect();
    let n = x.len() as f64;
    let (mx, my) = (x.iter().sum::<f64>() / n, y.iter().sum::<f64>() / n);
    let sxx: f64 = x.iter().map(|a| (a - mx) * (a - mx)).sum();
    let sxy: f64 = x.iter().zip(&y).map(|(a, b)| (a - mx) * (b - my)).sum();
    // Sizes equal up to rounding give no slope.
    if sxx <= 1e-12 * x.iter().map(|a| a * a).sum::<f64>().max(1.0) {
        return None;
    }
    Some(sxy / sxx)
}

/// One run of a method: what to override, and the size it has.
struct Size {
    /// As the table shows it.
    label: String,
    /// Vertices, voxels or texels (or a quantity proportional to them).
    n: f64,
    sets: Vec<String>,
}

/// A method measured at three sizes.
struct Case {
    method: &'static str,
    config: &'static str,
    /// What `Size::n` counts.
    unit: String,
    sizes: Vec<Size>,
}

/// The same stages' measurements at each size.
struct Measured {
    case: Case,
    reports: Vec<RunReport>,
    load: Vec<String>,
}

fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .ok()
        .and_then(|s| s.split_whitespace().next().map(str::to_owned))
        .unwrap_or_else(|| "?".into())
}

/// `cow.obj` subdivided 1, 2 and 3 times (midpoint subdivision, the shape unchanged), written as
/// OBJ into `dir`: (path, vertices).
fn subdivided_cows(repo: &Path, dir: &Path) -> Result<Vec<(PathBuf, usize)>> {
    let p = repo.join("configs/assets/cow.obj");
    let mut mesh: Mesh = texsyn::geom::io::read_mesh_bytes(&p, &std::fs::read(&p)?)?;
    let mut out = Vec::new();
    for times in 1..=3 {
        mesh = super::subdivide(&mesh);
        let path = dir.join(format!("cow_subdivided_{times}.obj"));
        let text = texsyn::export::write_obj(&mesh, None, None, "cow");
        std::fs::write(&path, text).with_context(|| path.display().to_string())?;
        out.push((path, mesh.vertex_count()));
    }
    Ok(out)
}

fn cases(repo: &Path, dir: &Path, data: Option<&Path>) -> Result<Vec<Case>> {
    let mut cases = Vec::new();
    // Jump maps: the demo on ever finer cows; the per-triangle atlas grows with them (2× side).
    let cows = subdivided_cows(repo, dir)?;
    cases.push(Case {
        method: "jump_maps",
        config: "configs/demo.toml",
        unit: "vertices (cow.obj subdivided 1, 2, 3 times; atlas side 1024, 2048, 4096)".into(),
        sizes: cows
            .iter()
            .zip([1024, 2048, 4096])
            .map(|((path, v), atlas)| Size {
                label: format!("{v}"),
                n: *v as f64,
                sets: vec![
                    format!("inputs.mesh={}", toml_string(path)),
                    format!("reconstruct.atlas_size={atlas}"),
                ],
            })
            .collect(),
    });
    // Geometry images: the geometry image's side doubles (2^k + 1 samples).
    let (gi_mesh, gi_name) = match data.map(|d| d.join("meshes/refined_elephant.off")) {
        Some(p) if p.exists() => (Some(p), "refined_elephant.off"),
        _ => (None, "cow.obj"),
    };
    cases.push(Case {
        method: "geometry_images",
        config: "configs/relief_cow.toml",
        unit: format!("texels (geometry image of {gi_name}, side 257, 513, 1025)"),
        sizes: [257u32, 513, 1025]
            .iter()
            .map(|&s| Size {
                label: format!("{s}²"),
                n: (s as f64) * (s as f64),
                sets: gi_mesh
                    .iter()
                    .map(|p| format!("inputs.mesh={}", toml_string(p)))
                    .chain([format!("parameterize.size={s}")])
                    .collect(),
            })
            .collect(),
    });
    // Solid: the longest side grows by 4^(1/3), so the volume's voxels by 4.
    cases.push(Case {
        method: "solid",
        config: "configs/solid_trivial.toml",
        unit: "voxels of the volume's r³ cube (r = parameterize.resolution 96, 152, 242; the \
               surface request holds about r² of them)"
            .into(),
        sizes: [96u32, 152, 242]
            .iter()
            .map(|&r| Size {
                label: format!("r = {r}"),
                n: (r as f64).powi(3),
                sets: vec![format!("parameterize.resolution={r}")],
            })
            .collect(),
    });
    // Graph matching and feature-aligned: the hierarchy or refinement goes down to about a texel
    // per edge, so the finest mesh's vertices grow with scale².
    cases.push(Case {
        method: "graph_matching",
        config: "configs/graph_matching.toml",
        unit: "scale² (parameterize.scale 60, 120, 240; the finest level's vertices ∝ scale²)"
            .into(),
        sizes: scaled("parameterize.scale", &[60, 120, 240], &[]),
    });
    cases.push(Case {
        method: "feature_aligned",
        config: "configs/feature_aligned.toml",
        unit: "scale² (parameterize.scale 50, 100, 200, `compare = false`; the refined mesh's \
               vertices ∝ scale²)"
            .into(),
        sizes: scaled("parameterize.scale", &[50, 100, 200], &["compare=false"]),
    });
    cases.push(Case {
        method: "synth2d",
        config: "configs/synth2d.toml",
        unit: "texels (output side 512, 1024, 2048)".into(),
        sizes: [512u32, 1024, 2048]
            .iter()
            .map(|&s| Size {
                label: format!("{s}²"),
                n: (s as f64) * (s as f64),
                sets: vec![
                    format!("synthesize.width={s}"),
                    format!("synthesize.height={s}"),
                ],
            })
            .collect(),
    });
    Ok(cases)
}

fn scaled(key: &str, values: &[u32], extra: &[&str]) -> Vec<Size> {
    values
        .iter()
        .map(|&v| Size {
            label: format!("{v}"),
            n: (v as f64) * (v as f64),
            sets: [format!("{key}={v}")]
                .into_iter()
                .chain(extra.iter().map(|s| s.to_string()))
                .collect(),
        })
        .collect()
}

/// A path as a TOML string for `--set` (quoted, so that any character survives).
fn toml_string(p: &Path) -> String {
    toml::Value::String(p.to_string_lossy().into_owned()).to_string()
}

/// `texsyn run CONFIG --report … --set …` in a fresh cache; the report.
fn run_once(config: &str, sets: &[String]) -> Result<RunReport> {
    let tmp = TempDir::create("texsyn-bench-scaling")
        .map_err(|(p, e)| anyhow::anyhow!("{}: {e}", p.display()))?;
    let report = tmp.path().join("report.json");
    let mut cmd = super::texsyn_run(config, tmp.path(), &["--quiet"])?;
    cmd.arg("--report").arg(&report);
    for s in sets {
        cmd.arg("--set").arg(s);
    }
    let out = cmd.output().context("running texsyn")?;
    if !out.status.success() {
        bail!(
            "texsyn run {config} {} failed: {}",
            sets.join(" "),
            String::from_utf8_lossy(&out.stderr)
        );
    }
    RunReport::read(&report).with_context(|| format!("{}: no run report", report.display()))
}

fn selected(method: &str) -> bool {
    match std::env::var("TEXSYN_BENCH_SCALING") {
        Ok(list) if !list.trim().is_empty() => list.split(',').any(|m| m.trim() == method),
        _ => true,
    }
}

/// Times under this are mostly process noise: no exponent is fitted to a stage this short at
/// every size.
const SHORTEST_FITTED: f64 = 0.05;
/// Nor to one with a time under two ticks of the CPU clock (1/100 s) at any size.
const SHORTEST_POINT: f64 = 0.02;

fn fmt_exponent(k: Option<f64>) -> String {
    k.map(|k| format!("{k:.2}")).unwrap_or_else(|| "–".into())
}

fn mib(b: Option<u64>) -> String {
    b.map(|b| format!("{:.0}", b as f64 / (1024.0 * 1024.0)))
        .unwrap_or_else(|| "?".into())
}

/// Fitted exponent and last step of a series of seconds, when it is long enough to fit.
fn time_fit(sizes: &[f64], secs: &[Option<f64>]) -> (Option<f64>, String) {
    let all: Option<Vec<f64>> = secs.iter().copied().collect();
    let Some(s) = all.filter(|s| {
        s.iter().any(|&v| v >= SHORTEST_FITTED) && s.iter().all(|&v| v >= SHORTEST_POINT)
    }) else {
        return (None, "–".into());
    };
    let (a, b) = (s[s.len() - 2], s[s.len() - 1]);
    (power_law_exponent(sizes, &s), format!("{:.1}", b / a))
}

fn cells(v: &[Option<f64>], digits: usize) -> String {
    v.iter()
        .map(|s| {
            s.map(|s| format!("{s:.digits$}"))
                .unwrap_or_else(|| "?".into())
        })
        .collect::<Vec<_>>()
        .join(" | ")
}

/// One method's table: a row per stage and one for the whole run.
fn method_table(m: &Measured) -> String {
    let sizes: Vec<f64> = m.case.sizes.iter().map(|s| s.n).collect();
    let labels: Vec<&str> = m.case.sizes.iter().map(|s| s.label.as_str()).collect();
    let mut t = format!(
        "\n### {} (`{}`)\n\nSize: {}. Load average (1 min) at each run's start: {}.\n\n",
        m.case.method,
        m.case.config,
        m.case.unit,
        m.load.join(", ")
    );
    let heads = |what: &str| {
        labels
            .iter()
            .map(|l| format!("{what} @ {l}"))
            .collect::<Vec<_>>()
            .join(" | ")
    };
    t += &format!(
        "| stage | {} | {} | wall exponent | CPU exponent | CPU last step × | {} | memory exponent |\n|---|",
        heads("wall s"),
        heads("CPU s"),
        heads("MiB")
    );
    t += &"---:|".repeat(3 * labels.len() + 4);
    t += "\n";
    let row =
        |name: &str, wall: Vec<Option<f64>>, cpu: Vec<Option<f64>>, peaks: Vec<Option<u64>>| {
            let (k_wall, _) = time_fit(&sizes, &wall);
            let (k_cpu, step) = time_fit(&sizes, &cpu);
            let mem: Option<Vec<f64>> = peaks.iter().map(|p| p.map(|b| b as f64)).collect();
            let k_mem = mem.and_then(|m| power_law_exponent(&sizes, &m));
            format!(
                "| {name} | {} | {} | {} | {} | {step} | {} | {} |\n",
                cells(&wall, 2),
                cells(&cpu, 2),
                fmt_exponent(k_wall),
                fmt_exponent(k_cpu),
                peaks
                    .iter()
                    .map(|&p| mib(p))
                    .collect::<Vec<_>>()
                    .join(" | "),
                fmt_exponent(k_mem)
            )
        };
    // Stages in the first run's order (every run has the same DAG).
    for node in &m.reports[0].nodes {
        let per: Vec<_> = m
            .reports
            .iter()
            .map(|r| r.nodes.iter().find(|n| n.node == node.node))
            .collect();
        t += &row(
            &node.node,
            per.iter().map(|n| n.map(|n| n.seconds)).collect(),
            per.iter().map(|n| n.and_then(|n| n.cpu_seconds)).collect(),
            per.iter()
                .map(|n| n.and_then(|n| n.peak_memory_bytes))
                .collect(),
        );
    }
    t += &row(
        "**whole run** (wall; CPU of the stages; process peak)",
        m.reports.iter().map(|r| Some(r.seconds)).collect(),
        m.reports
            .iter()
            .map(|r| r.nodes.iter().map(|n| n.cpu_seconds).sum::<Option<f64>>())
            .collect(),
        m.reports.iter().map(|r| r.peak_memory_bytes).collect(),
    );
    t
}

/// The scaling section of BENCHMARKS.md.
pub fn section(repo: &Path, data: Option<&Path>) -> Result<String> {
    let dir = TempDir::create("texsyn-bench-scaling-meshes")
        .map_err(|(p, e)| anyhow::anyhow!("{}: {e}", p.display()))?;
    let started = std::time::Instant::now();
    let mut measured = Vec::new();
    for case in cases(repo, dir.path(), data)? {
        if !selected(case.method) {
            continue;
        }
        let mut reports = Vec::new();
        let mut load = Vec::new();
        for size in &case.sizes {
            load.push(load_average());
            eprintln!("scaling: {} at {}", case.method, size.label);
            reports.push(run_once(case.config, &size.sets)?);
        }
        measured.push(Measured {
            case,
            reports,
            load,
        });
    }
    let cores = std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(1);
    let mut s = String::from("\n## How cost grows with size (issue 15, item 5)\n\n");
    s += &format!(
        "`TEXSYN_BENCH_ONLY=scaling cargo run --release -p texsyn-bench` ({:.0} s in all here, {cores} \
cores shared with other jobs). Each method runs as `texsyn run CONFIG --report FILE --set …` at \
three sizes, each 4× the last, from an empty cache; the seconds and peak resident memory per stage \
are the run report's: wall seconds, CPU seconds of the whole process (all threads) while the stage \
ran, and the process's peak resident memory while it ran (so it includes what earlier stages left \
resident). On a shared machine the CPU seconds are the steadier measure of a stage's work. The \
exponent k is the least-squares slope of log time (or log memory) against log size: a run of size n \
takes about t(n₀)·(n/n₀)^k. \"CPU last step ×\" is the largest size's CPU seconds over the middle \
one's (4 for linear cost). No time exponent is fitted to stages under {SHORTEST_FITTED} s at every \
size or under {SHORTEST_POINT} s at any.\n",
        started.elapsed().as_secs_f64()
    );
    for m in &measured {
        s += &method_table(m);
    }
    Ok(s)
}

#[cfg(test)]
mod tests {
    use super::power_law_exponent;
    #[test]
    fn a_known_power_law_gives_its_exponent_back() {
        let sizes = [1e4, 4e4, 1.6e5];
        // (exponent, value = 3.7 · (size / 10⁴)^exponent computed without logarithms)
        type Law = fn(f64) -> f64;
        let laws: [(f64, Law); 5] = [
            (0.0, |_| 1.0),
            (0.5, |r| r.sqrt()),
            (1.0, |r| r),
            (1.5, |r| r * r.sqrt()),
            (2.0, |r| r * r),
        ];
        for (k, law) in laws {
            let values: Vec<f64> = sizes.iter().map(|&s| 3.7 * law(s / 1e4)).collect();
            let got = power_law_exponent(&sizes, &values).unwrap();
            assert!((got - k).abs() < 1e-9, "exponent {k}: fitted {got}");
        }
    }

    #[test]
    fn the_fit_is_least_squares_over_all_points() {
        // log₂ points (0, 0), (1, 2), (2, 2), (3, 3): x̄ = 1.5, ȳ = 1.75, Σ(x − x̄)(y − ȳ) = 4.5 and
        // Σ(x − x̄)² = 5, so the slope is 0.9; the end points alone would give 1.
        let sizes = [1.0, 2.0, 4.0, 8.0];
        let values = [1.0, 4.0, 4.0, 8.0];
        let got = power_law_exponent(&sizes, &values).unwrap();
        assert!((got - 0.9).abs() < 1e-12, "{got}");
    }

    #[test]
    fn no_exponent_without_a_slope_or_with_nonpositive_values() {
        assert_eq!(power_law_exponent(&[5.0, 5.0, 5.0], &[1.0, 2.0, 3.0]), None);
        assert_eq!(power_law_exponent(&[1.0, 4.0], &[0.0, 1.0]), None);
        assert_eq!(power_law_exponent(&[1.0], &[1.0]), None);
        assert_eq!(power_law_exponent(&[1.0, 4.0], &[1.0]), None);
    }
}
