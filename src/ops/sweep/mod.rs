//! Parameter sweeps (README, "Sweeps"): one base config, axes over any of its values, and one
//! ordinary run per point, each with its own output folder, on one shared cache.
//!
//! A sweep file:
//!
//! ```toml
//! base = "../demo.toml"            # relative to the sweep file
//! combine = "product"              # or "zip": the i-th value of every axis together
//! [axes]
//! "synthesize.seed" = [1, 2, 3]
//! "inputs.mesh" = ["a.off", "b.off"]                          # paths: relative to the sweep file
//! "field.density_offset" = { from = 0, to = 2, steps = 5 }    # 0, 0.5, 1, 1.5, 2
//! ```
//!
//! Points are numbered in order: with `product`, the last axis varies fastest (like nested
//! loops written in the file's order). Each point is the base config with one `--set` per axis,
//! so everything `run` guarantees holds for a point; the sweep adds the table of all points
//! ([`table`]), the lock of all of them ([`lock`]), and executors that run them side by side
//! ([`local`]) or as Slurm job arrays ([`slurm_executor`]). A point's run writes its report
//! (`run --report`) beside its outputs; the table is made from those reports, so a point run
//! by another process, on another machine or in an earlier, killed sweep counts the same.

pub mod local;
pub mod lock;
pub mod slurm_executor;
pub mod table;

use crate::config::{Config, ConfigError};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

#[derive(Debug, thiserror::Error)]
pub enum SweepError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: {message}")]
    Invalid { path: PathBuf, message: String },
    #[error("{path}: point {index} ({label}): {source}")]
    Point {
        path: PathBuf,
        index: usize,
        label: String,
        source: Box<dyn std::error::Error + Send + Sync>,
    },
}

/// How the axes combine into points.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Combine {
    /// Every combination (nested loops, the last axis fastest).
    #[default]
    Product,
    /// The i-th value of every axis together; all axes must have one length.
    Zip,
}

/// An axis as written: a list of values, or an evenly spaced range.
#[derive(Debug, Clone, Deserialize)]
#[serde(untagged)]
enum AxisSpec {
    Values(Vec<toml::Value>),
    Range(RangeSpec),
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct RangeSpec {
    from: toml::Value,
    to: toml::Value,
    steps: i64,
}

/// The sweep file as written.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct SweepFile {
    base: PathBuf,
    #[serde(default)]
    combine: Combine,
    /// Keyed with their place in the file: a TOML table's keys come out sorted, and the axes'
    /// order as written is the table's column order and the points' loop order.
    #[serde(default)]
    axes: BTreeMap<toml::Spanned<String>, AxisSpec>,
    /// Points run side by side by the local executor (default: one per core, at most the
    /// number of points).
    workers: Option<usize>,
    /// Split each point's run into this many shards (a `solid` base only; see
    /// `texsyn run --shard`), gathered by one more run.
    shards: Option<u32>,
    /// Slurm options (`partition`, `time`, `mem`, `cpus_per_task`, `account`).
    slurm: Option<toml::Table>,
}

/// One axis: a config key and its values, in order.
#[derive(Debug, Clone, PartialEq)]
pub struct Axis {
    pub key: String,
    pub values: Vec<toml::Value>,
}

/// A loaded sweep.
#[derive(Debug, Clone)]
pub struct Sweep {
    pub path: PathBuf,
    /// The file name without extension: names the default output folder.
    pub stem: String,
    pub base: PathBuf,
    pub combine: Combine,
    pub axes: Vec<Axis>,
    pub workers: Option<usize>,
    pub shards: Option<u32>,
    pub slurm: Option<toml::Table>,
    pub points: Vec<Point>,
}

/// One point: the value of each axis, and the overrides that make its config.
#[derive(Debug, Clone, PartialEq)]
pub struct Point {
    pub index: usize,
    /// (key, value as written in the sweep file), one per axis.
    pub values: Vec<(String, toml::Value)>,
    /// The `--set` overrides applied to the base config (paths made relative to the base
    /// config's folder, or absolute).
    pub sets: Vec<String>,
}

impl Point {
    /// `synthesize.seed=2, inputs.mesh="a.off"`: the values as written.
    pub fn label(&self) -> String {
        self.values
            .iter()
            .map(|(k, v)| format!("{k}={v}"))
            .collect::<Vec<_>>()
            .join(", ")
    }

    /// The point's folder name: its number and a short, file-name-safe form of its values
    /// (`003-seed=3`), so a folder listing reads like the table.
    pub fn folder_name(&self) -> String {
        let mut slug = String::new();
        for (k, v) in &self.values {
            let leaf = k.rsplit('.').next().unwrap_or(k);
            let value = match v {
                toml::Value::String(s) => Path::new(s)
                    .file_stem()
                    .map(|s| s.to_string_lossy().into_owned())
                    .unwrap_or_else(|| s.clone()),
                other => other.to_string(),
            };
            if !slug.is_empty() {
                slug.push('_');
            }
            slug += &format!("{leaf}={value}");
        }
        let slug: String = slug
            .chars()
            .map(|c| {
                if c.is_ascii_alphanumeric() || matches!(c, '.' | '=' | '-' | '_') {
                    c
                } else {
                    '-'
                }
            })
            .take(60)
            .collect();
        format!("{:03}-{slug}", self.index)
    }
}

/// The most points one sweep may have: the axes' product (or, zipped, their length) is
/// checked against it before any point is made.
pub const MAX_POINTS: usize = 100_000;

/// A sweep of more points than this says how its checking of the points goes.
pub const SAY_PROGRESS_FROM: usize = 1000;

impl Sweep {
    /// Reads and checks a sweep file: the syntax, every axis (non-empty, zipped axes of one
    /// length) and every point's config (an unknown key or a value of the wrong type is an
    /// error naming the point), before anything runs.
    pub fn load(path: &Path) -> Result<Sweep, SweepError> {
        Self::load_saying(path, false)
    }

    /// As [`Sweep::load`]; unless `quiet`, a sweep of more than [`SAY_PROGRESS_FROM`] points
    /// says on stderr how many points it checks, and how far it got every tenth of them.
    pub fn load_saying(path: &Path, quiet: bool) -> Result<Sweep, SweepError> {
        let text = crate::config::read_text_file(path).map_err(|source| SweepError::Io {
            path: path.to_owned(),
            source,
        })?;
        let sweep = Self::parse(path, &text)?;
        let n = sweep.points.len();
        let say = !quiet && n > SAY_PROGRESS_FROM;
        if say {
            eprintln!("{}: checking the configs of {n} points", path.display());
        }
        for (i, point) in sweep.points.iter().enumerate() {
            sweep.check_point(point)?;
            if say && (i + 1) % n.div_ceil(10) == 0 && i + 1 < n {
                eprintln!("{}: {} of {n} points checked", path.display(), i + 1);
            }
        }
        Ok(sweep)
    }

    /// Whether a TOML file is a sweep rather than a run config: it has `base` and `axes`
    /// and no `method`.
    pub fn is_sweep_file(path: &Path) -> bool {
        crate::config::read_text_file(path)
            .ok()
            .and_then(|t| toml::from_str::<toml::Table>(&t).ok())
            .is_some_and(|t| {
                t.contains_key("base") && t.contains_key("axes") && !t.contains_key("method")
            })
    }

    /// Parses a sweep file's text into its points (the points' configs are not checked).
    pub fn parse(path: &Path, text: &str) -> Result<Sweep, SweepError> {
        let invalid = |message: String| SweepError::Invalid {
            path: path.to_owned(),
            message,
        };
        let file: SweepFile = toml::from_str(text).map_err(|e| {
            invalid(
                e.to_string()
                    .trim_end()
                    .replace('\n', " ")
                    .replace("  ", " "),
            )
        })?;
        let dir = match path.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_owned(),
            _ => PathBuf::from("."),
        };
        let base = dir.join(&file.base);
        if file.axes.is_empty() {
            return Err(invalid(
                "axes: empty; a sweep needs at least one axis, e.g. \"synthesize.seed\" = [1, 2, 3]"
                    .into(),
            ));
        }
        let mut written: Vec<(&toml::Spanned<String>, &AxisSpec)> = file.axes.iter().collect();
        written.sort_by_key(|(k, _)| k.span().start);
        let mut axes = Vec::new();
        for (key, spec) in written {
            let key = key.get_ref();
            let at = |m: String| invalid(format!("axes.\"{key}\": {m}"));
            if key.split('.').any(|p| p.trim().is_empty()) {
                return Err(at("the key has an empty part".into()));
            }
            let values = match spec {
                AxisSpec::Values(v) => v.clone(),
                AxisSpec::Range(r) => range_values(r).map_err(at)?,
            };
            if values.is_empty() {
                return Err(at("no values; give at least one".into()));
            }
            if values
                .iter()
                .any(|v| matches!(v, toml::Value::Table(_) | toml::Value::Array(_)))
                && key.starts_with("inputs.")
            {
                return Err(at(
                    "input values must be paths (strings) relative to the sweep file".into(),
                ));
            }
            axes.push(Axis {
                key: key.trim().to_owned(),
                values,
            });
        }
        if file.combine == Combine::Zip {
            let n = axes[0].values.len();
            if let Some(a) = axes.iter().find(|a| a.values.len() != n) {
                return Err(invalid(format!(
                    "combine = \"zip\" needs axes of one length: \"{}\" has {} values, \"{}\" has {}",
                    axes[0].key,
                    n,
                    a.key,
                    a.values.len()
                )));
            }
        }
        if let Some(t) = &file.slurm {
            use serde::Deserialize;
            let opts = crate::ops::slurm::SlurmOptions::deserialize(toml::Value::Table(t.clone()))
                .map_err(|e| invalid(format!("[slurm]: {}", e.to_string().trim())))?;
            opts.check().map_err(|e| invalid(format!("[slurm]: {e}")))?;
        }
        if let Some(0) = file.shards {
            return Err(invalid("shards: must be at least 1".into()));
        }
        if let Some(0) = file.workers {
            return Err(invalid("workers: must be at least 1".into()));
        }
        let base_dir = match base.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_owned(),
            _ => PathBuf::from("."),
        };
        let count = match file.combine {
            Combine::Zip => Some(axes[0].values.len()),
            Combine::Product => axes
                .iter()
                .try_fold(1usize, |n, a| n.checked_mul(a.values.len())),
        };
        if count.is_none_or(|n| n > MAX_POINTS) {
            let sizes: Vec<String> = axes
                .iter()
                .map(|a| format!("\"{}\" {}", a.key, a.values.len()))
                .collect();
            let total = count.map_or("more than 2^64".into(), |n| n.to_string());
            return Err(invalid(format!(
                "axes: {total} points ({}), over the limit of {MAX_POINTS} points per sweep; \
                 split it into several sweeps or use fewer values",
                sizes.join(" × ")
            )));
        }
        let combos = combinations(&axes, file.combine);
        let points = combos
            .into_iter()
            .enumerate()
            .map(|(index, choice)| {
                let values: Vec<(String, toml::Value)> = axes
                    .iter()
                    .zip(&choice)
                    .map(|(a, &i)| (a.key.clone(), a.values[i].clone()))
                    .collect();
                let sets = values
                    .iter()
                    .map(|(k, v)| set_arg(k, v, &dir, &base_dir))
                    .collect();
                Point {
                    index,
                    values,
                    sets,
                }
            })
            .collect();
        Ok(Sweep {
            path: path.to_owned(),
            stem: path
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_else(|| "sweep".into()),
            base,
            combine: file.combine,
            axes,
            workers: file.workers,
            shards: file.shards,
            slurm: file.slurm,
            points,
        })
    }

    /// The point's config: the base with the point's overrides.
    pub fn point_config(&self, point: &Point) -> Result<Config, ConfigError> {
        Config::load(&self.base, &point.sets)
    }

    /// Plans the point, so that an unknown key or a wrong type is found before anything runs.
    fn check_point(&self, point: &Point) -> Result<(), SweepError> {
        let wrap = |source: Box<dyn std::error::Error + Send + Sync>| SweepError::Point {
            path: self.path.clone(),
            index: point.index,
            label: point.label(),
            source,
        };
        let config = self.point_config(point).map_err(|e| wrap(Box::new(e)))?;
        let plan = crate::methods::plan(&config).map_err(|e| wrap(Box::new(e)))?;
        if self.shards.is_some_and(|n| n > 1) && !plan.splits_into_shards() {
            return Err(wrap(
                format!(
                    "shards = {}: only a `solid` run can be split into shards (this is {})",
                    self.shards.unwrap_or(1),
                    plan.method
                )
                .into(),
            ));
        }
        Ok(())
    }

    /// The default output folder: `out/<sweep name>` ([`crate::config::default_out`]).
    pub fn default_out(&self) -> Result<PathBuf, ConfigError> {
        crate::config::default_out(&self.path, &self.stem)
    }
}

/// The product or zip of the axes, as value indices per axis, in point order.
fn combinations(axes: &[Axis], combine: Combine) -> Vec<Vec<usize>> {
    match combine {
        Combine::Zip => (0..axes[0].values.len())
            .map(|i| vec![i; axes.len()])
            .collect(),
        Combine::Product => {
            let mut out = vec![Vec::new()];
            for a in axes {
                out = out
                    .into_iter()
                    .flat_map(|prefix| {
                        (0..a.values.len()).map(move |i| {
                            let mut p = prefix.clone();
                            p.push(i);
                            p
                        })
                    })
                    .collect();
            }
            out
        }
    }
}

/// `{ from, to, steps }`: `steps` evenly spaced values from `from` to `to` inclusive; integers
/// when both ends are integers and every step lands on one, else floats.
fn range_values(r: &RangeSpec) -> Result<Vec<toml::Value>, String> {
    let num = |v: &toml::Value, what: &str| match v {
        toml::Value::Integer(i) => Ok((*i as f64, Some(*i))),
        toml::Value::Float(f) if f.is_finite() => Ok((*f, None)),
        other => Err(format!("`{what}` must be a number, found {other}")),
    };
    let (from, from_int) = num(&r.from, "from")?;
    let (to, to_int) = num(&r.to, "to")?;
    if r.steps < 1 {
        return Err(format!("`steps` must be at least 1, found {}", r.steps));
    }
    if r.steps > 1_000_000 {
        return Err(format!(
            "`steps` must be at most 1000000, found {}",
            r.steps
        ));
    }
    let n = r.steps;
    if n == 1 {
        return Ok(vec![r.from.clone()]);
    }
    if let (Some(a), Some(b)) = (from_int, to_int)
        && let Some(span) = b.checked_sub(a)
        && span % (n - 1) == 0
    {
        let step = span / (n - 1);
        return Ok((0..n).map(|i| toml::Value::Integer(a + step * i)).collect());
    }
    let m = (n - 1) as f64;
    Ok((0..n)
        .map(|i| {
            // One rounding per term and one division: the ends exactly as written, and
            // 0.1 (not 0.09999999999999999) for i = 1 of 0 to 1 in 11 steps.
            let i = i as f64;
            toml::Value::Float((from * (m - i) + to * i) / m)
        })
        .collect())
}

/// The `--set` argument of one axis value. Input paths are written relative to the sweep
/// file; the base config resolves them relative to its own folder, so they are rewritten
/// relative to that folder when it is a prefix of theirs, and made absolute otherwise.
fn set_arg(key: &str, value: &toml::Value, sweep_dir: &Path, base_dir: &Path) -> String {
    match value {
        toml::Value::String(s) if key.starts_with("inputs.") => {
            let p = Path::new(s);
            let resolved = if p.is_absolute() {
                p.to_owned()
            } else {
                sweep_dir.join(p)
            };
            let abs = |q: &Path| std::path::absolute(q).unwrap_or_else(|_| q.to_owned());
            let (resolved, base_dir) = (abs(&resolved), abs(base_dir));
            let shown = resolved
                .strip_prefix(&base_dir)
                .map(Path::to_owned)
                .unwrap_or(resolved);
            format!(
                "{key}={}",
                toml::Value::String(shown.to_string_lossy().into_owned())
            )
        }
        other => format!("{key}={other}"),
    }
}

/// What a point's run reports (`texsyn run --report`), as the table reads it back.
#[derive(Debug, Clone, Deserialize, Serialize)]
pub struct RunReport {
    pub nodes: Vec<ReportedNode>,
    #[serde(default)]
    pub outputs: Vec<OutputEntry>,
    #[serde(default)]
    pub warnings: Vec<String>,
    pub seconds: f64,
    /// The process's peak resident memory (VmHWM), when the system says.
    #[serde(default)]
    pub peak_memory_bytes: Option<u64>,
    /// The overrides the run was made with.
    #[serde(default)]
    pub sets: Vec<String>,
    /// The shard this run computed (`i/N`), if any.
    #[serde(default)]
    pub shard: Option<String>,
    #[serde(default)]
    pub scores: Option<serde_json::Value>,
}

/// One node's line of a run report (the fields of [`crate::pipeline::NodeReport`]).
#[derive(Debug, Clone, Deserialize, Serialize)]
pub struct ReportedNode {
    pub node: String,
    pub stage: String,
    pub algorithm: String,
    /// "cached" or "ran".
    pub status: String,
    pub seconds: f64,
    pub bytes: u64,
    pub key: String,
    pub content_hash: String,
    #[serde(default)]
    pub pieces: Option<ReportedPieces>,
    #[serde(default)]
    pub peak_memory_bytes: Option<u64>,
    /// CPU seconds of the process while the node ran (reports written since it was added).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cpu_seconds: Option<f64>,
}

#[derive(Debug, Clone, Copy, Deserialize, Serialize)]
pub struct ReportedPieces {
    pub computed: u64,
    pub reused: u64,
}

#[derive(Debug, Clone, Deserialize, Serialize)]
pub struct OutputEntry {
    pub path: PathBuf,
    pub written: bool,
}

impl RunReport {
    pub fn read(path: &Path) -> Option<RunReport> {
        let bytes = std::fs::read(path).ok()?;
        serde_json::from_slice(&bytes).ok()
    }
}

/// Where one sweep keeps its points' outputs, reports and logs.
#[derive(Debug, Clone)]
pub struct SweepDir {
    pub root: PathBuf,
}

impl SweepDir {
    pub fn new(root: &Path) -> SweepDir {
        SweepDir {
            root: root.to_owned(),
        }
    }
    /// The point's output folder (what `run --out` gets).
    pub fn point_out(&self, point: &Point) -> PathBuf {
        self.root.join("points").join(point.folder_name())
    }
    /// The point's run report (`run --report`).
    pub fn report(&self, point: &Point) -> PathBuf {
        self.root
            .join("reports")
            .join(format!("{:03}.json", point.index))
    }
    /// A shard's run report.
    pub fn shard_report(&self, point: &Point, shard: u32) -> PathBuf {
        self.root
            .join("reports")
            .join(format!("{:03}.shard{shard}.json", point.index))
    }
    /// The point's log (stdout and stderr of its run).
    pub fn log(&self, point: &Point) -> PathBuf {
        self.root
            .join("logs")
            .join(format!("{:03}.log", point.index))
    }
    pub fn shard_log(&self, point: &Point, shard: u32) -> PathBuf {
        self.root
            .join("logs")
            .join(format!("{:03}.shard{shard}.log", point.index))
    }
}

impl SweepDir {
    /// Removes the reports of a point about to run (its own and its shards'), so that a run
    /// that fails leaves no earlier report to be taken for its result.
    pub fn clear_reports(&self, point: &Point, shards: u32) {
        let _ = std::fs::remove_file(self.report(point));
        for i in 0..shards.max(1) {
            let _ = std::fs::remove_file(self.shard_report(point, i));
        }
    }
}

/// A point's state before a sweep runs it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case", tag = "state")]
pub enum PointState {
    /// Its report is there, made with these overrides, every node is cached and every output
    /// it wrote is on disk: nothing to do.
    Done,
    /// These nodes would be computed (the others are cached).
    WouldRun { nodes: Vec<String> },
}

/// Whether the point is done, or what its run would compute (like `texsyn status`).
pub fn point_state(
    sweep: &Sweep,
    dir: &SweepDir,
    point: &Point,
    cache: &crate::cache::Cache,
) -> Result<PointState, SweepError> {
    let config = sweep
        .point_config(point)
        .map_err(|e| point_error(sweep, point, Box::new(e)))?;
    let plan = crate::methods::plan(&config).map_err(|e| point_error(sweep, point, Box::new(e)))?;
    let lines = crate::pipeline::status(&plan.dag, cache);
    let nodes: Vec<String> = lines
        .iter()
        .filter(|l| l.state != "cached")
        .map(|l| l.node.clone())
        .collect();
    // The report must be of this very run: the same overrides, and node for node the keys
    // the cache has now (so a base config edited since, or a code version bumped, is not
    // taken for done), and its outputs still in the point's folder.
    let out = dir.point_out(point);
    let report = RunReport::read(&dir.report(point));
    let reported = report.is_some_and(|r| {
        r.sets == point.sets
            && r.shard.is_none()
            && r.nodes.len() == lines.len()
            && r.nodes
                .iter()
                .zip(&lines)
                .all(|(n, l)| n.node == l.node && l.key.as_deref() == Some(n.key.as_str()))
            && r.outputs.iter().all(|o| {
                o.path
                    .file_name()
                    .is_some_and(|name| out.join(name).is_file())
            })
    });
    Ok(if nodes.is_empty() && reported {
        PointState::Done
    } else {
        PointState::WouldRun { nodes }
    })
}

fn point_error(
    sweep: &Sweep,
    point: &Point,
    source: Box<dyn std::error::Error + Send + Sync>,
) -> SweepError {
    SweepError::Point {
        path: sweep.path.clone(),
        index: point.index,
        label: point.label(),
        source,
    }
}

/// The command line that runs one point (or one shard of it) with the same binary: an
/// ordinary `texsyn run`, writing its report where the table looks for it.
pub fn point_command(
    exe: &Path,
    sweep: &Sweep,
    dir: &SweepDir,
    point: &Point,
    shard: Option<(u32, u32)>,
    common: &CommonArgs,
) -> Vec<std::ffi::OsString> {
    let mut argv: Vec<std::ffi::OsString> = vec![exe.into(), "run".into()];
    argv.push(sweep.base.clone().into());
    for s in &point.sets {
        argv.push("--set".into());
        argv.push(s.into());
    }
    if shard.is_none() {
        argv.push("--out".into());
        argv.push(dir.point_out(point).into());
    }
    argv.push("--report".into());
    match shard {
        Some((i, n)) => {
            argv.push(dir.shard_report(point, i).into());
            argv.push("--shard".into());
            argv.push(format!("{i}/{n}").into());
        }
        None => argv.push(dir.report(point).into()),
    }
    argv.push("--cache".into());
    argv.push(common.cache.clone().into());
    if let Some(j) = common.threads {
        argv.push("-j".into());
        argv.push(j.to_string().into());
    }
    if let Some(m) = common.max_memory {
        argv.push("--max-memory".into());
        argv.push(m.to_string().into());
    }
    argv
}

/// What every point's command shares.
#[derive(Debug, Clone)]
pub struct CommonArgs {
    /// The cache folder (absolute, so a task started anywhere finds it).
    pub cache: PathBuf,
    /// Threads per point.
    pub threads: Option<usize>,
    /// Memory budget per point, bytes.
    pub max_memory: Option<u64>,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sweep(text: &str) -> Result<Sweep, SweepError> {
        Sweep::parse(Path::new("sweeps/s.toml"), text)
    }

    #[test]
    fn product_varies_the_last_axis_fastest_and_zip_pairs_values() {
        let s = sweep(
            "base = \"../demo.toml\"\n[axes]\n\"synthesize.seed\" = [1, 2]\n\"parameterize.scale\" = [10.0, 20.0, 30.0]\n",
        )
        .unwrap();
        assert_eq!(s.points.len(), 6);
        let labels: Vec<String> = s.points.iter().map(|p| p.label()).collect();
        assert_eq!(
            labels[..4],
            [
                "synthesize.seed=1, parameterize.scale=10.0",
                "synthesize.seed=1, parameterize.scale=20.0",
                "synthesize.seed=1, parameterize.scale=30.0",
                "synthesize.seed=2, parameterize.scale=10.0",
            ]
        );
        assert_eq!(
            s.points[5].sets,
            ["synthesize.seed=2", "parameterize.scale=30.0"]
        );
        let z = sweep(
            "base = \"../demo.toml\"\ncombine = \"zip\"\n[axes]\n\"synthesize.seed\" = [1, 2]\n\"parameterize.scale\" = [10.0, 20.0]\n",
        )
        .unwrap();
        assert_eq!(z.points.len(), 2);
        assert_eq!(
            z.points[1].sets,
            ["synthesize.seed=2", "parameterize.scale=20.0"]
        );
    }

    #[test]
    fn ranges_give_integers_when_every_step_is_one_and_floats_otherwise() {
        let s = sweep("base = \"b.toml\"\n[axes]\n\"a.x\" = { from = 0, to = 2, steps = 5 }\n")
            .unwrap();
        let v: Vec<String> = s.points.iter().map(|p| p.values[0].1.to_string()).collect();
        assert_eq!(v, ["0.0", "0.5", "1.0", "1.5", "2.0"]);
        let s = sweep("base = \"b.toml\"\n[axes]\n\"a.x\" = { from = 0, to = 1, steps = 11 }\n")
            .unwrap();
        assert_eq!(s.points[1].values[0].1.to_string(), "0.1");
        assert_eq!(s.points[3].values[0].1.to_string(), "0.3");
        // No overflow on extreme ends: floats then.
        let s = sweep(&format!(
            "base = \"b.toml\"\n[axes]\n\"a.x\" = {{ from = {}, to = {}, steps = 3 }}\n",
            i64::MIN,
            i64::MAX
        ))
        .unwrap();
        assert_eq!(s.points.len(), 3);
        let s = sweep("base = \"b.toml\"\n[axes]\n\"a.x\" = { from = 1, to = 100, steps = 100 }\n")
            .unwrap();
        assert_eq!(s.points.len(), 100);
        assert_eq!(s.points[99].values[0].1, toml::Value::Integer(100));
        assert_eq!(s.points[0].values[0].1, toml::Value::Integer(1));
    }

    #[test]
    fn input_paths_are_relative_to_the_sweep_file_and_rewritten_for_the_base() {
        // The sweep in sweeps/, the base in the folder above: sweeps/../assets/a.off is
        // assets/a.off from the base's folder.
        let s = sweep("base = \"../demo.toml\"\n[axes]\n\"inputs.mesh\" = [\"../assets/a.off\"]\n")
            .unwrap();
        let set = &s.points[0].sets[0];
        assert!(set.starts_with("inputs.mesh="), "{set}");
        let value = set.trim_start_matches("inputs.mesh=").trim_matches('"');
        assert!(
            Path::new(value).ends_with("assets/a.off") && !value.contains("sweeps"),
            "{set}"
        );
        assert_eq!(s.points[0].folder_name(), "000-mesh=a");
    }

    #[test]
    fn bad_axes_are_errors_naming_the_file_and_the_axis() {
        let e = |t: &str| sweep(t).unwrap_err().to_string();
        let m = e("base = \"b.toml\"\n[axes]\n\"synthesize.seed\" = []\n");
        assert!(
            m.starts_with("sweeps/s.toml")
                && m.contains("synthesize.seed")
                && m.contains("no values"),
            "{m}"
        );
        let m = e("base = \"b.toml\"\n[axes]\n");
        assert!(m.contains("at least one axis"), "{m}");
        let m =
            e("base = \"b.toml\"\ncombine = \"zip\"\n[axes]\n\"a.x\" = [1]\n\"a.y\" = [1, 2]\n");
        assert!(m.contains("one length") && m.contains("a.y"), "{m}");
        let m = e("base = \"b.toml\"\n[axes]\n\"a.x\" = { from = \"a\", to = 1, steps = 2 }\n");
        assert!(m.contains("a.x"), "{m}");
        let m = e("base = \"b.toml\"\nbogus = 1\n[axes]\n\"a.x\" = [1]\n");
        assert!(m.contains("bogus"), "{m}");
        let m = e("base = \"b.toml\"\n[axes]\n\"a..x\" = [1]\n");
        assert!(m.contains("empty part"), "{m}");
        let m = e("base = \"b.toml\"\n[slurm]\ntime = \"soon\"\n[axes]\n\"a.x\" = [1]\n");
        assert!(m.contains("[slurm]") && m.contains("time"), "{m}");
    }
}
