//! Lock files: one line per artifact, `node key content-hash`, written by `texsyn hashes` and
//! checked by `texsyn verify` (README, "Commands").
//!
//! A key hashes a node's parameters, its inputs' content hashes and its algorithm's code
//! version; the content hash hashes what the node produced. So a difference in the content
//! hash under an unchanged key means the code now computes something else for the same
//! inputs without its version saying so (or that the result depends on the machine): such a
//! line is named apart from an ordinary mismatch, and `hashes -o` will not overwrite it unless
//! asked.

use crate::pipeline::NodeReport;
use std::fmt;
use std::path::{Path, PathBuf};

/// The first line `hashes` writes.
pub const HEADER: &str =
    "# texsyn lock file: node, key, content hash (written by `texsyn hashes`)\n";

/// One locked artifact.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LockEntry {
    pub node: String,
    pub key: String,
    pub content_hash: String,
}

/// A parsed lock file, entries in file order.
#[derive(Clone, Debug, PartialEq, Eq, Default)]
pub struct LockFile {
    /// The `--set` overrides the hashes were made with (`# set: KEY=VALUE` lines): `verify`
    /// applies them before the command line's own, so a companion lock of a config at small
    /// settings (`configs/cpu/`) verifies with no flags beyond the config and the lock.
    pub sets: Vec<String>,
    pub entries: Vec<LockEntry>,
}

/// The comment prefix of a recorded `--set` override.
const SET_PREFIX: &str = "# set: ";

#[derive(Debug, thiserror::Error)]
pub enum LockError {
    #[error("reading lock file {path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("lock file {path} is not UTF-8 text (byte {byte})")]
    NotText { path: PathBuf, byte: usize },
    #[error("{path}:{line}: {what}")]
    Line {
        path: PathBuf,
        line: usize,
        what: String,
    },
}

/// How a run differs from a lock file, per artifact.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Difference {
    /// The lock names a node this config does not produce.
    NotProduced { node: String },
    /// This config produces a node the lock does not name.
    NotLocked { node: String },
    /// The key differs: parameters, inputs or a code version changed (the content may too).
    KeyChanged {
        node: String,
        locked: LockEntry,
        now: LockEntry,
    },
    /// Same key, other content: the output changed and the node's version was not bumped (or
    /// the result depends on the machine).
    ContentChangedUnderSameKey {
        node: String,
        locked: String,
        now: String,
    },
}

impl Difference {
    /// `key unchanged, content changed`: the case a version bump should have prevented.
    pub fn is_unbumped(&self) -> bool {
        matches!(self, Difference::ContentChangedUnderSameKey { .. })
    }
}

impl fmt::Display for Difference {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Difference::NotProduced { node } => {
                write!(
                    f,
                    "{node}: in the lock file but not produced by this config"
                )
            }
            Difference::NotLocked { node } => {
                write!(
                    f,
                    "{node}: produced by this config but missing from the lock file"
                )
            }
            Difference::KeyChanged { node, locked, now } => {
                write!(
                    f,
                    "{node}: key {} differs from the locked {} (parameters, inputs or code \
                     version changed)",
                    now.key, locked.key
                )?;
                if now.content_hash != locked.content_hash {
                    write!(
                        f,
                        "; content hash {} differs from the locked {}",
                        now.content_hash, locked.content_hash
                    )?;
                }
                Ok(())
            }
            Difference::ContentChangedUnderSameKey { node, locked, now } => write!(
                f,
                "{node}: key unchanged, content changed: version not bumped (content hash {now} \
                 differs from the locked {locked} under the same key; the node's code changed \
                 without a version bump, or its result depends on the machine)"
            ),
        }
    }
}

/// A lock file's text (a regular file of UTF-8: a FIFO or device is refused, not read).
pub fn read_text(path: &Path) -> Result<String, LockError> {
    let bytes = crate::geom::io::read_regular_file(path).map_err(|source| LockError::Io {
        path: path.to_owned(),
        source,
    })?;
    String::from_utf8(bytes).map_err(|e| LockError::NotText {
        path: path.to_owned(),
        byte: e.utf8_error().valid_up_to(),
    })
}

/// A 64-digit lowercase hex string (a blake3 hash as texsyn prints it).
fn is_hash(s: &str) -> bool {
    s.len() == 64 && s.bytes().all(|b| matches!(b, b'0'..=b'9' | b'a'..=b'f'))
}

impl LockFile {
    /// Reads and parses `path` (a regular file: a FIFO or device is refused, not read).
    pub fn read(path: &Path) -> Result<LockFile, LockError> {
        LockFile::parse(&read_text(path)?, path)
    }

    /// Parses lock-file text; `path` only names the file in errors. Blank lines and `#`
    /// comments are skipped; every other line is `node key content-hash`, each node once.
    pub fn parse(text: &str, path: &Path) -> Result<LockFile, LockError> {
        let mut entries: Vec<LockEntry> = Vec::new();
        let mut sets = Vec::new();
        for (i, line) in text.lines().enumerate() {
            let bad = |what: String| LockError::Line {
                path: path.to_owned(),
                line: i + 1,
                what,
            };
            let line = line.trim();
            if let Some(set) = line.strip_prefix(SET_PREFIX) {
                let set = set.trim();
                if !set.contains('=') {
                    return Err(bad(format!(
                        "recorded override {set:?} is not STAGE.KEY=VALUE"
                    )));
                }
                sets.push(set.to_owned());
                continue;
            }
            if line.is_empty() || line.starts_with('#') {
                continue;
            }
            let f: Vec<&str> = line.split_whitespace().collect();
            if f.len() != 3 || !is_hash(f[1]) || !is_hash(f[2]) {
                let shown: String = line.chars().take(200).collect();
                return Err(bad(format!(
                    "expected `node key content-hash` (two 64-digit hex hashes), found {shown:?}"
                )));
            }
            if entries.iter().any(|e| e.node == f[0]) {
                return Err(bad(format!("node {} is locked twice", f[0])));
            }
            entries.push(LockEntry {
                node: f[0].to_owned(),
                key: f[1].to_owned(),
                content_hash: f[2].to_owned(),
            });
        }
        Ok(LockFile { sets, entries })
    }

    /// The lock file of a run's reports, made with the `sets` overrides.
    pub fn of_reports(reports: &[NodeReport], sets: &[String]) -> LockFile {
        LockFile {
            sets: sets.to_vec(),
            entries: reports
                .iter()
                .map(|r| LockEntry {
                    node: r.node.clone(),
                    key: r.key.clone(),
                    content_hash: r.content_hash.clone(),
                })
                .collect(),
        }
    }

    /// The text `hashes` writes.
    pub fn to_text(&self) -> String {
        let mut s = String::from(HEADER);
        for set in &self.sets {
            s += &format!("{SET_PREFIX}{set}\n");
        }
        for e in &self.entries {
            s += &format!("{} {} {}\n", e.node, e.key, e.content_hash);
        }
        s
    }

    /// Every difference between this lock and `now` (another lock, usually of a run): the
    /// lock's entries in order, then nodes only `now` has.
    pub fn compare(&self, now: &LockFile) -> Vec<Difference> {
        let mut out = Vec::new();
        for locked in &self.entries {
            match now.entries.iter().find(|e| e.node == locked.node) {
                None => out.push(Difference::NotProduced {
                    node: locked.node.clone(),
                }),
                Some(e) if e.key != locked.key => out.push(Difference::KeyChanged {
                    node: locked.node.clone(),
                    locked: locked.clone(),
                    now: e.clone(),
                }),
                Some(e) if e.content_hash != locked.content_hash => {
                    out.push(Difference::ContentChangedUnderSameKey {
                        node: locked.node.clone(),
                        locked: locked.content_hash.clone(),
                        now: e.content_hash.clone(),
                    })
                }
                Some(_) => {}
            }
        }
        for e in &now.entries {
            if !self.entries.iter().any(|l| l.node == e.node) {
                out.push(Difference::NotLocked {
                    node: e.node.clone(),
                });
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn h(c: char) -> String {
        std::iter::repeat_n(c, 64).collect()
    }

    fn lock(lines: &[(&str, char, char)]) -> LockFile {
        LockFile {
            sets: vec![],
            entries: lines
                .iter()
                .map(|&(n, k, c)| LockEntry {
                    node: n.into(),
                    key: h(k),
                    content_hash: h(c),
                })
                .collect(),
        }
    }

    #[test]
    fn text_round_trips() {
        let mut l = lock(&[("a", '1', '2'), ("b.c", '3', '4')]);
        assert_eq!(LockFile::parse(&l.to_text(), Path::new("x")).unwrap(), l);
        l.sets = vec!["parameterize.size=65".into(), "inputs.mesh=a b.off".into()];
        let text = l.to_text();
        assert!(text.contains("# set: parameterize.size=65\n"), "{text}");
        assert_eq!(LockFile::parse(&text, Path::new("x")).unwrap(), l);
        let e = LockFile::parse("# set: nothing\n", Path::new("x")).unwrap_err();
        assert!(e.to_string().contains("not STAGE.KEY=VALUE"), "{e}");
    }

    #[test]
    fn each_kind_of_difference_is_named() {
        let locked = lock(&[
            ("a", '1', '2'),
            ("b", '3', '4'),
            ("c", '5', '6'),
            ("d", '7', '8'),
        ]);
        let now = lock(&[
            ("a", '1', '2'),
            ("b", '9', '4'),
            ("c", '5', 'f'),
            ("e", '1', '1'),
        ]);
        let d = locked.compare(&now);
        assert_eq!(d.len(), 4, "{d:?}");
        assert!(matches!(&d[0], Difference::KeyChanged { node, .. } if node == "b"));
        assert!(d[1].is_unbumped() && d[1].to_string().contains("version not bumped"));
        assert_eq!(d[2], Difference::NotProduced { node: "d".into() });
        assert_eq!(d[3], Difference::NotLocked { node: "e".into() });
        assert_eq!(d.iter().filter(|d| d.is_unbumped()).count(), 1);
        assert!(locked.compare(&locked).is_empty());
    }

    #[test]
    fn malformed_lines_name_the_line() {
        let good = format!("# c\n\na {} {}\n", h('1'), h('2'));
        assert!(LockFile::parse(&good, Path::new("l")).is_ok());
        for bad in [
            format!("{good}a {} {}\n", h('3'), h('4')),  // node twice
            format!("{good}b {} {}x\n", h('3'), h('4')), // 65 digits
            format!("{good}b {} {}\n", h('3'), h('G')),  // not hex
            format!("{good}b {}\n", h('3')),             // two fields
            format!("{good}b {} {} extra\n", h('3'), h('4')), // four
        ] {
            let e = LockFile::parse(&bad, Path::new("l.lock")).unwrap_err();
            assert!(e.to_string().starts_with("l.lock:4: "), "{e}");
        }
    }
}
