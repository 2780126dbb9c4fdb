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

/// Runs `texsyn args` and returns whether it succeeded, its stderr, and the peak resident
/// set of that child alone in bytes (its own rusage from `wait4`: the test binary's other
/// children, running beside it, do not count).
fn texsyn_peak(args: &[&str], dir: &std::path::Path) -> (bool, String, u64) {
    use std::io::Read;
    #[allow(clippy::zombie_processes)] // reaped by wait4 below, which gives its rusage
    let mut child = Command::new(env!("CARGO_BIN_EXE_texsyn"))
        .args(args)
        .args(["--cache", &dir.join("cache").to_string_lossy()])
        .args(["--out", &dir.join("out").to_string_lossy()])
        .arg("--quiet")
        .current_dir(repo())
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut stderr = String::new();
    child
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut stderr)
        .unwrap();
    let mut status = 0;
    let mut u: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: the pid is our unreaped child; wait4 writes into the two values we pass.
    let pid = unsafe { libc::wait4(child.id() as libc::pid_t, &mut status, 0, &mut u) };
    assert_eq!(pid, child.id() as libc::pid_t, "wait4 failed");
    let ok = libc::WIFEXITED(status) && libc::WEXITSTATUS(status) == 0;
    (ok, stderr, u.ru_maxrss as u64 * 1024)
}

#[test]
fn estimates_are_within_twice_the_measured_peak() {
    crate::full_tier_only!("inputs sized to measure memory");
    let dir = tempfile::tempdir().unwrap();
    let cases: [(&[&str], u64); 3] = [
        (
            // A solid section: dense masks over the volume's box, half a byte per voxel of the
            // cube bound (72 MB measured at 384).
            &[
                "run",
                "configs/solid_trivial.toml",
                "--set",
                "parameterize.resolution=384",
                "--set",
                "parameterize.request={kind=\"section\",point=[0.0,0.0,0.0],normal=[0.0,0.0,1.0]}",
            ],
            384 * 384 * 384 / 2 + (48 << 20),
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
            // Geometry-image texel variants: 8 orientations, 3 scales (4^-1 + 1 + 4).
            &[
                "run",
                "configs/dragon_knot.toml",
                "--set",
                "analyse_exemplar.scales=3",
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
    // The same for the per-triangle baked atlas (solid and feature-aligned; jump maps' chart
    // pages follow the surface's area and are not estimated).
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
    // scales; the default k-coherence search needs no such structures and no check).
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
