//! `texsyn score`: nearest-patch quality numbers of a run's results against their exemplars,
//! read from the run's cached artifacts after the run.
//!
//! The measures are [`crate::image::patch_score`]'s (see there and the README's "Scoring"):
//! the mean RMS distance of each output `p × p` patch to its exact nearest exemplar patch,
//! divided by the same for unseen parts of the exemplar (`ratio`), `coverage`,
//! `largest_offset` and `gradient_ratio`. What each method's output is, and how it is brought
//! into the exemplar's frame, is in its own file: [`synth2d`] here, [`charts`] (jump maps:
//! discs unfolded through the parameterization, and coordinate seams), [`geometry`] (geometry
//! images: relief image and mesh checks), [`solid`] (sections along an exemplar plane),
//! [`surface`] (graph matching and feature-aligned texturing: vertex colours on discs
//! unfolded along the field). Outputs with no exemplar-aligned image (a solid's surface
//! request) are listed with the reason in [`Report::not_scored`].
//!
//! Each method's score hook ([`Planned::score`]) calls the function for its outputs
//! here with the typed handles of the nodes it reads; this floor knows no method.
//!
//! `[score]` never reaches a node: it is taken out of the config before the method builds
//! its DAG, so adding it changes no key and no lock file.

pub mod alignment;
pub mod charts;
pub mod geometry;
pub mod relief_frame;
pub mod solid;
pub mod surface;

use crate::artifact::{Bundle, Format};
use crate::check::{ParamError, check_range};
use crate::config::{Config, ConfigError};
use crate::image::patch_score::{PatchScore, ScoreParams, patch_score_masked};
use crate::image::{Image, ImageView};
use crate::pipeline::{Handle, RunResult};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// What a planned method keeps for after its run.
pub trait Planned: Send + Sync {
    /// Scores the run's results against their exemplars (README, "Scoring"), reading the
    /// nodes it kept handles to. An output with no exemplar-aligned image goes to
    /// `not_scored` with the reason.
    fn score(&self, run: &Run<'_>, not_scored: &mut Vec<String>)
    -> Result<Vec<Item>, ScoreFailure>;

    /// For a run with nothing to score as it is (a solid's surface request): the `--set`
    /// that asks for a scoreable variant, which `texsyn score` runs and scores instead.
    fn score_substitute(&self, _result: &RunResult) -> Option<String> {
        None
    }
}

/// `[score]` of any config.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ScoreSection {
    /// Whether `run` scores its results (and `run --json` reports them). `texsyn score`
    /// scores whatever this says. Default: true (the section asks for it).
    pub enabled: bool,
    /// Patch side in pixels, 1..=31. Default: 7.
    pub patch: u32,
    /// Most output patches scored (a seeded subset beyond), 1..=10 000 000. Default: 20 000.
    pub max_queries: u32,
    /// Seed of the query subset, the self baseline's crops and the seams' random placements.
    /// Default: 0.
    pub seed: u64,
}

impl Default for ScoreSection {
    fn default() -> Self {
        let d = ScoreParams::default();
        ScoreSection {
            enabled: true,
            patch: d.patch,
            max_queries: d.max_queries as u32,
            seed: d.seed,
        }
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct OnlyScore {
    score: ScoreSection,
}

impl ScoreSection {
    pub fn validate(&self) -> Result<(), ParamError> {
        check_range("score.patch", self.patch, 1, 31)?;
        check_range("score.max_queries", self.max_queries, 1, 10_000_000)
    }

    /// The config's `[score]` (with `--set` overrides), validated; `None` without one.
    pub fn from_config(config: &Config) -> Result<Option<ScoreSection>, ConfigError> {
        let Some(value) = config.table.get("score") else {
            return Ok(None);
        };
        let mut only = config.clone();
        only.table = toml::Table::new();
        only.table.insert("score".into(), value.clone());
        let s = only.parse::<OnlyScore>()?.score;
        s.validate().map_err(|e| config.param(e))?;
        Ok(Some(s))
    }

    pub fn params(&self) -> ScoreParams {
        ScoreParams {
            patch: self.patch,
            max_queries: self.max_queries as usize,
            seed: self.seed,
        }
    }
}

/// Why a run's results could not be scored.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct ScoreFailure(pub String);

impl ScoreFailure {
    pub fn new(msg: impl std::fmt::Display) -> Self {
        ScoreFailure(msg.to_string())
    }
}

/// One scored output.
#[derive(Clone, Debug, Serialize)]
pub struct Item {
    /// What was scored (an output file, or what was resampled from the artifacts).
    pub output: String,
    /// What it was compared with.
    pub exemplar: String,
    /// The nearest-patch measures; `None` when the output holds no whole patch (see `notes`).
    pub score: Option<PatchScore>,
    /// Method-specific numbers (seams, mesh checks, the density offset).
    #[serde(skip_serializing_if = "serde_json::Map::is_empty")]
    pub extra: serde_json::Map<String, serde_json::Value>,
    /// What to keep in mind when reading the numbers.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub notes: Vec<String>,
}

impl Item {
    pub fn new(output: impl Into<String>, exemplar: impl Into<String>) -> Self {
        Item {
            output: output.into(),
            exemplar: exemplar.into(),
            score: None,
            extra: serde_json::Map::new(),
            notes: Vec::new(),
        }
    }
}

/// The scores of one run.
#[derive(Clone, Debug, Serialize)]
pub struct Report {
    pub config: String,
    pub method: String,
    pub patch: u32,
    pub max_queries: u32,
    pub seed: u64,
    pub items: Vec<Item>,
    /// Outputs that are not scored, each with the reason.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub not_scored: Vec<String>,
    pub seconds: f64,
}

/// Scores one run: the items of a method's score hook, with the section's parameters.
pub fn report(
    config: &Config,
    method: &str,
    section: &ScoreSection,
    score: impl FnOnce(&ScoreParams, &mut Vec<String>) -> Result<Vec<Item>, ScoreFailure>,
) -> Result<Report, ScoreFailure> {
    let start = std::time::Instant::now();
    let mut not_scored = Vec::new();
    let items = score(&section.params(), &mut not_scored)?;
    Ok(Report {
        config: config.path.display().to_string(),
        method: method.to_owned(),
        patch: section.patch,
        max_queries: section.max_queries,
        seed: section.seed,
        items,
        not_scored,
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// What a method's score hook reads: its config (for paths relative to it), the run's
/// artifacts through the typed handles its plan kept, and the scoring parameters.
pub struct Run<'a> {
    pub config: &'a Config,
    pub result: &'a RunResult,
    pub params: ScoreParams,
}

impl<'a> Run<'a> {
    /// The artifact of the node behind `node`, viewed as `F`.
    pub fn view<F: Format>(&self, node: Handle<F>) -> Result<F::View<'a>, ScoreFailure> {
        let report = &self.result.reports[node.index()];
        F::view(&self.result.artifacts[node.index()])
            .map_err(|e| ScoreFailure::new(format!("reading {}'s artifact: {e}", report.node)))
    }

    /// One file of node `node`'s output bundle.
    pub fn file(&self, node: Handle<Bundle>, file: &str) -> Result<Vec<u8>, ScoreFailure> {
        let bundle = self.view(node)?;
        let entry = bundle
            .entries
            .iter()
            .find(|e| e.name == file)
            .ok_or_else(|| {
                ScoreFailure::new(format!("the run's outputs have no {file} to score"))
            })?;
        bundle
            .file(entry)
            .map(|b| b.into_owned())
            .map_err(|e| ScoreFailure::new(format!("reading {file} from the cache: {e}")))
    }

    /// An output image file of node `node`, decoded.
    pub fn image(&self, node: Handle<Bundle>, file: &str) -> Result<Image, ScoreFailure> {
        let bytes = self.file(node, file)?;
        crate::image::decode_image(Path::new(file), &bytes)
            .map_err(|e| ScoreFailure::new(format!("decoding {file}: {e}")))
    }

    /// Scores `output` (where `mask` is set) against `exemplar` into `item`; an output with
    /// no whole patch leaves the score empty with a note.
    pub fn score_into(
        &self,
        item: &mut Item,
        output: ImageView<'_>,
        mask: Option<&[bool]>,
        exemplar: ImageView<'_>,
    ) -> Result<(), ScoreFailure> {
        use crate::image::patch_score::ScoreError;
        // What is scored, as a picture (masked texels black), for looking at.
        if let Some(dir) = std::env::var_os("TEXSYN_SCORE_DUMP") {
            let slug: String = item
                .output
                .chars()
                .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
                .collect();
            let mut img = Image {
                width: output.width,
                height: output.height,
                pixels: output.pixels.to_vec(),
            };
            if let Some(m) = mask {
                for (p, &inside) in img.pixels.iter_mut().zip(m) {
                    if !inside {
                        *p = [0.0, 0.0, 0.0, 1.0];
                    }
                }
            }
            let png =
                crate::stages::reconstruct::textured_export::encode_png(&img.to_rgba8(), false);
            let path = Path::new(&dir).join(format!("score_{}.png", &slug[..slug.len().min(60)]));
            if let Err(e) = std::fs::write(&path, png) {
                tracing::warn!("TEXSYN_SCORE_DUMP: writing {}: {e}", path.display());
            }
        }
        match patch_score_masked(output, mask, exemplar, &self.params) {
            Ok(s) => item.score = Some(s),
            Err(
                e @ (ScoreError::NoPatchInMask { .. }
                | ScoreError::TooSmall { .. }
                | ScoreError::BaselineTooSmall { .. }),
            ) => item.notes.push(format!("not scored: {e}")),
            Err(e) => {
                return Err(ScoreFailure::new(format!(
                    "scoring {} against {}: {e}",
                    item.output, item.exemplar
                )));
            }
        }
        Ok(())
    }
}

/// The nodes `synth2d`'s score reads.
pub struct Synth2dNodes {
    pub reconstruct: Handle<Bundle>,
    pub exemplar: Handle<Image>,
}

impl Planned for Synth2dNodes {
    fn score(&self, run: &Run<'_>, _: &mut Vec<String>) -> Result<Vec<Item>, ScoreFailure> {
        Ok(vec![synth2d(run, self.reconstruct, self.exemplar)?])
    }
}

/// `synth2d`: the blended image against the exemplar.
pub fn synth2d(
    run: &Run,
    out: Handle<Bundle>,
    exemplar: Handle<Image>,
) -> Result<Item, ScoreFailure> {
    let out = run.image(out, "synthesized.png")?;
    let ex = run.view(exemplar)?;
    let mut item = Item::new("synthesized.png", "inputs.exemplar");
    run.score_into(&mut item, out.view(), None, ex)?;
    Ok(item)
}

/// The text `texsyn score` prints for a report.
pub fn report_text(r: &Report) -> String {
    let mut s = format!(
        "{} ({}), {}×{} patches, at most {} queries, seed {}\n",
        r.config, r.method, r.patch, r.patch, r.max_queries, r.seed
    );
    for item in &r.items {
        s += &format!("  {} against {}\n", item.output, item.exemplar);
        if let Some(sc) = &item.score {
            s += &format!(
                "    ratio {:.3} (mean RMS {:.4} / baseline {:.4}), coverage {:.3}, largest offset {:.3}, gradient ratio {:.3}, {} patches{}\n",
                sc.ratio,
                sc.mean_rms,
                sc.baseline_rms,
                sc.coverage,
                sc.largest_offset,
                sc.gradient_ratio,
                sc.queries,
                if sc.subsampled {
                    " (seeded subset)"
                } else {
                    ""
                }
            );
        }
        for (k, v) in &item.extra {
            s += &format!("    {k}: {v}\n");
        }
        for n in &item.notes {
            s += &format!("    note: {n}\n");
        }
    }
    for n in &r.not_scored {
        s += &format!("  not scored: {n}\n");
    }
    s
}

/// The heading of BENCHMARKS.md's quality table, which `cargo run --release -p texsyn-bench -- -o` keeps.
pub const QUALITY_HEADING: &str = "## Quality: nearest-patch scores of every shipped config";

/// The quality table of several reports (BENCHMARKS.md): one row per scored item.
pub fn markdown_table(reports: &[Report]) -> String {
    let mut s = String::from(
        "| config | output | ratio | coverage | largest offset | gradient ratio | patches | other |\n\
         |---|---|---:|---:|---:|---:|---:|---|\n",
    );
    let f = |x: f64| {
        if x.is_finite() {
            format!("{x:.3}")
        } else {
            "∞".into()
        }
    };
    for r in reports {
        let name = Path::new(&r.config)
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| r.config.clone());
        for item in &r.items {
            let other: Vec<String> = item
                .extra
                .iter()
                .map(|(k, v)| format!("{k} {}", compact(v)))
                .collect();
            match &item.score {
                Some(sc) => {
                    s += &format!(
                        "| {name} | {} | {} | {} | {} | {} | {}{} | {} |\n",
                        item.output,
                        f(sc.ratio),
                        f(sc.coverage),
                        f(sc.largest_offset),
                        f(sc.gradient_ratio),
                        sc.queries,
                        if sc.subsampled { " (subset)" } else { "" },
                        other.join("; ")
                    )
                }
                None => {
                    s += &format!(
                        "| {name} | {} | – | – | – | – | 0 | {} |\n",
                        item.output,
                        other.join("; ")
                    )
                }
            }
        }
        for n in &r.not_scored {
            let short = n.split(':').next().unwrap_or(n);
            s += &format!(
                "| {name} | not scored ({short}) | – | – | – | – | – | see `texsyn score` |\n"
            );
        }
    }
    s
}

/// A JSON value in a table cell: numbers to 3 decimals, objects as `k v` pairs.
fn compact(v: &serde_json::Value) -> String {
    match v {
        serde_json::Value::Number(n) => match n.as_f64() {
            Some(x) if n.is_f64() => format!("{x:.3}"),
            _ => n.to_string(),
        },
        serde_json::Value::Object(m) => m
            .iter()
            .map(|(k, v)| format!("{k} {}", compact(v)))
            .collect::<Vec<_>>()
            .join(", "),
        serde_json::Value::Null => "–".into(),
        other => other.to_string(),
    }
}

/// `x` to three decimals (the precision the reports print), so JSON floors read cleanly.
fn round3(x: f64) -> f64 {
    (x * 1000.0).round() / 1000.0
}
