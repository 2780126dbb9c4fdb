//! Running the `texsyn` binary as a user does, and looking at what it left: shared by the
//! command-line tests (cli.rs, pack.rs, score.rs).

use std::path::Path;
use std::process::{Command, Output};

/// `texsyn ARGS` in `cwd`.
pub fn texsyn(args: &[&str], cwd: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_texsyn"))
        .args(args)
        .current_dir(cwd)
        .output()
        .expect("texsyn runs")
}

/// `o`, once asserted to be the output of a command that succeeded (its output tells why not).
pub fn succeeded(o: Output) -> Output {
    assert!(o.status.success(), "{}{}", stdout(&o), stderr(&o));
    o
}

pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

pub fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// The number of objects in the cache at `cache`.
pub fn object_count(cache: &Path) -> usize {
    files_under(&cache.join("objects-v1"))
}

fn files_under(dir: &Path) -> usize {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return 0;
    };
    entries
        .flatten()
        .map(|e| {
            if e.path().is_dir() {
                files_under(&e.path())
            } else {
                1
            }
        })
        .sum()
}
