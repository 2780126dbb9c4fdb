//! Every shipped config reproduces its committed lock file (configs/NAME.lock) from an empty
//! cache: each node's key and each artifact's content hash. The full-size configs are the full
//! tier's; the default tier verifies the small-setting companion locks (configs/cpu/), which
//! cover every method. A key or format change on purpose regenerates the lock in the same
//! commit (`texsyn hashes configs/NAME.toml > configs/NAME.lock`) and says why.

use std::path::PathBuf;
use std::process::Command;

fn verify_from_empty_cache(name: &str) {
    let repo = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let config = repo.join("configs").join(format!("{name}.toml"));
    verify_fresh(&config, &repo.join("configs").join(format!("{name}.lock")));
}

/// `texsyn verify CONFIG LOCK --fresh` in an empty cache, asserted to pass.
fn verify_fresh(config: &std::path::Path, lock: &std::path::Path) {
    let repo = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let cache = tempfile::tempdir().unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_texsyn"))
        .arg("verify")
        .arg(config)
        .arg(lock)
        .args(["--fresh", "--quiet", "--cache"])
        .arg(cache.path())
        .current_dir(&repo)
        .output()
        .expect("texsyn runs");
    assert!(
        o.status.success(),
        "{}: verify failed:\n{}{}",
        lock.display(),
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
}

macro_rules! lock_tests {
    ($($name:ident),* $(,)?) => {
        $(
            #[test]
            fn $name() {
                crate::full_tier_only!("a full-size config from an empty cache");
                verify_from_empty_cache(stringify!($name));
            }
        )*

        /// A config shipped without a lock, or a lock without its test here, is caught.
        #[test]
        fn every_shipped_config_has_a_lock_and_a_test() {
            let tested = [$(stringify!($name)),*];
            let repo = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
            for entry in std::fs::read_dir(repo.join("configs")).unwrap() {
                let path = entry.unwrap().path();
                if path.extension().is_some_and(|e| e == "toml") {
                    let text = std::fs::read_to_string(&path).unwrap();
                    // Companion files (curves) name no method: they are not configs.
                    if !text.lines().any(|l| l.trim_start().starts_with("method")) {
                        continue;
                    }
                    let stem = path.file_stem().unwrap().to_str().unwrap().to_owned();
                    assert!(path.with_extension("lock").exists(), "{stem} has no lock file");
                    assert!(tested.contains(&stem.as_str()), "{stem}.lock is not verified by a test");
                }
            }
        }
    };
}

lock_tests!(
    demo,
    synth2d,
    relief_cow,
    relief_oriented,
    dragon_knot,
    dragon_elephant,
    solid_trivial,
    solid_elephant,
    solid_elephant_section,
    solid_elephant_bark,
    graph_matching,
    graph_matching_open,
    graph_matching_displacement,
    feature_aligned,
    feature_aligned_crest,
    feature_aligned_curves,
);

/// The small-setting companion locks in configs/cpu/ (which `.ci/verify-emulated-cpu` checks
/// under emulated CPUs) verify natively too, each with the `--set`
/// overrides it records, and together they cover every method a shipped config uses.
#[test]
fn cpu_companion_locks_verify_and_cover_every_method() {
    let repo = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let method_of = |config: &std::path::Path| -> Option<String> {
        let text = std::fs::read_to_string(config).ok()?;
        let line = text
            .lines()
            .find(|l| l.trim_start().starts_with("method"))?;
        Some(line.split('"').nth(1)?.to_owned())
    };
    let mut shipped: Vec<String> = std::fs::read_dir(repo.join("configs"))
        .unwrap()
        .filter_map(|e| {
            let p = e.unwrap().path();
            (p.extension()? == "toml").then_some(())?;
            method_of(&p)
        })
        .collect();
    shipped.sort();
    shipped.dedup();
    let mut covered = Vec::new();
    for entry in std::fs::read_dir(repo.join("configs/cpu")).unwrap() {
        let lock = entry.unwrap().path();
        let stem = lock.file_stem().unwrap().to_str().unwrap().to_owned();
        let config = repo.join("configs").join(format!("{stem}.toml"));
        let text = std::fs::read_to_string(&lock).unwrap();
        assert!(
            text.lines().any(|l| l.starts_with("# set: ")),
            "{stem}: a companion lock records its small settings"
        );
        covered.push(method_of(&config).expect("a companion lock names a shipped config"));
        verify_fresh(&config, &lock);
    }
    covered.sort();
    covered.dedup();
    assert_eq!(covered, shipped, "configs/cpu/ has one lock per method");
}

/// A sweep's lock (every point's hashes; README, "Sweeps") verifies from an empty cache: the
/// demo's seed sweep, four points sharing one jump map.
#[test]
fn the_demo_seed_sweeps_lock_verifies_from_an_empty_cache() {
    let repo = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    verify_fresh(
        &repo.join("configs/sweeps/demo_seeds.toml"),
        &repo.join("configs/sweeps/demo_seeds.lock"),
    );
}
