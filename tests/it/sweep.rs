//! `texsyn sweep` as a user runs it: the table agrees with the same points run one by one,
//! a killed sweep resumes with only its missing points, the sweep lock verifies (and catches a
//! change), and bad sweeps are refused before anything runs.

use crate::common;

use common::cli::{stderr, stdout, succeeded, texsyn};
use std::path::{Path, PathBuf};

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// A seed sweep of the small synth2d run, written into `dir` (the base is the repo's config).
fn write_sweep(dir: &Path, extra: &str, seeds: &str) -> PathBuf {
    let base = repo().join("configs/synth2d.toml");
    let path = dir.join("seeds.toml");
    std::fs::write(
        &path,
        format!(
            "base = {:?}\n{extra}\n[axes]\n\"synthesize.width\" = [64]\n\"synthesize.height\" = [64]\n\"synthesize.seed\" = {seeds}\n",
            base.to_str().unwrap()
        ),
    )
    .unwrap();
    path
}

fn csv_rows(path: &Path) -> Vec<std::collections::HashMap<String, String>> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header: Vec<String> = lines
        .next()
        .unwrap()
        .split(',')
        .map(str::to_owned)
        .collect();
    lines
        .map(|l| {
            header
                .iter()
                .cloned()
                .zip(l.split(',').map(str::to_owned))
                .collect()
        })
        .collect()
}

#[test]
fn the_tables_hashes_equal_those_of_the_points_run_one_by_one() {
    let t = tempfile::tempdir().unwrap();
    let sweep = write_sweep(t.path(), "workers = 2", "[1, 2, 3]");
    let out = t.path().join("out");
    let o = texsyn(
        &[
            "sweep",
            sweep.to_str().unwrap(),
            "--cache",
            "c1",
            "--out",
            out.to_str().unwrap(),
        ],
        t.path(),
    );
    let o = succeeded(o);
    assert!(stdout(&o).contains("3 points"), "{}", stdout(&o));
    let rows = csv_rows(&out.join("results.csv"));
    assert_eq!(rows.len(), 3);
    let md = std::fs::read_to_string(out.join("results.md")).unwrap();
    assert_eq!(
        md.lines().filter(|l| l.starts_with("| ")).count(),
        4,
        "{md}"
    );
    for (i, row) in rows.iter().enumerate() {
        assert_eq!(row["state"], "ok");
        assert_eq!(row["synthesize.seed"], (i + 1).to_string());
        // The same point, run alone in a cache of its own.
        let lock = succeeded(texsyn(
            &[
                "hashes",
                repo().join("configs/synth2d.toml").to_str().unwrap(),
                "--cache",
                "c2",
                "--set",
                "synthesize.width=64",
                "--set",
                "synthesize.height=64",
                "--set",
                &format!("synthesize.seed={}", i + 1),
            ],
            t.path(),
        ));
        let mut compared = 0;
        for line in stdout(&lock).lines().filter(|l| !l.starts_with('#')) {
            let f: Vec<&str> = line.split_whitespace().collect();
            assert_eq!(
                row[&format!("{} hash", f[0])],
                f[2],
                "point {i}, node {}",
                f[0]
            );
            compared += 1;
        }
        assert!(compared >= 3, "{}", stdout(&lock));
        // Its outputs are in its own folder.
        let folder = PathBuf::from(&row["output folder"]);
        assert!(
            folder.join("synthesized.png").is_file(),
            "{}",
            folder.display()
        );
    }
    // Points differ by seed: their synthesis differs, their shared import does not.
    assert_ne!(rows[0]["synthesize hash"], rows[1]["synthesize hash"]);
    assert_eq!(
        rows[0]["import.exemplar hash"],
        rows[2]["import.exemplar hash"]
    );

    // The sweep's lock verifies, and a changed hash in it is a mismatch naming the point.
    let lock = out.join("sweep.lock");
    let o = succeeded(texsyn(
        &[
            "verify",
            sweep.to_str().unwrap(),
            lock.to_str().unwrap(),
            "--cache",
            "c1",
        ],
        t.path(),
    ));
    assert!(stdout(&o).contains("3 points"), "{}", stdout(&o));
    // The sweep's lock with the base config instead of the sweep: said so.
    let o = texsyn(
        &[
            "verify",
            repo().join("configs/synth2d.toml").to_str().unwrap(),
            lock.to_str().unwrap(),
            "--cache",
            "c1",
        ],
        t.path(),
    );
    assert!(
        o.status.code() == Some(1) && stderr(&o).contains("is a sweep's lock"),
        "{}",
        stderr(&o)
    );
    let text = std::fs::read_to_string(&lock).unwrap();
    let synth = rows[1]["synthesize hash"].clone();
    std::fs::write(&lock, text.replace(&synth, &"0".repeat(64))).unwrap();
    let o = texsyn(
        &[
            "verify",
            sweep.to_str().unwrap(),
            lock.to_str().unwrap(),
            "--cache",
            "c1",
        ],
        t.path(),
    );
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("point 1 (") && stderr(&o).contains("synthesize"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn a_killed_sweep_resumed_runs_only_its_missing_points() {
    use std::os::unix::process::CommandExt;
    let t = tempfile::tempdir().unwrap();
    let sweep = write_sweep(t.path(), "workers = 1", "[1, 2, 3, 4, 5, 6, 7, 8]");
    let out = t.path().join("out");
    let args = [
        "sweep",
        sweep.to_str().unwrap(),
        "--cache",
        "c",
        "--out",
        out.to_str().unwrap(),
        "-q",
    ];
    // The sweep and its point processes in a group of their own, killed together as a
    // terminal's Ctrl-\ or a batch system's kill would.
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_texsyn"))
        .args(args)
        .current_dir(t.path())
        .process_group(0)
        .spawn()
        .unwrap();
    let first = out.join("reports/000.json");
    let start = std::time::Instant::now();
    while !first.exists() && start.elapsed().as_secs() < 120 {
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    assert!(first.exists(), "the first point never finished");
    unsafe {
        libc::kill(-(child.id() as i32), libc::SIGKILL);
    }
    let _ = child.wait();
    let reports = out.join("reports");
    let before: Vec<(usize, Option<Vec<u8>>)> = (0..8)
        .map(|i| (i, std::fs::read(reports.join(format!("{i:03}.json"))).ok()))
        .collect();
    let done = before.iter().filter(|(_, r)| r.is_some()).count();
    assert!(
        done < 8,
        "every point finished before the kill: nothing left to resume"
    );

    let o = succeeded(texsyn(&args[..6], t.path()));
    assert!(
        stdout(&o).contains(&format!("running {}", 8 - done)),
        "{}",
        stdout(&o)
    );
    for (i, old) in before {
        let now = std::fs::read(reports.join(format!("{i:03}.json"))).unwrap();
        match old {
            // A point done before the kill was not run again: its report is the same.
            Some(old) => assert_eq!(old, now, "point {i} ran again"),
            // A missing point ran now. Its synthesis ran now, or, when the kill came after
            // that node was stored but before the point's report, was found in the cache.
            None => {
                let r: serde_json::Value = serde_json::from_slice(&now).unwrap();
                let synth = r["nodes"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .find(|n| n["node"] == "synthesize")
                    .unwrap();
                let status = synth["status"].as_str().unwrap_or("");
                assert!(["ran", "cached"].contains(&status), "point {i}: {status}");
            }
        }
    }
    let rows = csv_rows(&out.join("results.csv"));
    assert!(rows.iter().all(|r| r["state"] == "ok"));
}

#[test]
fn a_failed_point_is_reported_with_its_log_and_the_rerun_runs_only_it() {
    let t = tempfile::tempdir().unwrap();
    // The third point's width is out of range: found when the sweep is checked, so make
    // it fail at run time instead, with an exemplar that is not an image.
    let bad = t.path().join("bad.png");
    std::fs::write(&bad, b"not a png").unwrap();
    let base = repo().join("configs/synth2d.toml");
    let sweep = t.path().join("inputs.toml");
    std::fs::write(
        &sweep,
        format!(
            "base = {:?}\n[axes]\n\"synthesize.width\" = [64]\n\"inputs.exemplar\" = [{:?}, \"bad.png\"]\n",
            base.to_str().unwrap(),
            repo().join("configs/assets/leopard.png").to_str().unwrap()
        ),
    )
    .unwrap();
    let args = ["sweep", "inputs.toml", "--cache", "c", "--out", "out"];
    let o = texsyn(&args, t.path());
    assert_eq!(o.status.code(), Some(1), "{}", stdout(&o));
    let err = stderr(&o);
    assert!(
        err.contains("point 1 failed") && err.contains("bad.png") && err.contains("logs/001.log"),
        "{err}"
    );
    let rows = csv_rows(&t.path().join("out/results.csv"));
    assert_eq!(rows[0]["state"], "ok");
    assert_eq!(rows[1]["state"], "failed");
    assert!(!t.path().join("out/sweep.lock").exists());
    // Fixed, the rerun runs that point only.
    std::fs::copy(repo().join("configs/assets/leopard.png"), &bad).unwrap();
    let o = succeeded(texsyn(&args, t.path()));
    assert!(stdout(&o).contains("running 1"), "{}", stdout(&o));
    assert!(t.path().join("out/sweep.lock").exists());
}

#[test]
fn bad_sweeps_are_refused_before_anything_runs() {
    let t = tempfile::tempdir().unwrap();
    let base = repo().join("configs/synth2d.toml");
    let cases = [
        ("\"synthesize.sede\" = [1]", "sede"),
        ("\"synthesize.seed\" = [\"one\"]", "synthesize.seed"),
        ("\"synthesize.seed\" = []", "no values"),
        (
            "\"synthesize.seed\" = { from = 1, to = 2, steps = 0 }",
            "steps",
        ),
    ];
    for (axes, says) in cases {
        let path = t.path().join("s.toml");
        std::fs::write(
            &path,
            format!("base = {:?}\n[axes]\n{axes}\n", base.to_str().unwrap()),
        )
        .unwrap();
        let o = texsyn(
            &["sweep", "s.toml", "--cache", "c", "--out", "out"],
            t.path(),
        );
        assert_eq!(o.status.code(), Some(1), "{axes}");
        let err = stderr(&o);
        assert!(
            err.contains("s.toml") && err.contains(says),
            "{axes}: {err}"
        );
        assert!(!t.path().join("out").exists(), "{axes}: something ran");
    }
    std::fs::write(
        t.path().join("z.toml"),
        format!(
            "base = {:?}\ncombine = \"zip\"\n[axes]\n\"synthesize.seed\" = [1, 2]\n\"synthesize.width\" = [64]\n",
            base.to_str().unwrap()
        ),
    )
    .unwrap();
    let o = texsyn(&["sweep", "z.toml", "--cache", "c"], t.path());
    assert!(stderr(&o).contains("one length"), "{}", stderr(&o));
    std::fs::write(
        t.path().join("m.toml"),
        "base = \"missing.toml\"\n[axes]\n\"synthesize.seed\" = [1]\n",
    )
    .unwrap();
    let o = texsyn(&["sweep", "m.toml", "--cache", "c"], t.path());
    assert!(
        o.status.code() == Some(1) && stderr(&o).contains("missing.toml"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn an_edited_base_reruns_its_points_and_a_failed_rerun_leaves_no_lock() {
    let t = tempfile::tempdir().unwrap();
    let leopard = repo().join("configs/assets/leopard.png");
    std::fs::copy(&leopard, t.path().join("ex.png")).unwrap();
    let base = |continuation: f64| {
        std::fs::write(
            t.path().join("base.toml"),
            format!(
                "method = \"synth2d\"\n[inputs]\nexemplar = {:?}\n[synthesize]\nwidth = 64\nheight = 64\ncontinuation = {continuation:?}\n",
                leopard.to_str().unwrap()
            ),
        )
        .unwrap()
    };
    std::fs::write(
        t.path().join("s.toml"),
        "base = \"base.toml\"\n[axes]\n\"inputs.exemplar\" = [\"ex.png\", \"ex.png\"]\n\"synthesize.seed\" = [1]\n",
    )
    .unwrap();
    let args = ["sweep", "s.toml", "--cache", "c", "--out", "out"];
    let synth_hashes = || {
        csv_rows(&t.path().join("out/results.csv"))
            .iter()
            .map(|r| r["synthesize hash"].clone())
            .collect::<Vec<_>>()
    };
    base(300.0);
    succeeded(texsyn(&args, t.path()));
    let first = synth_hashes();
    assert!(t.path().join("out/sweep.lock").exists());
    // Edited: both points run again, with other results.
    base(50.0);
    let o = succeeded(texsyn(&args, t.path()));
    assert!(stdout(&o).contains("(2 run now)"), "{}", stdout(&o));
    assert_ne!(synth_hashes(), first);
    // Reverted: every node is cached, but the reports are the edited run's, so both points
    // run again (from the cache) and the table is the first run's again.
    base(300.0);
    let o = succeeded(texsyn(&args, t.path()));
    assert!(stdout(&o).contains("(2 run now)"), "{}", stdout(&o));
    assert_eq!(synth_hashes(), first);
    // A rerun that fails leaves no lock of an earlier run behind.
    std::fs::write(t.path().join("ex.png"), b"not a png").unwrap();
    base(50.0);
    let o = texsyn(&args, t.path());
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(!t.path().join("out/sweep.lock").exists());
    assert!(
        csv_rows(&t.path().join("out/results.csv"))
            .iter()
            .all(|r| r["state"] == "failed")
    );
}

#[test]
fn a_sweep_past_the_point_limit_is_refused_before_allocating_and_a_big_one_says_what_it_does() {
    let t = tempfile::tempdir().unwrap();
    let base = repo().join("configs/synth2d.toml");
    let range = "{ from = 1, to = 100000, steps = 100000 }";
    std::fs::write(
        t.path().join("huge.toml"),
        format!(
            "base = {:?}\n[axes]\n\"synthesize.seed\" = {range}\n\"synthesize.width\" = {range}\n",
            base.to_str().unwrap()
        ),
    )
    .unwrap();
    let start = std::time::Instant::now();
    let o = texsyn(&["sweep", "huge.toml", "--cache", "c"], t.path());
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    for word in [
        "huge.toml",
        "10000000000 points",
        "synthesize.seed",
        "over the limit of 100000",
    ] {
        assert!(err.contains(word), "expected {word:?} in: {err}");
    }
    assert!(start.elapsed().as_secs() < 10, "took {:?}", start.elapsed());
    assert!(!t.path().join("c").exists(), "something ran");

    let path = write_sweep(t.path(), "", "{ from = 1, to = 2000, steps = 2000 }");
    let o = succeeded(texsyn(
        &[
            "sweep",
            path.to_str().unwrap(),
            "--status",
            "--cache",
            "c",
            "--out",
            "out",
        ],
        t.path(),
    ));
    let err = stderr(&o);
    assert!(
        err.contains("checking the configs of 2000 points") && err.contains("1000 of 2000"),
        "a sweep of 2000 points must say what it is doing: {err}"
    );
}
