//! `texsyn sweep --executor slurm` through the local one-node cluster (scripts/slurm-local),
//! compared with the local executor: the same table hashes; a failed point named with its job
//! id and log, and rerun alone; a killed client re-attached; a two-shard solid gathered equal
//! to one machine's run. Without the cluster these tests fail (TEXSYN_NO_SLURM=1 skips them
//! loudly; CI never sets it).

use crate::common;

use common::cli::{stderr, stdout, succeeded, texsyn};
use common::cluster::cluster;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// A folder on the local disk, seen by the cluster's daemons (same machine).
fn folder() -> tempfile::TempDir {
    tempfile::Builder::new()
        .prefix("texsyn-sweep-slurm-")
        .tempdir()
        .unwrap()
}

const SLURM: &str = "[slurm]\ntime = \"10\"\nmem = \"1G\"\ncpus_per_task = 1\n";

fn write(dir: &Path, name: &str, text: String) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

/// `texsyn sweep SWEEP --executor slurm` into `out`, on the cache `cache`.
fn slurm_args(sweep: &Path) -> Vec<String> {
    let sweep = sweep.to_str().unwrap().to_owned();
    [
        "sweep",
        &sweep,
        "--executor",
        "slurm",
        "--out",
        "out",
        "--cache",
        "cache",
    ]
    .map(str::to_owned)
    .to_vec()
}

/// Node → content hash, per point, from a sweep's results.csv.
fn hashes(csv: &Path) -> Vec<HashMap<String, String>> {
    let text = std::fs::read_to_string(csv).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    lines
        .map(|l| {
            header
                .iter()
                .zip(l.split(','))
                .filter_map(|(h, v)| {
                    h.strip_suffix(" hash")
                        .map(|n| (n.to_owned(), v.to_owned()))
                })
                .collect()
        })
        .collect()
}

#[test]
fn a_slurm_sweep_gives_the_local_tables_hashes_and_reruns_only_a_failed_point() {
    if !cluster("slurm sweep") {
        return;
    }
    let t = folder();
    let base = repo().join("configs/synth2d.toml");
    let leopard = repo().join("configs/assets/leopard.png");
    let bad = t.path().join("bad.png");
    std::fs::write(&bad, b"not a png").unwrap();
    let sweep = write(
        t.path(),
        "s.toml",
        format!(
            "base = {:?}\n{SLURM}[axes]\n\"synthesize.width\" = [64]\n\"synthesize.seed\" = [1, 2]\n\"inputs.exemplar\" = [{:?}, \"bad.png\"]\n",
            base.to_str().unwrap(),
            leopard.to_str().unwrap()
        ),
    );
    let args = |exec: &str, out: &str, cache: &str| {
        texsyn(
            &[
                "sweep",
                sweep.to_str().unwrap(),
                "--executor",
                exec,
                "--out",
                out,
                "--cache",
                cache,
            ],
            t.path(),
        )
    };
    // Points 1 and 3 read bad.png and fail.
    let o = args("slurm", "out-slurm", "cache-slurm");
    assert_eq!(o.status.code(), Some(1), "{}{}", stdout(&o), stderr(&o));
    let err = stderr(&o);
    for p in [1, 3] {
        let line = err
            .lines()
            .find(|l| l.starts_with(&format!("point {p} failed")))
            .unwrap_or_else(|| panic!("point {p} not reported: {err}"));
        assert!(
            line.contains("Slurm job ") && line.contains("log ") && line.contains("bad.png"),
            "{line}"
        );
        // The log named holds the run's error.
        let log = line.rsplit("log ").next().unwrap().trim();
        let text = std::fs::read_to_string(log).unwrap();
        assert!(text.contains("bad.png"), "{log}: {text}");
    }
    // Fixed, the rerun submits the two failed points only.
    std::fs::copy(&leopard, &bad).unwrap();
    let o = succeeded(args("slurm", "out-slurm", "cache-slurm"));
    assert!(stdout(&o).contains("submitting 2 points"), "{}", stdout(&o));
    let local = succeeded(args("local", "out-local", "cache-local"));
    assert!(stdout(&local).contains("4 points"), "{}", stdout(&local));
    let (s, l) = (
        hashes(&t.path().join("out-slurm/results.csv")),
        hashes(&t.path().join("out-local/results.csv")),
    );
    assert_eq!(s.len(), 4);
    assert!(s[0].len() >= 3, "{:?}", s[0]);
    assert_eq!(
        s, l,
        "the Slurm executor's hashes differ from the local one's"
    );
    // Both locks verify against one cache.
    succeeded(texsyn(
        &[
            "verify",
            sweep.to_str().unwrap(),
            "out-slurm/sweep.lock",
            "--cache",
            "cache-local",
        ],
        t.path(),
    ));
}

#[test]
fn a_slurm_sweep_whose_client_was_killed_is_reattached_and_finishes() {
    if !cluster("slurm re-attach") {
        return;
    }
    let t = folder();
    let base = repo().join("configs/synth2d.toml");
    // Points of a few seconds each, so they are still queued or running when the client dies.
    let sweep = write(
        t.path(),
        "s.toml",
        format!(
            "base = {:?}\n{SLURM}[axes]\n\"synthesize.width\" = [1536]\n\"synthesize.height\" = [1536]\n\"synthesize.seed\" = [1, 2, 3]\n",
            base.to_str().unwrap()
        ),
    );
    let args = slurm_args(&sweep);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let mut client = std::process::Command::new(env!("CARGO_BIN_EXE_texsyn"))
        .args(&args)
        .current_dir(t.path())
        .stdout(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let submissions = t.path().join("out/slurm/submissions.json");
    let start = std::time::Instant::now();
    while !submissions.exists() && start.elapsed().as_secs() < 120 {
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    assert!(submissions.exists(), "the client never submitted");
    client.kill().unwrap();
    let _ = client.wait();
    // Its tasks live on in Slurm; the same command waits for them instead of submitting anew.
    let o = succeeded(texsyn(&args, t.path()));
    assert!(stdout(&o).contains("re-attached"), "{}", stdout(&o));
    let subs: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&submissions).unwrap()).unwrap();
    assert_eq!(subs.as_array().unwrap().len(), 1, "submitted again: {subs}");
    let text = std::fs::read_to_string(t.path().join("out/results.csv")).unwrap();
    assert_eq!(
        text.lines().skip(1).filter(|l| l.contains(",ok,")).count(),
        3,
        "{text}"
    );
}

#[test]
fn a_two_shard_solid_through_slurm_gathers_to_the_unsharded_result() {
    if !cluster("slurm shards") {
        return;
    }
    let t = folder();
    let base = repo().join("configs/solid_trivial.toml");
    let elephant = repo().join("configs/assets/elephant.off");
    // Point 1's mesh is broken: its shards fail, and only its own gather may be cancelled.
    std::fs::write(t.path().join("bad.off"), b"OFF\nnot a mesh\n").unwrap();
    let sweep = write(
        t.path(),
        "s.toml",
        format!(
            "base = {:?}\nshards = 2\n{SLURM}[axes]\n\"parameterize.resolution\" = [80]\n\"reconstruct.atlas_size\" = [512]\n\"inputs.mesh\" = [{:?}, \"bad.off\"]\n",
            base.to_str().unwrap(),
            elephant.to_str().unwrap()
        ),
    );
    let args = slurm_args(&sweep);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let o = texsyn(&args, t.path());
    assert_eq!(o.status.code(), Some(1), "{}{}", stdout(&o), stderr(&o));
    assert!(
        stdout(&o).contains("2 points to Slurm (6 tasks)"),
        "{}",
        stdout(&o)
    );
    let err = stderr(&o);
    assert!(
        err.contains("point 1 failed") && err.contains("shard") && !err.contains("point 0 failed"),
        "{err}"
    );
    // Both of point 0's shards ran as Slurm tasks and wrote their reports.
    for s in 0..2 {
        let r = t.path().join(format!("out/reports/000.shard{s}.json"));
        assert!(r.is_file(), "{}", r.display());
    }
    // One machine, unsharded, in a cache of its own.
    let one = succeeded(texsyn(
        &[
            "hashes",
            base.to_str().unwrap(),
            "--set",
            "parameterize.resolution=80",
            "--set",
            "reconstruct.atlas_size=512",
            "--cache",
            "alone",
        ],
        t.path(),
    ));
    let check = |point: usize| {
        let gathered = &hashes(&t.path().join("out/results.csv"))[point];
        let mut compared = 0;
        for line in stdout(&one).lines().filter(|l| !l.starts_with('#')) {
            let f: Vec<&str> = line.split_whitespace().collect();
            assert_eq!(gathered[f[0]], f[2], "point {point}: {}", f[0]);
            compared += 1;
        }
        assert!(compared >= 6, "{}", stdout(&one));
        // The gather computed no brick: every one came from the shards.
        let r: serde_json::Value = serde_json::from_slice(
            &std::fs::read(t.path().join(format!("out/reports/{point:03}.json"))).unwrap(),
        )
        .unwrap();
        let synth = r["nodes"]
            .as_array()
            .unwrap()
            .iter()
            .find(|n| n["node"] == "synthesize")
            .unwrap();
        // (Point 1's mesh is point 0's, so its whole synthesis may be found cached.)
        assert!(
            synth["status"] == "cached" || synth["pieces"]["computed"] == 0,
            "{synth}"
        );
    };
    check(0);
    // Mended, the rerun submits point 1 alone; the same mesh gives the same result.
    std::fs::copy(&elephant, t.path().join("bad.off")).unwrap();
    let o = succeeded(texsyn(&args, t.path()));
    assert!(
        stdout(&o).contains("submitting 1 points to Slurm (3 tasks)"),
        "{}",
        stdout(&o)
    );
    check(1);
}

#[test]
fn a_sweep_beyond_the_clusters_max_array_size_is_refused_before_submitting() {
    if !cluster("slurm MaxArraySize") {
        return;
    }
    let t = folder();
    let base = repo().join("configs/synth2d.toml");
    // The local cluster keeps Slurm's default MaxArraySize, 1001: indices 0 to 1000.
    let sweep = write(
        t.path(),
        "s.toml",
        format!(
            "base = {:?}\n[axes]\n\"synthesize.seed\" = {{ from = 1, to = 1002, steps = 1002 }}\n",
            base.to_str().unwrap()
        ),
    );
    let args = slurm_args(&sweep);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let o = texsyn(&args, t.path());
    assert_eq!(o.status.code(), Some(1), "{}", stdout(&o));
    assert!(
        stderr(&o).contains("MaxArraySize is 1001") && stderr(&o).contains("1001"),
        "{}",
        stderr(&o)
    );
    assert!(!t.path().join("out/slurm/submissions.json").exists());
}
