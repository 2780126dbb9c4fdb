//! The results table of a sweep: one row per point, written as CSV, Markdown and JSON into the
//! sweep's folder (`results.csv`, `results.md`, `results.json`).
//!
//! A row holds the point's axis values, whether it ran, each node's status (cached or ran) and
//! content hash, seconds per stage, the run's peak memory, its output folder and, when the
//! base config asks for scores (`[score]`), the scores of `texsyn score`. Rows are made from
//! the points' run reports, so the table is the same whichever executor ran them.

use super::{Point, RunReport, Sweep, SweepDir};
use serde::Serialize;
use std::path::PathBuf;

/// One point's row.
#[derive(Debug, Clone, Serialize)]
pub struct Row {
    pub index: usize,
    /// (axis key, value as written).
    pub values: Vec<(String, String)>,
    /// "ok", "failed" or "missing" (never run, or its report is gone).
    pub state: String,
    /// Why it failed, and where its log is.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    pub out: PathBuf,
    /// (node, "ran" or "cached"), in the pipeline's order.
    pub nodes: Vec<(String, String)>,
    /// (node, content hash).
    pub hashes: Vec<(String, String)>,
    /// (stage, seconds): the sum over the stage's nodes, in the pipeline's order.
    pub stage_seconds: Vec<(String, f64)>,
    pub seconds: Option<f64>,
    /// A sharded point's shards: their seconds, summed (they may have run side by side), and
    /// their largest peak memory.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub shard_seconds: Option<f64>,
    pub peak_memory_bytes: Option<u64>,
    /// (column, value): each scored output's ratio, coverage and gradient ratio.
    pub scores: Vec<(String, f64)>,
}

/// The whole table.
#[derive(Debug, Clone, Serialize)]
pub struct Table {
    pub sweep: PathBuf,
    pub base: PathBuf,
    pub axes: Vec<String>,
    pub rows: Vec<Row>,
}

/// A point that did not produce a report: its error text.
pub type Failures = std::collections::HashMap<usize, String>;

impl Table {
    /// The table of every point of `sweep`, from the reports in `dir`.
    pub fn collect(sweep: &Sweep, dir: &SweepDir, failures: &Failures) -> Table {
        let rows = sweep
            .points
            .iter()
            .map(|p| row(p, dir, failures.get(&p.index), sweep.shards.unwrap_or(1)))
            .collect();
        Table {
            sweep: sweep.path.clone(),
            base: sweep.base.clone(),
            axes: sweep.axes.iter().map(|a| a.key.clone()).collect(),
            rows,
        }
    }

    pub fn failed(&self) -> impl Iterator<Item = &Row> {
        self.rows.iter().filter(|r| r.state != "ok")
    }

    /// Every column name beyond the axes, in a stable order: node statuses, stage seconds,
    /// the totals, scores, hashes.
    fn columns(&self) -> Columns {
        let mut c = Columns::default();
        for r in &self.rows {
            for (n, _) in &r.nodes {
                push_unique(&mut c.nodes, n);
            }
            for (s, _) in &r.stage_seconds {
                push_unique(&mut c.stages, s);
            }
            for (s, _) in &r.scores {
                push_unique(&mut c.scores, s);
            }
        }
        c
    }

    pub fn to_csv(&self) -> String {
        let c = self.columns();
        let mut header: Vec<String> = vec!["point".into()];
        header.extend(self.axes.iter().cloned());
        header.push("state".into());
        header.extend(c.nodes.iter().map(|n| format!("{n} status")));
        header.extend(c.stages.iter().map(|s| format!("{s} seconds")));
        header.push("seconds".into());
        header.push("shard seconds".into());
        header.push("peak memory bytes".into());
        header.extend(c.scores.iter().cloned());
        header.extend(c.nodes.iter().map(|n| format!("{n} hash")));
        header.push("output folder".into());
        header.push("error".into());
        let mut s = csv_line(&header);
        for r in &self.rows {
            let mut f: Vec<String> = vec![r.index.to_string()];
            f.extend(r.values.iter().map(|(_, v)| v.clone()));
            f.push(r.state.clone());
            f.extend(
                c.nodes
                    .iter()
                    .map(|n| lookup(&r.nodes, n).unwrap_or_default()),
            );
            f.extend(
                c.stages
                    .iter()
                    .map(|st| lookup_f(&r.stage_seconds, st).map(secs).unwrap_or_default()),
            );
            f.push(r.seconds.map(secs).unwrap_or_default());
            f.push(r.shard_seconds.map(secs).unwrap_or_default());
            f.push(
                r.peak_memory_bytes
                    .map(|b| b.to_string())
                    .unwrap_or_default(),
            );
            f.extend(
                c.scores
                    .iter()
                    .map(|k| lookup_f(&r.scores, k).map(score).unwrap_or_default()),
            );
            f.extend(
                c.nodes
                    .iter()
                    .map(|n| lookup(&r.hashes, n).unwrap_or_default()),
            );
            f.push(r.out.display().to_string());
            f.push(r.error.clone().unwrap_or_default());
            s += &csv_line(&f);
        }
        s
    }

    /// The Markdown table: hashes shortened to 12 digits (the CSV and JSON hold them whole),
    /// node statuses as a count of nodes that ran.
    pub fn to_markdown(&self) -> String {
        let c = self.columns();
        let mut header: Vec<String> = vec!["point".into()];
        header.extend(self.axes.iter().map(|a| format!("`{a}`")));
        header.push("state".into());
        header.push("ran / cached".into());
        header.extend(c.stages.iter().map(|s| format!("{s} s")));
        header.push("total s".into());
        let sharded = self.rows.iter().any(|r| r.shard_seconds.is_some());
        if sharded {
            header.push("shards s".into());
        }
        header.push("peak memory".into());
        header.extend(c.scores.iter().cloned());
        let last = c.nodes.last().cloned();
        if let Some(n) = &last {
            header.push(format!("{n} hash"));
        }
        header.push("outputs".into());
        let mut s = format!(
            "Sweep `{}` over `{}`: {} points.\n\n",
            self.sweep.display(),
            self.base.display(),
            self.rows.len()
        );
        s += &format!("| {} |\n", header.join(" | "));
        s += &format!(
            "|{}\n",
            header
                .iter()
                .enumerate()
                .map(|(i, _)| if i == 0 { "---:|" } else { "---|" })
                .collect::<String>()
        );
        for r in &self.rows {
            let ran = r.nodes.iter().filter(|(_, st)| st == "ran").count();
            let mut f: Vec<String> = vec![r.index.to_string()];
            f.extend(r.values.iter().map(|(_, v)| md_escape(v)));
            f.push(match &r.error {
                Some(e) => format!("{}: {}", r.state, md_escape(e)),
                None => r.state.clone(),
            });
            f.push(if r.nodes.is_empty() {
                String::new()
            } else {
                format!("{ran} / {}", r.nodes.len() - ran)
            });
            f.extend(
                c.stages
                    .iter()
                    .map(|st| lookup_f(&r.stage_seconds, st).map(secs).unwrap_or_default()),
            );
            f.push(r.seconds.map(secs).unwrap_or_default());
            if sharded {
                f.push(r.shard_seconds.map(secs).unwrap_or_default());
            }
            f.push(
                r.peak_memory_bytes
                    .map(crate::memory::human)
                    .unwrap_or_default(),
            );
            f.extend(
                c.scores
                    .iter()
                    .map(|k| lookup_f(&r.scores, k).map(score).unwrap_or_default()),
            );
            if let Some(n) = &last {
                f.push(
                    lookup(&r.hashes, n)
                        .map(|h| format!("`{}`", &h[..h.len().min(12)]))
                        .unwrap_or_default(),
                );
            }
            f.push(format!("`{}`", r.out.display()));
            s += &format!("| {} |\n", f.join(" | "));
        }
        s
    }
}

#[derive(Default)]
struct Columns {
    nodes: Vec<String>,
    stages: Vec<String>,
    scores: Vec<String>,
}

fn push_unique(v: &mut Vec<String>, s: &str) {
    if !v.iter().any(|x| x == s) {
        v.push(s.to_owned());
    }
}

fn lookup(v: &[(String, String)], k: &str) -> Option<String> {
    v.iter().find(|(x, _)| x == k).map(|(_, y)| y.clone())
}

fn lookup_f(v: &[(String, f64)], k: &str) -> Option<f64> {
    v.iter().find(|(x, _)| x == k).map(|(_, y)| *y)
}

fn secs(x: f64) -> String {
    format!("{x:.3}")
}

fn score(x: f64) -> String {
    if x.is_finite() {
        format!("{x:.4}")
    } else {
        "inf".into()
    }
}

fn md_escape(s: &str) -> String {
    s.replace('|', "\\|").replace('\n', " ")
}

/// One CSV record (RFC 4180: fields with a comma, quote or line break are quoted).
fn csv_line(fields: &[String]) -> String {
    let quoted: Vec<String> = fields
        .iter()
        .map(|f| {
            if f.contains([',', '"', '\n', '\r']) {
                format!("\"{}\"", f.replace('"', "\"\""))
            } else {
                f.clone()
            }
        })
        .collect();
    quoted.join(",") + "\n"
}

fn row(point: &Point, dir: &SweepDir, failure: Option<&String>, shards: u32) -> Row {
    let values = point
        .values
        .iter()
        .map(|(k, v)| {
            let shown = match v {
                toml::Value::String(s) => s.clone(),
                other => other.to_string(),
            };
            (k.clone(), shown)
        })
        .collect();
    let report = RunReport::read(&dir.report(point)).filter(|r| r.sets == point.sets);
    let mut row = Row {
        index: point.index,
        values,
        state: "missing".into(),
        error: failure.cloned(),
        out: dir.point_out(point),
        nodes: Vec::new(),
        hashes: Vec::new(),
        stage_seconds: Vec::new(),
        seconds: None,
        shard_seconds: None,
        peak_memory_bytes: None,
        scores: Vec::new(),
    };
    if failure.is_some() {
        row.state = "failed".into();
        return row;
    }
    let Some(report) = report else {
        return row;
    };
    row.state = "ok".into();
    for n in &report.nodes {
        row.nodes.push((n.node.clone(), n.status.clone()));
        row.hashes.push((n.node.clone(), n.content_hash.clone()));
        match row.stage_seconds.iter_mut().find(|(s, _)| *s == n.stage) {
            Some((_, t)) => *t += n.seconds,
            None => row.stage_seconds.push((n.stage.clone(), n.seconds)),
        }
    }
    row.seconds = Some(report.seconds);
    row.peak_memory_bytes = report.peak_memory_bytes;
    let shards: Vec<RunReport> = (0..shards)
        .filter(|_| shards > 1)
        .filter_map(|i| RunReport::read(&dir.shard_report(point, i)))
        .filter(|r| r.sets == point.sets)
        .collect();
    if !shards.is_empty() {
        row.shard_seconds = Some(shards.iter().map(|r| r.seconds).sum());
        row.peak_memory_bytes = shards
            .iter()
            .filter_map(|r| r.peak_memory_bytes)
            .chain(row.peak_memory_bytes)
            .max();
    }
    if let Some(scores) = &report.scores {
        row.scores = score_columns(scores);
    }
    row
}

/// The numbers of a `texsyn score` report as columns: `<output> ratio`, `… coverage`,
/// `… gradient ratio`, each numeric extra (`<output> <name>`) and each number of an extra
/// that groups them (`<output> <name> <member>`).
fn score_columns(report: &serde_json::Value) -> Vec<(String, f64)> {
    let mut out = Vec::new();
    let Some(items) = report.get("items").and_then(|v| v.as_array()) else {
        return out;
    };
    for item in items {
        let name = item
            .get("output")
            .and_then(|v| v.as_str())
            .unwrap_or("output");
        if let Some(sc) = item.get("score").filter(|s| !s.is_null()) {
            for (field, label) in [
                ("ratio", "ratio"),
                ("coverage", "coverage"),
                ("gradient_ratio", "gradient ratio"),
            ] {
                if let Some(x) = sc.get(field).and_then(|v| v.as_f64()) {
                    out.push((format!("{name} {label}"), x));
                }
            }
        }
        if let Some(extra) = item.get("extra").and_then(|v| v.as_object()) {
            for (k, v) in extra {
                if let Some(x) = v.as_f64() {
                    out.push((format!("{name} {k}"), x));
                } else if let Some(members) = v.as_object() {
                    // One level of grouped numbers, e.g. the surface row's `floor`.
                    for (m, x) in members {
                        if let Some(x) = x.as_f64() {
                            out.push((format!("{name} {k} {}", m.replace('_', " ")), x));
                        }
                    }
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_quotes_fields_with_commas_quotes_and_line_breaks() {
        let line = csv_line(&["a".into(), "b,c".into(), "say \"hi\"".into(), "x\ny".into()]);
        assert_eq!(line, "a,\"b,c\",\"say \"\"hi\"\"\",\"x\ny\"\n");
    }

    #[test]
    fn score_columns_name_the_output_and_the_measure() {
        let report = serde_json::json!({"items": [
            {"output": "texture.png", "score": {"ratio": 0.5, "coverage": 0.25, "gradient_ratio": 0.75}, "extra": {"seams": 2.0, "note": "x", "floor": {"gradient_ratio": 0.125, "what": "y"}}},
            {"output": "other.png", "score": null}
        ]});
        let cols = score_columns(&report);
        let names: Vec<&str> = cols.iter().map(|(k, _)| k.as_str()).collect();
        assert_eq!(
            names,
            [
                "texture.png ratio",
                "texture.png coverage",
                "texture.png gradient ratio",
                "texture.png floor gradient ratio",
                "texture.png seams"
            ]
        );
        assert_eq!(cols[1].1, 0.25);
        assert_eq!(cols[3].1, 0.125);
    }
}
