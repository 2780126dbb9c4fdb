//! Processes sharing one cache: a node two runs need at the same moment is
//! computed by one of them while the other waits and reads it; a lock whose holder was killed
//! is taken over at once; where locks are unavailable, runs go on unlocked with the same
//! results.
//!
//! Overlap is made certain, not hoped for: either the test itself holds a node's key lock
//! (the documented `locks/ab/<key>.lock` file) while both runs start, or the second run is
//! started once the first has said (`-v`) that it is computing the slow node.

use crate::common;
use common::cli::{object_count, stderr, stdout, succeeded, texsyn};
use common::repo;
use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::mpsc::{Receiver, channel};

const CONFIG: &str = "configs/synth2d.toml";

fn size(side: u32) -> Vec<String> {
    vec![
        "--set".into(),
        format!("synthesize.width={side}"),
        "--set".into(),
        format!("synthesize.height={side}"),
    ]
}

/// A `texsyn -v --json run` in the background, its stderr read line by line as it comes.
struct Running {
    child: Child,
    lines: Receiver<String>,
    seen: Vec<String>,
}

impl Running {
    fn start(cache: &Path, out: &Path, extra: &[String]) -> Running {
        let mut child = Command::new(env!("CARGO_BIN_EXE_texsyn"))
            .args(["-v", "--json", "run", CONFIG])
            .args(["--cache", &cache.to_string_lossy()])
            .args(["--out", &out.to_string_lossy()])
            .args(extra)
            .current_dir(repo())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("texsyn starts");
        let err = child.stderr.take().unwrap();
        let (tx, lines) = channel();
        std::thread::spawn(move || {
            for line in BufReader::new(err).lines().map_while(Result::ok) {
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        Running {
            child,
            lines,
            seen: Vec::new(),
        }
    }

    /// Waits for a stderr line containing `needle`; false if the process ended first.
    fn wait_for(&mut self, needle: &str) -> bool {
        if self.seen.iter().any(|l| l.contains(needle)) {
            return true;
        }
        while let Ok(line) = self.lines.recv() {
            let hit = line.contains(needle);
            self.seen.push(line);
            if hit {
                return true;
            }
        }
        false
    }

    /// Waits for the process; its exit status, stdout and whole stderr.
    fn finish(mut self) -> (ExitStatus, String, String) {
        let mut out = String::new();
        self.child
            .stdout
            .take()
            .unwrap()
            .read_to_string(&mut out)
            .unwrap();
        let status = self.child.wait().unwrap();
        self.seen.extend(self.lines.iter());
        (status, out, self.seen.join("\n"))
    }

    /// Waits for a run that must succeed; its `--json` report and stderr.
    fn report(self) -> (serde_json::Value, String) {
        let (status, out, err) = self.finish();
        assert!(status.success(), "{out}{err}");
        (serde_json::from_str(&out).expect("a JSON report"), err)
    }
}

/// Node name → status ("ran" or "cached") in a `--json` run report.
fn statuses(report: &serde_json::Value) -> BTreeMap<String, String> {
    report["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|n| {
            (
                n["node"].as_str().unwrap().to_owned(),
                n["status"].as_str().unwrap().to_owned(),
            )
        })
        .collect()
}

/// Every node ran in exactly one of the two runs and was read from the cache in the other.
fn assert_computed_once(a: &serde_json::Value, b: &serde_json::Value) {
    let (a, b) = (statuses(a), statuses(b));
    assert_eq!(a.keys().collect::<Vec<_>>(), b.keys().collect::<Vec<_>>());
    for (node, sa) in &a {
        let mut pair = [sa.as_str(), b[node].as_str()];
        pair.sort();
        assert_eq!(pair, ["cached", "ran"], "{node}: {a:?} / {b:?}");
    }
}

/// Every file in `dir` (outputs are one flat folder), by name.
fn files(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    std::fs::read_dir(dir)
        .unwrap()
        .flatten()
        .map(|e| {
            let bytes = std::fs::read(e.path()).unwrap();
            (e.file_name().to_string_lossy().into_owned(), bytes)
        })
        .collect()
}

/// The lock file of a key, as the README documents it.
fn lock_path(cache: &Path, key: &str) -> PathBuf {
    cache
        .join("locks")
        .join(&key[..2])
        .join(format!("{key}.lock"))
}

/// The key `texsyn status` gives `node` (known only once its inputs are).
fn status_key(cache: &Path, extra: &[String], node: &str) -> String {
    let mut args = vec!["--json", "status", CONFIG, "--cache"];
    let c = cache.to_string_lossy().into_owned();
    args.push(&c);
    args.extend(extra.iter().map(String::as_str));
    let o = succeeded(texsyn(&args, &repo()));
    let lines: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    let line = lines
        .as_array()
        .unwrap()
        .iter()
        .find(|l| l["node"] == node)
        .unwrap_or_else(|| panic!("no node {node}: {lines}"));
    line["key"].as_str().expect("a known key").to_owned()
}

/// (a) Two runs started while their first node's lock is held (here by the test) are both
/// waiting at once; released, they compute every node once between them, the other run
/// reading it, and write the same files.
#[test]
fn two_runs_waiting_on_one_key_compute_each_node_once() {
    let tmp = tempfile::tempdir().unwrap();
    let cache = tmp.path().join("cache");
    let extra = size(1024);
    let key = status_key(&cache, &extra, "import.exemplar");
    let path = lock_path(&cache, &key);
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    let held = File::create(&path).unwrap();
    held.lock().unwrap();
    let mut a = Running::start(&cache, &tmp.path().join("a"), &extra);
    let mut b = Running::start(&cache, &tmp.path().join("b"), &extra);
    for run in [&mut a, &mut b] {
        assert!(
            run.wait_for("waiting for import.exemplar (computed by another process)"),
            "{}",
            run.seen.join("\n")
        );
    }
    drop(held);
    let ((ra, _), (rb, _)) = (a.report(), b.report());
    assert_computed_once(&ra, &rb);
    assert_eq!(files(&tmp.path().join("a")), files(&tmp.path().join("b")));
    // `gc` removes the lock files nobody holds, and no object with them.
    let before = object_count(&cache);
    let c = cache.to_string_lossy().into_owned();
    succeeded(texsyn(&["--cache", &c, "gc", "--max-size", "1T"], &repo()));
    assert_eq!(object_count(&cache), before);
    assert!(!path.exists());
}

/// (a) The second of two runs, started once the first is computing the slow node, waits for
/// it instead of computing it too, and reports it cached; between them every node is
/// computed once, and they write the same files.
#[test]
fn a_run_started_during_anothers_node_waits_for_it() {
    let tmp = tempfile::tempdir().unwrap();
    let cache = tmp.path().join("cache");
    let extra = size(4096);
    let mut a = Running::start(&cache, &tmp.path().join("a"), &extra);
    assert!(a.wait_for("computing synthesize"), "{}", a.seen.join("\n"));
    let b = Running::start(&cache, &tmp.path().join("b"), &extra);
    let ((ra, _), (rb, err_b)) = (a.report(), b.report());
    assert_computed_once(&ra, &rb);
    assert_eq!(statuses(&rb)["synthesize"], "cached");
    assert!(
        err_b.contains("waiting for synthesize (computed by another process)"),
        "{err_b}"
    );
    assert_eq!(files(&tmp.path().join("a")), files(&tmp.path().join("b")));
}

/// (b) A run killed (SIGKILL) while computing a node leaves its lock file, but not its lock:
/// the next run takes it at once, computes the node and succeeds.
#[test]
fn a_lock_left_by_a_killed_run_is_taken_over() {
    let tmp = tempfile::tempdir().unwrap();
    let cache = tmp.path().join("cache");
    let extra = size(4096);
    let mut a = Running::start(&cache, &tmp.path().join("a"), &extra);
    assert!(
        a.wait_for("computing synthesize (key "),
        "{}",
        a.seen.join("\n")
    );
    let line = a.seen.last().unwrap().clone();
    let key = line.rsplit("(key ").next().unwrap().trim_end_matches(')');
    let path = lock_path(&cache, key);
    // The killed run really held the lock.
    let probe = File::open(&path).unwrap();
    assert!(probe.try_lock().is_err(), "{} is not held", path.display());
    a.child.kill().unwrap(); // SIGKILL
    let (status, _, _) = a.finish();
    assert!(!status.success());
    assert!(path.exists(), "the lock file stays behind");
    drop(probe);

    let b = Running::start(&cache, &tmp.path().join("b"), &extra);
    let (rb, err_b) = b.report();
    let st = statuses(&rb);
    assert_eq!(st["synthesize"], "ran", "{rb}");
    assert_eq!(st["analyse_exemplar"], "cached", "{rb}");
    assert!(!err_b.contains("waiting for"), "{err_b}");
}

/// (c) Where no lock file can be made (here `locks` is a file), runs warn once and go on
/// unlocked: two at once both succeed, and write what a locked run on its own cache writes.
#[test]
fn without_locks_runs_warn_once_and_give_the_same_results() {
    let tmp = tempfile::tempdir().unwrap();
    let extra = size(1024);
    let reference = Running::start(&tmp.path().join("ref"), &tmp.path().join("ref-out"), &extra);
    let (r0, err0) = reference.report();
    assert!(!err0.contains("locks are unavailable"), "{err0}");

    let cache = tmp.path().join("cache");
    std::fs::create_dir_all(&cache).unwrap();
    std::fs::write(cache.join("locks"), b"not a folder").unwrap();
    let a = Running::start(&cache, &tmp.path().join("a"), &extra);
    let b = Running::start(&cache, &tmp.path().join("b"), &extra);
    for (run, out) in [(a, "a"), (b, "b")] {
        let (report, err) = run.report();
        let warnings = report["warnings"].as_array().unwrap();
        let about_locks: Vec<_> = warnings
            .iter()
            .filter(|w| w.as_str().unwrap().contains("key locks are unavailable"))
            .collect();
        assert_eq!(about_locks.len(), 1, "{warnings:?}");
        assert!(!err.contains("waiting for"), "{err}");
        let hashes = |r: &serde_json::Value| {
            r["nodes"]
                .as_array()
                .unwrap()
                .iter()
                .map(|n| n["content_hash"].clone())
                .collect::<Vec<_>>()
        };
        assert_eq!(hashes(&report), hashes(&r0));
        assert_eq!(
            files(&tmp.path().join(out)),
            files(&tmp.path().join("ref-out"))
        );
    }
    // `gc` and `verify` take the odd `locks` entry in their stride.
    let c = cache.to_string_lossy().into_owned();
    let o = texsyn(&["--cache", &c, "gc", "--max-size", "1T"], &repo());
    assert!(o.status.success(), "{}", stderr(&o));
}
