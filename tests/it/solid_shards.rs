//! A solid run split into shards (`src/pipeline/shard.rs`): two shards on
//! one cache, then a gather run, give the outputs and hashes of one unsharded run in another
//! cache; the shards compute each finest brick once between them and the gather none; bad
//! `--shard` values are refused clearly, before anything is computed.
//!
//! The config is configs/solid_trivial.toml made small (a 40-voxel volume, 3 levels), so a
//! run takes seconds.

use crate::common;
use common::cli::{object_count, stderr, stdout, succeeded, texsyn};
use common::repo;
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::Output;

const SMALL: &[&str] = &[
    "parameterize.resolution=40",
    "analyse_exemplar.levels=3",
    "analyse_exemplar.neighbourhood_coarsest=5",
    "analyse_exemplar.neighbourhood=5",
    "synthesize.levels=[{ passes = 2, scheme = \"plain\" }, { passes = 2 }, { passes = 2 }]",
    "reconstruct.preview_size=32",
    "reconstruct.atlas_size=1024",
];

fn config() -> String {
    repo()
        .join("configs/solid_trivial.toml")
        .display()
        .to_string()
}

/// `texsyn COMMAND CONFIG --set SMALL… --cache CACHE EXTRA…` in `cwd`.
fn small(command: &str, cache: &Path, extra: &[&str], cwd: &Path) -> Output {
    let config = config();
    let cache = cache.display().to_string();
    let mut args = vec![command, config.as_str(), "--cache", cache.as_str()];
    for s in SMALL {
        args.extend(["--set", s]);
    }
    args.extend(extra);
    texsyn(&args, cwd)
}

fn json(o: &Output) -> serde_json::Value {
    serde_json::from_slice(&o.stdout).unwrap_or_else(|e| panic!("{e}: {}", stdout(o)))
}

type Bricks = BTreeSet<[i64; 3]>;

/// A shard's report on the synthesize node: its finest bricks, the total over all shards,
/// and the bricks it computed per level (coarsest first).
fn share(report: &serde_json::Value) -> (Bricks, u64, Vec<u64>) {
    let sharded = report["sharded"].as_array().expect("sharded nodes");
    assert_eq!(sharded.len(), 1, "{report}");
    assert_eq!(sharded[0]["node"], "synthesize");
    let share = &sharded[0]["share"];
    let assigned = share["assigned"]
        .as_array()
        .unwrap()
        .iter()
        .map(|b| {
            let c: Vec<i64> = b
                .as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_i64().unwrap())
                .collect();
            [c[0], c[1], c[2]]
        })
        .collect();
    let computed = share["levels"]
        .as_array()
        .unwrap()
        .iter()
        .map(|l| l["bricks_computed"].as_u64().unwrap())
        .collect();
    (assigned, share["finest_bricks"].as_u64().unwrap(), computed)
}

/// The synthesize node's pieces (computed, reused) in a `run --json` report.
fn pieces(report: &serde_json::Value) -> (u64, u64) {
    let node = report["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .find(|n| n["node"] == "synthesize")
        .expect("synthesize node");
    let p = &node["pieces"];
    (
        p["computed"].as_u64().unwrap(),
        p["reused"].as_u64().unwrap(),
    )
}

/// Every file under `dir` with its bytes, by relative path.
fn files(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_owned()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap().flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.push((
                    p.strip_prefix(dir).unwrap().to_owned(),
                    std::fs::read(&p).unwrap(),
                ));
            }
        }
    }
    out.sort();
    out
}

#[test]
fn two_shards_gathered_equal_the_unsharded_run() {
    let work = tempfile::tempdir().unwrap();
    let (shared, fresh) = (work.path().join("shared"), work.path().join("fresh"));
    let cwd = work.path();

    let first = json(&succeeded(small(
        "run",
        &shared,
        &["--json", "--shard", "0/2"],
        cwd,
    )));
    // Before the second shard runs, `status --shard 1/2` names its share and says it has
    // every finest brick of it still to compute.
    let status = json(&succeeded(small(
        "status",
        &shared,
        &["--json", "--shard", "1/2"],
        cwd,
    )));
    let second = json(&succeeded(small(
        "run",
        &shared,
        &["--json", "--shard", "1/2"],
        cwd,
    )));
    let (a, total_a, computed_a) = share(&first);
    let (b, total_b, computed_b) = share(&second);
    let (planned, _, to_compute) = share(&status["shard"]);
    assert_eq!(
        planned, b,
        "status --shard names the share run --shard computes"
    );
    assert_eq!(*to_compute.last().unwrap(), b.len() as u64);

    // The shares split the finest bricks: disjoint, each computed once, by its own shard.
    assert_eq!(total_a, total_b);
    assert!(!a.is_empty() && !b.is_empty(), "{a:?} {b:?}");
    assert!(
        a.is_disjoint(&b),
        "{:?}",
        a.intersection(&b).collect::<Vec<_>>()
    );
    assert_eq!(a.union(&b).count() as u64, total_a);
    assert_eq!(*computed_a.last().unwrap(), a.len() as u64);
    assert_eq!(*computed_b.last().unwrap(), b.len() as u64);

    // A shard writes no outputs and stores no artifact for the split node or below it.
    for report in [&first, &second] {
        assert_eq!(report["outputs"], serde_json::json!([]));
        assert_eq!(report["skipped"], serde_json::json!(["reconstruct"]));
    }
    assert!(!cwd.join("out").exists(), "a shard wrote outputs");
    let lines = json(&succeeded(small("status", &shared, &["--json"], cwd)));
    let state = |name: &str| {
        lines
            .as_array()
            .unwrap()
            .iter()
            .find(|l| l["node"] == name)
            .unwrap()["state"]
            .clone()
    };
    assert_eq!(state("analyse_exemplar"), "cached");
    assert_eq!(state("synthesize"), "run", "a shard stored the synthesis");

    // The gather computes no brick at all: every one was made by a shard.
    let gathered_out = work.path().join("gathered");
    let gathered_out_s = gathered_out.display().to_string();
    let gather = json(&succeeded(small(
        "run",
        &shared,
        &["--json", "--out", &gathered_out_s],
        cwd,
    )));
    let (computed, reused) = pieces(&gather);
    assert_eq!(computed, 0, "the gather computed bricks");
    assert!(reused >= total_a, "{reused} < {total_a}");

    // One machine, another cache: the same artifacts, hashes and output bytes.
    let alone_out = work.path().join("alone");
    let alone_out_s = alone_out.display().to_string();
    let alone = json(&succeeded(small(
        "run",
        &fresh,
        &["--json", "--out", &alone_out_s],
        cwd,
    )));
    assert!(pieces(&alone).0 >= total_a);
    let hashes = |r: &serde_json::Value| -> Vec<(String, String)> {
        r["nodes"]
            .as_array()
            .unwrap()
            .iter()
            .map(|n| {
                let s = |k: &str| n[k].as_str().unwrap().to_owned();
                (s("node"), s("content_hash"))
            })
            .collect()
    };
    assert_eq!(hashes(&gather), hashes(&alone));
    let lock = |cache: &Path| stdout(&succeeded(small("hashes", cache, &[], cwd)));
    assert_eq!(lock(&shared), lock(&fresh));
    let (g, u) = (files(&gathered_out), files(&alone_out));
    assert!(!g.is_empty());
    assert_eq!(
        g.iter().map(|f| &f.0).collect::<Vec<_>>(),
        u.iter().map(|f| &f.0).collect::<Vec<_>>()
    );
    for ((path, x), (_, y)) in g.iter().zip(&u) {
        assert!(x == y, "{} differs", path.display());
    }
}

#[test]
fn bad_shards_are_refused_clearly_before_any_work() {
    let work = tempfile::tempdir().unwrap();
    let cache = work.path().join("cache");
    let cwd = work.path();
    for (value, reason) in [
        ("2/2", "numbered 0 to 1"),
        ("1/0", "at least 1"),
        ("x", "expected i/N"),
        ("1/", "expected i/N"),
    ] {
        for command in ["run", "status"] {
            let o = small(command, &cache, &["--shard", value], cwd);
            let e = stderr(&o);
            assert_eq!(o.status.code(), Some(1), "{command} --shard {value}: {e}");
            assert!(
                e.contains(&format!("--shard \"{value}\"")) && e.contains(reason),
                "{command} --shard {value}: {e}"
            );
            assert!(!e.contains("panicked"), "{e}");
        }
    }
    assert_eq!(
        object_count(&cache),
        0,
        "a refused shard computed something"
    );

    // A method without bricks to split: the config and its method are named.
    let demo = repo().join("configs/demo.toml").display().to_string();
    let cache_s = cache.display().to_string();
    let o = texsyn(&["run", &demo, "--cache", &cache_s, "--shard", "0/2"], cwd);
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{e}");
    assert!(
        e.contains("demo.toml") && e.contains("jump_maps") && e.contains("solid"),
        "{e}"
    );
    assert_eq!(object_count(&cache), 0);
    assert!(!cwd.join("out").exists());
}
