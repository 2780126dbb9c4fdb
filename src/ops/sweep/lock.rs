//! Sweep lock files: every point's lock (`node key content-hash` lines, as in
//! [`crate::ops::lockfile`]) under a heading naming the point, so a paper's whole table is checked
//! with one `texsyn verify SWEEP.toml SWEEP.lock`.
//!
//! ```text
//! # texsyn sweep lock: …
//! [point 0: synthesize.seed=1]
//! import.mesh <key> <content hash>
//! …
//! [point 1: synthesize.seed=2]
//! …
//! ```
//!
//! The heading's label is the point's axis values as the sweep file writes them: `verify`
//! re-derives the points from the sweep file and refuses a lock whose points are not the
//! sweep's (a sweep edited after its lock was written).

use super::{Point, RunReport, Sweep, SweepDir};
use crate::ops::lockfile::{LockEntry, LockError, LockFile};
use std::path::Path;

pub const HEADER: &str = "# texsyn sweep lock: per point, node, key, content hash (written by `texsyn sweep` and `texsyn hashes SWEEP.toml`)\n";

/// One point's section.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PointLock {
    pub index: usize,
    pub label: String,
    pub lock: LockFile,
}

#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct SweepLock {
    pub points: Vec<PointLock>,
}

impl SweepLock {
    /// Whether lock-file text is a sweep lock (its first line).
    pub fn is_sweep_lock(text: &str) -> bool {
        text.starts_with(HEADER.trim_end())
    }

    pub fn read(path: &Path) -> Result<SweepLock, LockError> {
        Self::parse(&crate::ops::lockfile::read_text(path)?, path)
    }

    pub fn parse(text: &str, path: &Path) -> Result<SweepLock, LockError> {
        let mut points: Vec<PointLock> = Vec::new();
        // (index, label, first line number, text of the section)
        let mut current: Option<(usize, String, usize, String)> = None;
        let finish = |c: Option<(usize, String, usize, String)>,
                      points: &mut Vec<PointLock>|
         -> Result<(), LockError> {
            if let Some((index, label, first, body)) = c {
                let lock = LockFile::parse(&body, path).map_err(|e| match e {
                    LockError::Line { path, line, what } => LockError::Line {
                        path,
                        line: line + first,
                        what,
                    },
                    e => e,
                })?;
                points.push(PointLock { index, label, lock });
            }
            Ok(())
        };
        for (i, line) in text.lines().enumerate() {
            let t = line.trim();
            if let Some(head) = t.strip_prefix("[point ").and_then(|h| h.strip_suffix(']')) {
                finish(current.take(), &mut points)?;
                let (n, label) = head.split_once(':').unwrap_or((head, ""));
                let index: usize = n.trim().parse().map_err(|_| LockError::Line {
                    path: path.to_owned(),
                    line: i + 1,
                    what: format!("expected `[point N: values]`, found {t:?}"),
                })?;
                if points.iter().any(|p| p.index == index) {
                    return Err(LockError::Line {
                        path: path.to_owned(),
                        line: i + 1,
                        what: format!("point {index} is locked twice"),
                    });
                }
                current = Some((index, label.trim().to_owned(), i + 1, String::new()));
                continue;
            }
            match &mut current {
                Some((_, _, _, body)) => {
                    body.push_str(line);
                    body.push('\n');
                }
                None if t.is_empty() || t.starts_with('#') => {}
                None => {
                    return Err(LockError::Line {
                        path: path.to_owned(),
                        line: i + 1,
                        what: "an artifact line before the first `[point N: values]` heading"
                            .into(),
                    });
                }
            }
        }
        finish(current.take(), &mut points)?;
        Ok(SweepLock { points })
    }

    pub fn to_text(&self, sweep: &Path) -> String {
        let mut s = String::from(HEADER);
        s += &format!("# sweep: {}\n", sweep.display());
        for p in &self.points {
            s += &format!("[point {}: {}]\n", p.index, p.label);
            for e in &p.lock.entries {
                s += &format!("{} {} {}\n", e.node, e.key, e.content_hash);
            }
        }
        s
    }

    /// The lock of every point that has a report in `dir`; `None` when a point has none (the
    /// sweep is not complete).
    pub fn of_reports(sweep: &Sweep, dir: &SweepDir) -> Option<SweepLock> {
        let mut points = Vec::new();
        for p in &sweep.points {
            let r = RunReport::read(&dir.report(p)).filter(|r| r.sets == p.sets)?;
            points.push(PointLock {
                index: p.index,
                label: p.label(),
                lock: LockFile {
                    sets: Vec::new(),
                    entries: r
                        .nodes
                        .iter()
                        .map(|n| LockEntry {
                            node: n.node.clone(),
                            key: n.key.clone(),
                            content_hash: n.content_hash.clone(),
                        })
                        .collect(),
                },
            });
        }
        Some(SweepLock { points })
    }

    /// The section of `point`, checked against the sweep: an error when the lock's point of
    /// that number has other values (the sweep was edited after the lock was written).
    pub fn section(&self, point: &Point) -> Result<&PointLock, String> {
        let label = point.label();
        match self.points.iter().find(|p| p.index == point.index) {
            None => Err(format!(
                "point {} ({label}) is not in the lock file",
                point.index
            )),
            Some(p) if p.label != label => Err(format!(
                "point {} is {label} in the sweep but {} in the lock file (the sweep changed \
                 after its lock was written)",
                point.index, p.label
            )),
            Some(p) => Ok(p),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const H: &str = "0000000000000000000000000000000000000000000000000000000000000000";

    #[test]
    fn text_round_trips_and_sections_keep_their_labels() {
        let entry = |n: &str| LockEntry {
            node: n.into(),
            key: H.into(),
            content_hash: H.replace('0', "a"),
        };
        let lock = SweepLock {
            points: vec![
                PointLock {
                    index: 0,
                    label: "synthesize.seed=1".into(),
                    lock: LockFile {
                        sets: vec![],
                        entries: vec![entry("import.mesh"), entry("synthesize")],
                    },
                },
                PointLock {
                    index: 1,
                    label: "synthesize.seed=2".into(),
                    lock: LockFile {
                        sets: vec![],
                        entries: vec![entry("synthesize")],
                    },
                },
            ],
        };
        let text = lock.to_text(Path::new("s.toml"));
        assert!(SweepLock::is_sweep_lock(&text));
        assert_eq!(SweepLock::parse(&text, Path::new("s.lock")).unwrap(), lock);
    }

    #[test]
    fn bad_lines_name_their_line_in_the_whole_file() {
        let text = format!("{HEADER}[point 0: a=1]\nnode {H} {H}\nbroken line\n");
        let e = SweepLock::parse(&text, Path::new("s.lock"))
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("s.lock:4:"), "{e}");
        let text = format!("{HEADER}[point 0: a=1]\n[point 0: a=1]\n");
        let e = SweepLock::parse(&text, Path::new("s.lock"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("locked twice"), "{e}");
    }
}
