//! The local one-node Slurm cluster (scripts/slurm-local), started once per test binary, for
//! the tests that submit to it (slurm.rs, sweep_slurm.rs).

use std::io::Write;
use std::path::Path;
use std::process::Command;
use std::sync::OnceLock;

/// Starts the local cluster once; false (after a loud SKIPPED line) outside the full tier or
/// with TEXSYN_NO_SLURM=1.
pub fn cluster(test: &str) -> bool {
    if !super::full_tier() {
        super::say_skipped("the one-node Slurm cluster");
        return false;
    }
    if std::env::var_os("TEXSYN_NO_SLURM").is_some_and(|v| v == "1") {
        // Straight to the process's stderr: libtest would swallow eprintln! of a passing test.
        let _ = writeln!(
            std::io::stderr(),
            "\n*** SKIPPED: {test}: TEXSYN_NO_SLURM=1, the Slurm integration tests did not run ***\n"
        );
        return false;
    }
    static STARTED: OnceLock<Result<(), String>> = OnceLock::new();
    let started = STARTED.get_or_init(|| {
        let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/slurm-local");
        match Command::new(&script).arg("start").output() {
            Ok(out) if out.status.success() => Ok(()),
            Ok(out) => Err(format!(
                "{} exited with {}:\n{}{}",
                script.display(),
                out.status,
                String::from_utf8_lossy(&out.stdout),
                String::from_utf8_lossy(&out.stderr)
            )),
            Err(e) => Err(format!("{} could not be run: {e}", script.display())),
        }
    });
    if let Err(why) = started {
        panic!(
            "the local Slurm cluster could not be started, so the Slurm tests cannot run (they \
             need root and apt-get or dnf; set TEXSYN_NO_SLURM=1 to skip them loudly):\n{why}"
        );
    }
    true
}
