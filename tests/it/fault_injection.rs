//! Faults injected into real runs: the binary killed at seeded random moments, and
//! a full disk. After each, the output folder holds one run's outputs, all of them, and the
//! next run ends with the same files as an uninterrupted run, leaving no temporary behind
//! (the full tier). Concurrent runs with `gc` on one cache agree (the default tier).

use crate::common;
use common::repo;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn texsyn(cache: &Path, out: &Path, extra: &[String]) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_texsyn"));
    c.args(["run", "configs/synth2d.toml", "--quiet"])
        .args(["--cache", &cache.to_string_lossy()])
        .args(["--out", &out.to_string_lossy()])
        .args(extra)
        .current_dir(repo())
        .stdout(Stdio::null())
        .stderr(Stdio::piped());
    c
}

/// A 1024² synthesis (about half a second) with `seed`: two seeds give two different sets.
fn settings(seed: u32, side: u32) -> Vec<String> {
    [
        format!("synthesize.width={side}"),
        format!("synthesize.height={side}"),
        format!("synthesize.seed={seed}"),
    ]
    .into_iter()
    .flat_map(|s| ["--set".to_string(), s])
    .collect()
}

/// Every file in `dir` (not recursing), by name.
fn files(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    std::fs::read_dir(dir)
        .map(|rd| {
            rd.flatten()
                .map(|e| {
                    let bytes = std::fs::read(e.path()).unwrap_or_default();
                    (e.file_name().to_string_lossy().into_owned(), bytes)
                })
                .collect()
        })
        .unwrap_or_default()
}

/// Temporary files anywhere under `dir` (names starting with "." : texsyn's staging, journals
/// and temporaries).
fn leftovers(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let Ok(rd) = std::fs::read_dir(dir) else {
        return out;
    };
    for e in rd.flatten() {
        let p = e.path();
        if e.file_name().to_string_lossy().starts_with('.') {
            out.push(p.clone());
        }
        if p.is_dir() {
            out.extend(leftovers(&p));
        }
    }
    out
}

fn run_to_end(cache: &Path, out: &Path, extra: &[String]) {
    let o = texsyn(cache, out, extra).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

#[test]
fn runs_killed_at_random_moments_leave_one_whole_set_and_reruns_match() {
    crate::full_tier_only!("fault injection");
    let tmp = tempfile::tempdir().unwrap();
    let (cache, out) = (tmp.path().join("cache"), tmp.path().join("out"));
    // The two sets an uninterrupted run writes, each from its own empty cache.
    let mut reference = Vec::new();
    let mut duration = Duration::ZERO;
    for seed in [1, 2] {
        let dir = tmp.path().join(format!("ref{seed}"));
        let t = Instant::now();
        run_to_end(&dir.join("cache"), &dir.join("out"), &settings(seed, 1024));
        duration = duration.max(t.elapsed());
        reference.push(files(&dir.join("out")));
    }
    assert_ne!(reference[0], reference[1]);
    run_to_end(&cache, &out, &settings(1, 1024));
    let kills = 16;
    let mut current = 0;
    for i in 0..kills {
        let next = 1 - current;
        // A seeded moment in [0, 1.2 × a run]: before, during and after the export.
        let f = texsyn::random::counter_unit(11, 0, i as u64) * 1.2;
        let mut child = texsyn(&cache, &out, &settings(next as u32 + 1, 1024))
            .spawn()
            .unwrap();
        std::thread::sleep(duration.mul_f32(f));
        let _ = child.kill();
        child.wait().unwrap();
        // What the next command on the folder sees first: a swap the kill interrupted is
        // finished or undone.
        texsyn::pipeline::outputs::recover(&out).unwrap();
        let now = files(&out);
        assert!(
            now == reference[current] || now == reference[next],
            "kill {i} at {f:.2} of a run: the outputs are a mix of two runs: {:?}",
            now.keys().collect::<Vec<_>>()
        );
        // Rerun to the end: the uninterrupted run's files, and nothing left behind.
        run_to_end(&cache, &out, &settings(next as u32 + 1, 1024));
        assert_eq!(files(&out), reference[next], "rerun after kill {i}");
        let left: Vec<_> = leftovers(&out)
            .into_iter()
            .chain(leftovers(&cache))
            .collect();
        assert!(left.is_empty(), "kill {i}: left behind {left:?}");
        current = next;
    }
    eprintln!("{kills} runs killed at seeded moments; every rerun matched");
}

/// A full disk: a 1 MiB tmpfs for the outputs when running as root (CI does), a file-size
/// limit otherwise. The run fails with a clear error, and the outputs and the cache are as
/// they were.
#[test]
fn a_full_disk_fails_clearly_and_keeps_the_outputs_and_the_cache() {
    crate::full_tier_only!("fault injection");
    let tmp = tempfile::tempdir().unwrap();
    let cache = tmp.path().join("cache");
    let small = tmp.path().join("small");
    std::fs::create_dir_all(&small).unwrap();
    // SAFETY: geteuid has no preconditions.
    let root = unsafe { libc::geteuid() } == 0;
    let mounted = root
        && Command::new("mount")
            .args(["-t", "tmpfs", "-o", "size=1m", "tmpfs"])
            .arg(&small)
            .status()
            .map(|s| s.success())
            .unwrap_or(false);
    if root && !mounted {
        eprintln!("mount failed although running as root: using the file-size limit instead");
    }
    let out = small.join("out");
    // A small run that fits: the outputs to keep.
    run_to_end(&cache, &out, &settings(1, 128));
    let before = files(&out);
    let mut cmd = texsyn(&cache, &out, &settings(2, 1024));
    if !mounted {
        use std::os::unix::process::CommandExt;
        // SAFETY: only async-signal-safe calls between fork and exec.
        unsafe {
            cmd.pre_exec(|| {
                libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
                let lim = libc::rlimit {
                    rlim_cur: 1 << 20,
                    rlim_max: 1 << 20,
                };
                libc::setrlimit(libc::RLIMIT_FSIZE, &lim);
                Ok(())
            });
        }
    }
    let o = cmd.output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr).to_string();
    let (after, left) = (files(&out), leftovers(&out));
    if mounted {
        let _ = Command::new("umount").arg(&small).status();
    }
    assert!(!o.status.success(), "a 1024² run fit in 1 MiB?");
    assert!(err.contains("space") || err.contains("too large"), "{err}");
    assert_eq!(after, before, "the previous outputs changed");
    assert!(left.is_empty(), "{left:?}");
    assert!(leftovers(&cache).is_empty(), "{:?}", leftovers(&cache));
    // The cache still gives the small run's results, and the big run completes elsewhere.
    let o = texsyn(&cache, &tmp.path().join("out2"), &settings(1, 128))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(files(&tmp.path().join("out2")), before);
}

/// Concurrent runs of overlapping configs on one cache, with `gc` trimming it to nothing at
/// the same time: every run succeeds, and runs of one config agree byte for byte.
#[test]
fn concurrent_runs_and_gc_on_one_cache_agree() {
    let tmp = tempfile::tempdir().unwrap();
    let cache = tmp.path().join("cache");
    let mut children = Vec::new();
    for (i, seed) in [1, 1, 2, 1, 2].into_iter().enumerate() {
        let out = tmp.path().join(format!("out{i}"));
        children.push((
            seed,
            out.clone(),
            texsyn(&cache, &out, &settings(seed, 512)).spawn().unwrap(),
        ));
    }
    let mut gcs = Vec::new();
    for _ in 0..3 {
        std::thread::sleep(Duration::from_millis(100));
        gcs.push(
            Command::new(env!("CARGO_BIN_EXE_texsyn"))
                .args(["gc", "--max-size", "0", "--quiet", "--cache"])
                .arg(&cache)
                .stderr(Stdio::piped())
                .output()
                .unwrap(),
        );
    }
    let mut sets: BTreeMap<u32, BTreeMap<String, Vec<u8>>> = BTreeMap::new();
    for (seed, out, child) in children {
        let o = child.wait_with_output().unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let f = files(&out);
        assert!(!f.is_empty());
        if let Some(first) = sets.get(&seed) {
            assert_eq!(first, &f, "two runs of seed {seed} disagree");
        } else {
            sets.insert(seed, f);
        }
    }
    for g in gcs {
        assert!(g.status.success(), "{}", String::from_utf8_lossy(&g.stderr));
    }
    assert_ne!(sets[&1], sets[&2]);
    assert!(leftovers(&cache).is_empty(), "{:?}", leftovers(&cache));
}
