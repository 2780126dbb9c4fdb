//! `texsyn report`'s pages: one self-contained HTML file per run or sweep that opens from disk
//! with no network. Images are inlined as data URIs, models as base64 in script elements, and
//! the page's two scripts are inlined too: a three.js viewer (vendored from npm at a pinned
//! version by `scripts/vendor-three`, bundled with esbuild; assets/VENDORED says which, its
//! licence is assets/THREE_LICENSE) and assets/report.js (sortable and filterable tables, and
//! the reload that `texsyn watch --serve` asks for).
//!
//! A run's page: the config and its overrides, the DAG as SVG (each node's status, time,
//! size, key and content hash), the inputs (images shown), the outputs (PNG previews shown,
//! every .glb in one 3D view with a toggle between them), the scores when the config asks for
//! them, whether the lock file beside the config verifies, and the run's time and peak memory.
//! A sweep's page: a gallery with one thumbnail per point, the results table sortable by any
//! column and filterable by each axis, and one section per point that the gallery and the
//! table link to.

pub mod dag_svg;

use crate::ops::sweep::table::Table;
use crate::ops::sweep::{RunReport, Sweep, SweepDir};
use crate::pipeline::{Dag, InputRef, NodeReport, NodeStatus};
use base64::Engine;
use std::fmt::Write;
use std::path::{Path, PathBuf};

const VIEWER_JS: &str = include_str!("assets/viewer.bundle.js");
const REPORT_JS: &str = include_str!("assets/report.js");
const VENDORED: &str = include_str!("assets/VENDORED");

/// Largest PNG shown inline at full size; larger ones are shown scaled down.
const MAX_INLINE_PNG: u64 = 4 << 20;
/// Longest side of a scaled-down preview.
const SCALED_SIDE: u32 = 1024;
/// Models inlined into one page, in all (base64 adds a third).
const MAX_MODELS_BYTES: u64 = 64 << 20;

/// Whether the lock file beside a config verifies the run.
pub enum LockStatus {
    /// No `NAME.lock` beside the config.
    Missing(PathBuf),
    /// The lock was made with other `--set` overrides: it says nothing about this run.
    OtherOverrides { path: PathBuf, sets: Vec<String> },
    /// Every entry matches.
    Verifies { path: PathBuf, entries: usize },
    /// Some do not: one line each.
    Differs { path: PathBuf, lines: Vec<String> },
    /// It could not be read.
    Unreadable { path: PathBuf, error: String },
}

/// What a run's page shows.
pub struct RunView<'a> {
    pub config: &'a Path,
    pub config_text: &'a str,
    pub method: &'a str,
    pub sets: &'a [String],
    pub dag: &'a Dag,
    pub reports: &'a [NodeReport],
    pub out_dir: &'a Path,
    /// The outputs and whether this run wrote each.
    pub outputs: &'a [(PathBuf, bool)],
    /// `texsyn score`'s text, when the config asks for scores.
    pub scores: Option<String>,
    pub lock: LockStatus,
    pub seconds: f64,
    pub peak_memory_bytes: Option<u64>,
    /// `watch --serve`: where the page learns that a rerun made a newer one.
    pub reload: Option<Reload<'a>>,
    /// The up direction the 3D view turns onto its +Y ([`preview_up`]).
    pub up: Option<[f32; 3]>,
}

/// The up direction of a config's previews, for the 3D view: `reconstruct.up` when it is a
/// vector, else (`"auto"` or absent) the guess for the mesh `inputs.mesh` names
/// ([`crate::render::up_axis::guess_up`]); `None` without a mesh or when it cannot be read.
pub fn preview_up(config: &crate::config::Config) -> Option<[f32; 3]> {
    use crate::render::up_axis::{UpAxis, guess_up};
    let given = config
        .table
        .get("reconstruct")
        .and_then(|r| r.get("up"))
        .and_then(|u| u.clone().try_into::<UpAxis>().ok());
    if let Some(UpAxis::Given(v)) = given {
        return Some(v);
    }
    let mesh = config.table.get("inputs")?.get("mesh")?.as_str()?;
    let path = config.resolve(Path::new(mesh));
    let bytes = std::fs::read(&path).ok()?;
    let mesh = crate::geom::io::read_mesh_bytes(&path, &bytes).ok()?;
    Some(guess_up(&mesh.positions, &mesh.triangles).to_array())
}

/// A served page's reload: `url` answers the current version; the page reloads itself when
/// the answer differs from `version`, the one it was made as.
#[derive(Clone, Copy)]
pub struct Reload<'a> {
    pub url: &'a str,
    pub version: u64,
}

/// Escapes text for HTML element content and quoted attributes.
pub fn escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
}

fn base64(bytes: &[u8]) -> String {
    base64::engine::general_purpose::STANDARD.encode(bytes)
}

fn data_uri(mime: &str, bytes: &[u8]) -> String {
    format!("data:{mime};base64,{}", base64(bytes))
}

fn human(bytes: u64) -> String {
    crate::memory::human(bytes)
}

fn mime_of(path: &Path) -> Option<&'static str> {
    match path.extension()?.to_str()?.to_ascii_lowercase().as_str() {
        "png" => Some("image/png"),
        "jpg" | "jpeg" => Some("image/jpeg"),
        _ => None,
    }
}

/// `bytes` (a PNG or JPEG) scaled so its longer side is at most `side`, as PNG; `None` when
/// it cannot be decoded.
fn scaled_png(bytes: &[u8], side: u32) -> Option<Vec<u8>> {
    let img = image::load_from_memory(bytes).ok()?;
    let img = if img.width().max(img.height()) > side {
        img.resize(side, side, image::imageops::FilterType::Triangle)
    } else {
        img
    };
    let mut out = std::io::Cursor::new(Vec::new());
    img.to_rgba8()
        .write_to(&mut out, image::ImageFormat::Png)
        .ok()?;
    Some(out.into_inner())
}

/// An `<img>` of an image file: inline as it is when small, scaled down otherwise.
fn image_tag(path: &Path, bytes: &[u8], alt: &str) -> String {
    let Some(mime) = mime_of(path) else {
        return String::new();
    };
    let src = if bytes.len() as u64 <= MAX_INLINE_PNG {
        data_uri(mime, bytes)
    } else {
        match scaled_png(bytes, SCALED_SIDE) {
            Some(png) => data_uri("image/png", &png),
            None => return format!("<p>{}: not shown (unreadable)</p>", escape(alt)),
        }
    };
    format!(
        "<img src=\"{src}\" alt=\"{}\" loading=\"lazy\">",
        escape(alt)
    )
}

/// The models of `glbs` (label, bytes) as one viewer and its data elements, ids prefixed by
/// `id`; models beyond `budget` bytes are named and left out.
fn viewer(id: &str, glbs: &[(String, Vec<u8>)], up: Option<[f32; 3]>, budget: &mut u64) -> String {
    let mut data = String::new();
    let mut models = Vec::new();
    let mut left_out = Vec::new();
    for (k, (label, bytes)) in glbs.iter().enumerate() {
        if bytes.len() as u64 > *budget {
            left_out.push(format!("{label} ({})", human(bytes.len() as u64)));
            continue;
        }
        *budget -= bytes.len() as u64;
        let data_id = format!("{id}-glb-{k}");
        let _ = writeln!(
            data,
            "<script type=\"application/octet-stream\" id=\"{data_id}\">{}</script>",
            base64(bytes)
        );
        let mut model = serde_json::json!({ "label": label, "data": data_id });
        if let Some(up) = up {
            model["up"] = serde_json::json!(up);
        }
        models.push(model);
    }
    let mut s = String::new();
    if !models.is_empty() {
        let _ = write!(
            s,
            "<div class=\"texsyn-viewer\" data-models=\"{}\"></div>\n{data}",
            escape(&serde_json::Value::Array(models).to_string())
        );
    }
    if !left_out.is_empty() {
        let _ = write!(
            s,
            "<p class=\"note\">Not in the 3D view (the page holds at most {} of models): {}</p>",
            human(MAX_MODELS_BYTES),
            escape(&left_out.join(", "))
        );
    }
    s
}

const STYLE: &str = r#"
body { font: 14px/1.45 system-ui, sans-serif; margin: 0 auto; max-width: 1400px; padding: 16px 24px; color: #222; }
h1 { font-size: 22px; } h2 { font-size: 18px; margin-top: 28px; border-bottom: 1px solid #ddd; }
pre { background: #f4f4f4; padding: 8px; overflow-x: auto; font-size: 12px; }
table { border-collapse: collapse; font-size: 13px; }
th, td { border: 1px solid #ccc; padding: 3px 8px; text-align: left; vertical-align: top; }
th { background: #eee; cursor: pointer; user-select: none; }
td.num { text-align: right; font-variant-numeric: tabular-nums; }
code, .hash { font-family: ui-monospace, monospace; font-size: 12px; }
.images { display: flex; flex-wrap: wrap; gap: 12px; }
.images figure { margin: 0; } .images img { max-width: 640px; max-height: 640px; border: 1px solid #ccc; image-rendering: auto; }
.images figcaption { font-size: 12px; color: #555; }
.dag-wrap { overflow-x: auto; }
svg.dag text { font: 11px ui-monospace, monospace; fill: #222; } svg.dag text.title { font-weight: bold; font-family: system-ui, sans-serif; font-size: 12px; }
svg.dag .edge { fill: none; stroke: #888; stroke-width: 1.3; }
svg.dag .node rect { stroke: #555; } svg.dag .ran rect { fill: #fde2b8; } svg.dag .cached rect { fill: #d5ecd4; }
svg.dag .file rect { fill: #e4e8f4; } svg.dag .missing rect { fill: #f6d0d0; }
.ok { color: #16651c; font-weight: bold; } .bad { color: #a11; font-weight: bold; } .note { color: #666; }
.gallery { display: flex; flex-wrap: wrap; gap: 10px; } .gallery a { text-decoration: none; color: inherit; width: 200px; }
.gallery img { width: 200px; border: 1px solid #ccc; display: block; } .gallery span { font-size: 12px; }
"#;

fn page(title: &str, body: &str, reload: Option<Reload<'_>>) -> String {
    let meta = reload
        .map(|r| {
            format!(
                "<meta name=\"texsyn-reload\" content=\"{}\" data-version=\"{}\">\n",
                escape(r.url),
                r.version
            )
        })
        .unwrap_or_default();
    format!(
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n\
         <meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n{meta}\
         <title>{}</title>\n<style>{STYLE}</style>\n</head>\n<body>\n{body}\n\
         <footer class=\"note\">Made by texsyn {}. 3D view: {} (MIT licence, see THREE_LICENSE in \
         texsyn's sources).</footer>\n\
         <script>{VIEWER_JS}</script>\n<script>{REPORT_JS}</script>\n</body>\n</html>\n",
        escape(title),
        env!("CARGO_PKG_VERSION"),
        escape(
            VENDORED
                .lines()
                .find(|l| l.starts_with("three "))
                .unwrap_or("three.js")
        )
    )
}

/// A page with a title and one message (HTML), e.g. while `watch` runs the config for the
/// first time, or when its last run failed.
pub fn message_page(title: &str, message_html: &str, reload: Option<Reload<'_>>) -> String {
    page(
        title,
        &format!("<h1>{}</h1>\n{message_html}", escape(title)),
        reload,
    )
}

fn status_word(s: NodeStatus) -> &'static str {
    match s {
        NodeStatus::Cached => "cached",
        NodeStatus::Ran => "ran",
    }
}

/// The DAG of a run: its input files and nodes, with what the run reported of each.
fn run_dag(dag: &Dag, reports: &[NodeReport]) -> String {
    let files = dag.files.len();
    let mut boxes = Vec::new();
    for f in &dag.files {
        let name = f
            .path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        boxes.push(dag_svg::Box {
            title: name,
            lines: vec![
                format!("input file, {}", human(f.bytes.len() as u64)),
                format!("hash {}", &f.hash.to_hex()[..16]),
            ],
            class: "file",
            tooltip: format!("{}\ncontent hash {}", f.path.display(), f.hash.to_hex()),
        });
    }
    let mut edges = Vec::new();
    for (i, node) in dag.nodes.iter().enumerate() {
        let report = reports.iter().find(|r| r.node == node.name);
        let (class, lines, tooltip) = match report {
            Some(r) => (
                status_word(r.status),
                vec![
                    format!("{} · {}", r.stage, status_word(r.status)),
                    format!("{:.3} s · {}", r.seconds, human(r.bytes)),
                    format!("key  {}", &r.key[..r.key.len().min(16)]),
                    format!("hash {}", &r.content_hash[..r.content_hash.len().min(16)]),
                ],
                format!(
                    "{} ({})\nkey {}\ncontent hash {}",
                    r.node, r.algorithm, r.key, r.content_hash
                ),
            ),
            None => (
                "missing",
                vec!["not resolved in this run".into()],
                node.name.clone(),
            ),
        };
        boxes.push(dag_svg::Box {
            title: node.name.clone(),
            lines,
            class,
            tooltip,
        });
        for input in &node.inputs {
            match *input {
                InputRef::Node(j) => edges.push((files + j, files + i)),
                InputRef::File(j) => edges.push((j, files + i)),
            }
        }
    }
    dag_svg::dag_svg(&boxes, &edges)
}

fn nodes_table(reports: &[NodeReport]) -> String {
    let mut s = String::from(
        "<table class=\"sortable\" id=\"nodes\"><thead><tr><th>node</th><th>stage</th>\
         <th>algorithm</th><th>status</th><th>seconds</th><th>bytes</th><th>key</th>\
         <th>content hash</th></tr></thead><tbody>\n",
    );
    for r in reports {
        let _ = writeln!(
            s,
            "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td class=\"num\">{:.3}</td>\
             <td class=\"num\" data-value=\"{}\">{}</td><td class=\"hash\">{}</td>\
             <td class=\"hash\">{}</td></tr>",
            escape(&r.node),
            r.stage,
            r.algorithm,
            status_word(r.status),
            r.seconds,
            r.bytes,
            human(r.bytes),
            escape(&r.key),
            escape(&r.content_hash)
        );
    }
    s + "</tbody></table>\n"
}

fn lock_html(lock: &LockStatus) -> String {
    match lock {
        LockStatus::Missing(p) => format!(
            "<p class=\"note\">No lock file ({}); <code>texsyn hashes CONFIG -o {}</code> writes \
             one.</p>",
            escape(&p.display().to_string()),
            escape(&p.display().to_string())
        ),
        LockStatus::OtherOverrides { path, sets } => format!(
            "<p class=\"note\">{} was made with other overrides ({}): it does not apply to \
             this run.</p>",
            escape(&path.display().to_string()),
            escape(&sets.join(" "))
        ),
        LockStatus::Verifies { path, entries } => format!(
            "<p><span class=\"ok\">verifies</span>: all {entries} entries of {} match this \
             run.</p>",
            escape(&path.display().to_string())
        ),
        LockStatus::Differs { path, lines } => {
            let mut s = format!(
                "<p><span class=\"bad\">differs</span> from {}:</p><ul>",
                escape(&path.display().to_string())
            );
            for l in lines {
                let _ = write!(s, "<li><code>{}</code></li>", escape(l));
            }
            s + "</ul>"
        }
        LockStatus::Unreadable { path, error } => format!(
            "<p><span class=\"bad\">unreadable</span>: {}: {}</p>",
            escape(&path.display().to_string()),
            escape(error)
        ),
    }
}

/// The outputs' images and models, read from `dir` (names from `outputs`).
fn outputs_html(id: &str, outputs: &[PathBuf], up: Option<[f32; 3]>, budget: &mut u64) -> String {
    let mut images = String::new();
    let mut glbs = Vec::new();
    let mut list = String::from(
        "<table class=\"sortable\" id=\"outputs\"><thead><tr><th>file</th><th>size</th></tr>\
         </thead><tbody>",
    );
    for path in outputs {
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let Ok(meta) = std::fs::metadata(path) else {
            let _ = write!(list, "<tr><td>{}</td><td>missing</td></tr>", escape(&name));
            continue;
        };
        let _ = write!(
            list,
            "<tr><td>{}</td><td class=\"num\" data-value=\"{}\">{}</td></tr>",
            escape(&name),
            meta.len(),
            human(meta.len())
        );
        // Only images and models are read (an OBJ may be hundreds of MB).
        let shown = mime_of(path).is_some() || path.extension().is_some_and(|e| e == "glb");
        let Some(bytes) = shown.then(|| std::fs::read(path).ok()).flatten() else {
            continue;
        };
        if mime_of(path).is_some() {
            let _ = write!(
                images,
                "<figure>{}<figcaption>{}</figcaption></figure>",
                image_tag(path, &bytes, &name),
                escape(&name)
            );
        } else if path.extension().is_some_and(|e| e == "glb") {
            let label = path
                .file_stem()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default();
            glbs.push((label, bytes));
        }
    }
    list += "</tbody></table>";
    let mut s = String::new();
    if !glbs.is_empty() {
        s += "<h3>3D view</h3><p class=\"note\">Drag to orbit, scroll to zoom, right-drag to \
              pan.</p>";
        s += &viewer(id, &glbs, up, budget);
    }
    if !images.is_empty() {
        let _ = write!(s, "<h3>Images</h3><div class=\"images\">{images}</div>");
    }
    s + "<h3>Files</h3>" + &list
}

/// A run's page.
pub fn run_page(v: &RunView<'_>) -> String {
    let mut b = String::new();
    let title = format!("texsyn: {}", v.config.display());
    let _ = writeln!(
        b,
        "<h1>{}</h1>\n<p>method <code>{}</code> · outputs in <code>{}</code> · run {:.3} s{}</p>",
        escape(&title),
        escape(v.method),
        escape(&v.out_dir.display().to_string()),
        v.seconds,
        v.peak_memory_bytes
            .map(|p| format!(" · peak memory {}", human(p)))
            .unwrap_or_default()
    );
    let ran = v
        .reports
        .iter()
        .filter(|r| r.status == NodeStatus::Ran)
        .count();
    let _ = writeln!(
        b,
        "<p>{} nodes: {ran} ran, {} cached. {} outputs: {} written, {} unchanged.</p>",
        v.reports.len(),
        v.reports.len() - ran,
        v.outputs.len(),
        v.outputs.iter().filter(|o| o.1).count(),
        v.outputs.iter().filter(|o| !o.1).count()
    );
    b += "<h2>Lock</h2>";
    b += &lock_html(&v.lock);
    b += "<h2>Config</h2>";
    if !v.sets.is_empty() {
        let _ = write!(
            b,
            "<p>Overrides: {}</p>",
            v.sets
                .iter()
                .map(|s| format!("<code>--set {}</code>", escape(s)))
                .collect::<Vec<_>>()
                .join(" ")
        );
    }
    let _ = write!(b, "<pre>{}</pre>", escape(v.config_text));
    b += "<h2>Pipeline</h2><p class=\"note\">Orange: computed in this run; green: found in \
          the cache; blue: input files. Hover a box for its full key and hash.</p>";
    let _ = write!(
        b,
        "<div class=\"dag-wrap\">{}</div>",
        run_dag(v.dag, v.reports)
    );
    b += &nodes_table(v.reports);
    b += "<h2>Inputs</h2><div class=\"images\">";
    for f in &v.dag.files {
        let name = f.path.display().to_string();
        if mime_of(&f.path).is_some() {
            let _ = write!(
                b,
                "<figure>{}<figcaption>{} ({})</figcaption></figure>",
                image_tag(&f.path, &f.bytes, &name),
                escape(&name),
                human(f.bytes.len() as u64)
            );
        } else {
            let _ = write!(
                b,
                "<figure><figcaption>{} ({})</figcaption></figure>",
                escape(&name),
                human(f.bytes.len() as u64)
            );
        }
    }
    b += "</div>";
    if let Some(scores) = &v.scores {
        let _ = write!(b, "<h2>Scores</h2><pre>{}</pre>", escape(scores));
    }
    b += "<h2>Outputs</h2>";
    let outputs: Vec<PathBuf> = v.outputs.iter().map(|o| o.0.clone()).collect();
    let mut budget = MAX_MODELS_BYTES;
    b += &outputs_html("run", &outputs, v.up, &mut budget);
    page(&title, &b, v.reload)
}

/// The preview a sweep's gallery shows for a point's output folder: `preview.png`, else the
/// first PNG by name.
fn point_preview(out: &Path) -> Option<PathBuf> {
    let preview = out.join("preview.png");
    if preview.is_file() {
        return Some(preview);
    }
    let mut pngs: Vec<PathBuf> = std::fs::read_dir(out)
        .ok()?
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == "png"))
        .collect();
    pngs.sort();
    pngs.into_iter().next()
}

/// A sweep's page, from its folder (what `texsyn sweep` left there).
pub fn sweep_page(sweep: &Sweep, dir: &SweepDir, reload: Option<Reload<'_>>) -> String {
    // A point whose run left no report of its own but a log failed: its log's last error.
    let failures = sweep
        .points
        .iter()
        .filter(|p| {
            RunReport::read(&dir.report(p))
                .filter(|r| r.sets == p.sets)
                .is_none()
        })
        .filter_map(|p| {
            let log = dir.log(p);
            log.is_file().then(|| {
                let why = crate::ops::sweep::local::last_error(&log)
                    .unwrap_or_else(|| "it wrote no report".into());
                (p.index, format!("{why} (log: {})", log.display()))
            })
        })
        .collect();
    let table = Table::collect(sweep, dir, &failures);
    let title = format!("texsyn sweep: {}", sweep.path.display());
    let mut b = format!(
        "<h1>{}</h1>\n<p>base config <code>{}</code> · {} points · folder <code>{}</code></p>",
        escape(&title),
        escape(&sweep.base.display().to_string()),
        table.rows.len(),
        escape(&dir.root.display().to_string())
    );
    // Gallery.
    b += "<h2>Gallery</h2><div class=\"gallery\">";
    for (row, point) in table.rows.iter().zip(&sweep.points) {
        // Only a point that ran shows its folder: after a failure it holds an older run's.
        let thumb = (row.state == "ok")
            .then(|| point_preview(&row.out))
            .flatten()
            .and_then(|p| std::fs::read(p).ok())
            .and_then(|bytes| scaled_png(&bytes, 200));
        let img = match thumb {
            Some(png) => format!("<img src=\"{}\" alt=\"\">", data_uri("image/png", &png)),
            None => format!("<div class=\"note\">no preview ({})</div>", row.state),
        };
        let _ = write!(
            b,
            "<a href=\"#point-{:03}\">{img}<span>{:03} · {}</span></a>",
            row.index,
            row.index,
            escape(&point.label())
        );
    }
    b += "</div>";
    // Results table, with a filter per axis.
    let score_columns: Vec<String> = {
        let mut cols: Vec<String> = Vec::new();
        for row in &table.rows {
            for (c, _) in &row.scores {
                if !cols.contains(c) {
                    cols.push(c.clone());
                }
            }
        }
        cols
    };
    b += "<h2>Results</h2><p>";
    for (a, axis) in table.axes.iter().enumerate() {
        let mut values: Vec<String> = table
            .rows
            .iter()
            .filter_map(|r| r.values.get(a).map(|v| v.1.clone()))
            .collect();
        values.dedup();
        values.sort();
        values.dedup();
        let _ = write!(
            b,
            "<label>{} <select class=\"filter\" data-table=\"results\" data-column=\"{}\">\
             <option value=\"\">all</option>",
            escape(axis),
            a + 1
        );
        for v in values {
            let _ = write!(b, "<option>{}</option>", escape(&v));
        }
        b += "</select></label> ";
    }
    b += "</p><table class=\"sortable\" id=\"results\"><thead><tr><th>point</th>";
    for axis in &table.axes {
        let _ = write!(b, "<th>{}</th>", escape(axis));
    }
    b += "<th>state</th><th>seconds</th><th>peak memory</th>";
    for c in &score_columns {
        let _ = write!(b, "<th>{}</th>", escape(c));
    }
    b += "</tr></thead><tbody>\n";
    for row in &table.rows {
        let _ = write!(
            b,
            "<tr><td data-value=\"{}\"><a href=\"#point-{:03}\">{:03}</a></td>",
            row.index, row.index, row.index
        );
        for (_, v) in &row.values {
            let _ = write!(b, "<td>{}</td>", escape(v));
        }
        let _ = write!(b, "<td>{}</td>", escape(&row.state));
        match row.seconds {
            Some(s) => {
                let _ = write!(b, "<td class=\"num\" data-value=\"{s}\">{s:.2}</td>");
            }
            None => b += "<td data-value=\"\">—</td>",
        }
        match row.peak_memory_bytes {
            Some(p) => {
                let _ = write!(b, "<td class=\"num\" data-value=\"{p}\">{}</td>", human(p));
            }
            None => b += "<td data-value=\"\">—</td>",
        }
        for c in &score_columns {
            match row.scores.iter().find(|(k, _)| k == c) {
                Some((_, v)) => {
                    let _ = write!(b, "<td class=\"num\" data-value=\"{v}\">{v:.3}</td>");
                }
                None => b += "<td data-value=\"\">—</td>",
            }
        }
        b += "</tr>\n";
    }
    b += "</tbody></table>";
    // One section per point.
    b += "<h2>Points</h2>";
    let mut budget = MAX_MODELS_BYTES;
    for (row, point) in table.rows.iter().zip(&sweep.points) {
        let _ = write!(
            b,
            "<section id=\"point-{:03}\"><h3>{:03}: {}</h3><p>state {} · folder <code>{}</code>{}</p>",
            row.index,
            row.index,
            escape(&point.label()),
            escape(&row.state),
            escape(&row.out.display().to_string()),
            row.error
                .as_ref()
                .map(|e| format!(" · <span class=\"bad\">{}</span>", escape(e)))
                .unwrap_or_default()
        );
        let _ = write!(
            b,
            "<p>overrides: {}</p>",
            point
                .sets
                .iter()
                .map(|s| format!("<code>--set {}</code>", escape(s)))
                .collect::<Vec<_>>()
                .join(" ")
        );
        if let Some(report) = RunReport::read(&dir.report(point))
            .filter(|r| r.sets == point.sets && row.state == "ok")
        {
            b += "<table><thead><tr><th>node</th><th>stage</th><th>status</th><th>seconds</th>\
                  <th>content hash</th></tr></thead><tbody>";
            for n in &report.nodes {
                let _ = write!(
                    b,
                    "<tr><td>{}</td><td>{}</td><td>{}</td><td class=\"num\">{:.3}</td>\
                     <td class=\"hash\">{}</td></tr>",
                    escape(&n.node),
                    escape(&n.stage),
                    escape(&n.status),
                    n.seconds,
                    escape(&n.content_hash)
                );
            }
            b += "</tbody></table>";
            // The report's paths are relative to where `sweep` ran: take the names only.
            let outputs: Vec<PathBuf> = report
                .outputs
                .iter()
                .filter_map(|o| o.path.file_name().map(|n| row.out.join(n)))
                .collect();
            let _ = write!(
                b,
                "<details><summary>outputs, previews and 3D view</summary>{}</details>",
                outputs_html(
                    &format!("p{:03}", row.index),
                    &outputs,
                    sweep.point_config(point).ok().and_then(|c| preview_up(&c)),
                    &mut budget
                )
            );
        }
        b += "<p><a href=\"#results\">back to the table</a></p></section>";
    }
    page(&title, &b, reload)
}
