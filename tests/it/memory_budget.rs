//! The memory budget: a parameter whose estimated need is over the budget
//! is refused before work starts, naming a value that fits; and the estimates are within 2×
//! of what a run really takes (peak resident memory of the child process).

use crate::common;
use common::repo;
use std::process::Command;

fn texsyn(args: &[&str], dir: &std::path::Path) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_texsyn"))
        .args(args)
        .args(["--cache", &dir.join("cache").to_string_lossy()])
        .args(["--out", &dir.join("out").to_string_lossy()])
        .arg("--quiet")
        .current_dir(repo())
        .output()
        .unwrap()
}

/// Runs `texsyn args` with `--report` and returns whether it succeeded, its stderr, and the
/// run's own peak resident set in bytes (`peak_memory_bytes`: the process's VmHWM). Not the
/// child's rusage: Linux carries the parent's peak into a forked child's `ru_maxrss` across
/// exec, and this test binary's other tests make that parent large.
fn texsyn_peak(args: &[&str], dir: &std::path::Path) -> (bool, String, u64) {
    let report = dir.join("report.json");
    let _ = std::fs::remove_file(&report);
    let out = Command::new(env!("CARGO_BIN_EXE_texsyn"))
        .args(args)
        .args(["--cache", &dir.join("cache").to_string_lossy()])
        .args(["--out", &dir.join("out").to_string_lossy()])
        .arg("--report")
        .arg(&report)
        .arg("--quiet")
        .current_dir(repo())
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    if !out.status.success() {
        return (false, stderr, 0);
    }
    let peak = texsyn::ops::sweep::RunReport::read(&report)
        .and_then(|r| r.peak_memory_bytes)
        .expect("the run's report gives its peak memory (Linux)");
    (true, stderr, peak)
}

#[test]
fn estimates_are_within_twice_the_measured_peak() {
    crate::full_tier_only!("inputs sized to measure memory");
    let dir = tempfile::tempdir().unwrap();
    let cases: [(&[&str], u64); 5] = [
        (
            // Jump maps' chart pages: 16 bytes per page texel (one 5704×4980 page, 469 MB
            // measured).
            &[
                "run",
                "configs/demo.toml",
                "--set",
                "reconstruct.texel_density=16",
                "--set",
                "reconstruct.atlas_size=8192",
            ],
            16 * 5704 * 4980 + (48 << 20),
        ),
        (
            // A preview: 120 bytes per pixel of one view (513 MB measured at 2048).
            &[
                "run",
                "configs/demo.toml",
                "--set",
                "reconstruct.preview_size=2048",
            ],
            120 * 2048 * 2048 + (48 << 20),
        ),
        (
            // A solid section: about two bytes per voxel of the cube bound (158 MiB measured
            // at 384).
            &[
                "run",
                "configs/solid_trivial.toml",
                "--set",
                "parameterize.resolution=384",
                "--set",
                "parameterize.request={kind=\"section\",point=[0.0,0.0,0.0],normal=[0.0,0.0,1.0]}",
            ],
            2 * 384 * 384 * 384 + (48 << 20),
        ),
        (
            &[
                "run",
                "configs/synth2d.toml",
                "--set",
                "synthesize.width=2048",
                "--set",
                "synthesize.height=2048",
            ],
            52 * 2048 * 2048 + (32 << 20),
        ),
        (
            // Geometry-image texel variants with the template synthesizer's per-texel search
            // structures: 8 orientations, 3 scales (4^-1 + 1 + 4).
            &[
                "run",
                "configs/dragon_knot.toml",
                "--set",
                "analyse_exemplar.scales=3",
                "--set",
                "synthesize.algorithm=\"template\"",
                "--set",
                "synthesize.search=\"per_texel\"",
            ],
            (580.0 * 8.0 * 5.25) as u64 * 128 * 128 + (64 << 20),
        ),
    ];
    for (args, estimate) in cases {
        let (ok, stderr, peak) = texsyn_peak(args, dir.path());
        assert!(ok, "{stderr}");
        assert!(
            estimate as f64 <= 2.0 * peak as f64 && peak as f64 <= 2.0 * estimate as f64,
            "{args:?}: estimate {estimate} B, measured peak {peak} B"
        );
    }
}

/// Each estimated parameter past the budget is refused before any work, naming a value that
/// fits.
#[test]
fn oversized_runs_are_refused_naming_a_value_that_fits() {
    let dir = tempfile::tempdir().unwrap();
    // 16384² is inside synthesize.width's range but not inside 4 GiB.
    let out = texsyn(
        &[
            "run",
            "configs/synth2d.toml",
            "--max-memory",
            "4GiB",
            "--set",
            "synthesize.width=16384",
            "--set",
            "synthesize.height=16384",
        ],
        dir.path(),
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("synthesize.width = 16384") && err.contains("fits") && err.contains("4.0 GiB"),
        "{err}"
    );
    // The same for the per-triangle baked atlas (solid and feature-aligned).
    let out = texsyn(
        &[
            "run",
            "configs/solid_trivial.toml",
            "--max-memory",
            "64MiB",
            "--set",
            "reconstruct.atlas_size=8192",
        ],
        dir.path(),
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("reconstruct.atlas_size = 8192") && err.contains("fits"),
        "{err}"
    );
    // And for a geometry-image sample's per-texel variants (5.9 GB measured at 256² with 5
    // scales; only the template synthesizer's per-texel search builds them, so only it is
    // checked).
    let out = texsyn(
        &[
            "run",
            "configs/dragon_knot.toml",
            "--max-memory",
            "1GiB",
            "--set",
            "extract.size=256",
            "--set",
            "analyse_exemplar.scales=5",
            "--set",
            "synthesize.algorithm=\"template\"",
            "--set",
            "synthesize.search=\"per_texel\"",
        ],
        dir.path(),
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("extract.size = 256") && err.contains("fits"),
        "{err}"
    );
    // And for jump maps' chart pages, which follow the surface's area: refused once the
    // charts are laid out, before the bake (469 MB measured at density 16).
    let out = texsyn(
        &[
            "run",
            "configs/demo.toml",
            "--max-memory",
            "100MiB",
            "--set",
            "reconstruct.texel_density=16",
            "--set",
            "reconstruct.atlas_size=8192",
        ],
        dir.path(),
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("reconstruct.texel_density = 16.00") && err.contains("fits"),
        "{err}"
    );
    assert!(!dir.path().join("out").exists(), "no outputs written");
    // And for a preview (1.9 GB measured at 4096).
    let out = texsyn(
        &[
            "run",
            "configs/demo.toml",
            "--max-memory",
            "100MiB",
            "--set",
            "reconstruct.preview_size=4096",
        ],
        dir.path(),
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("reconstruct.preview_size = 4096") && err.contains("fits"),
        "{err}"
    );
    // And for a solid's resolution (a surface request: 16 bytes per voxel of the cube bound up
    // to the batch bound, and half a byte per voxel for the volume's masks).
    let out = texsyn(
        &[
            "run",
            "configs/solid_trivial.toml",
            "--max-memory",
            "1GiB",
            "--set",
            "parameterize.resolution=4096",
        ],
        dir.path(),
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("parameterize.resolution = 4096") && err.contains("fits"),
        "{err}"
    );
}
