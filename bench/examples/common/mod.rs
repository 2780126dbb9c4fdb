//! What the examples share: where they write and how they read their settings. Each example
//! says `mod common;`; helpers shared with the tests come from `tests/it/common/` by `#[path]`.
#![allow(dead_code)] // each example uses a different part

use std::path::PathBuf;

/// The output directory: the first command-line argument, or the system temp directory.
/// Created if missing.
pub fn out_dir() -> PathBuf {
    let dir = std::env::args_os()
        .nth(1)
        .map(PathBuf::from)
        .unwrap_or_else(std::env::temp_dir);
    std::fs::create_dir_all(&dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display()));
    dir
}

/// The environment variable `name` parsed as a `T`, or `default` if it is unset or does not
/// parse.
pub fn env_or<T: std::str::FromStr>(name: &str, default: T) -> T {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

/// The texsyn binary beside the running example's folder (target/release/examples/..).
pub fn texsyn_binary() -> PathBuf {
    let exe = std::env::current_exe().unwrap();
    let bin = exe.parent().unwrap().parent().unwrap().join("texsyn");
    assert!(
        bin.exists(),
        "{}: build it first (cargo build --release)",
        bin.display()
    );
    bin
}
