//! Values a plan works out from its inputs at some cost, remembered in the cache so that a
//! rerun with nothing changed plans in milliseconds, as its nodes come from the cache.
//!
//! A memo lives at `CACHE/plan-memo/KEY`, `KEY` the hash of everything the value is a
//! function of, the version of the rule that computes it included (so a changed rule never
//! reads an old value). It is a cache: a missing, damaged or unreadable memo is worked out
//! again, and one that cannot be written is not written; memos are written without fsync
//! (temporary file, then rename), and only into a cache folder that exists (a mistyped
//! `--cache` is never made). Only `texsyn run` remembers ([`remember_in`]), and not with
//! `--recheck`; every other command (`verify` above all), the library and its tests work
//! every value out.

use crate::artifact::ContentHash;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// The memos' folder inside a cache. `gc` leaves memos alone (a few bytes each, and a
/// trimmed one costs a rerun its fit again) and removes the temporaries of dead writers.
pub const MEMOS: &str = crate::cache::PLAN_MEMO_DIR;

static DIR: OnceLock<PathBuf> = OnceLock::new();

/// Remembers plan values in `dir` (a cache's [`MEMOS`] folder) for the rest of the process.
/// The first call wins.
pub fn remember_in(dir: PathBuf) {
    let _ = DIR.set(dir);
}

/// The number remembered under `key` if `valid` takes it, else `compute()`'s, which is
/// remembered when `valid` takes it. A memo is the number's 4 little-endian bytes.
pub(crate) fn number(
    key: &ContentHash,
    valid: impl Fn(f32) -> bool,
    compute: impl FnOnce() -> f32,
) -> f32 {
    match DIR.get() {
        Some(dir) => number_in(dir, key, valid, compute),
        None => compute(),
    }
}

fn number_in(
    dir: &Path,
    key: &ContentHash,
    valid: impl Fn(f32) -> bool,
    compute: impl FnOnce() -> f32,
) -> f32 {
    let path = dir.join(key.to_hex());
    let read = std::fs::read(&path).ok();
    if let Some(x) = read.and_then(|b| <[u8; 4]>::try_from(b.as_slice()).ok()) {
        let x = f32::from_le_bytes(x);
        if valid(x) {
            return x;
        }
    }
    let x = compute();
    if valid(x) {
        // Temporaries are named as the cache names its own (a leading `.tmp-` and the
        // writer's host and process), so two writers never share one.
        let tmp = dir.join(format!(
            ".tmp-{}-{}",
            crate::owner::Owner::this_tag(),
            key.to_hex()
        ));
        // `create_dir`, not `create_dir_all`: the cache folder itself must already exist.
        let made = match std::fs::create_dir(dir) {
            Err(e) if e.kind() != std::io::ErrorKind::AlreadyExists => Err(e),
            _ => Ok(()),
        };
        let written = made
            .and_then(|()| std::fs::write(&tmp, x.to_le_bytes()))
            .and_then(|()| std::fs::rename(&tmp, &path));
        if let Err(e) = written {
            let _ = std::fs::remove_file(&tmp);
            tracing::debug!("plan memo {}: not written: {e}", path.display());
        }
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_memo_is_read_back_and_a_damaged_one_is_worked_out_again() {
        let d = tempfile::tempdir().unwrap();
        // No cache folder: nothing is made, and the value is still worked out.
        let missing = d.path().join("no cache").join(MEMOS);
        let key = ContentHash::of(b"a key");
        assert_eq!(number_in(&missing, &key, |x| x > 0.0, || 1.5), 1.5);
        assert!(!d.path().join("no cache").exists());
        let dir = d.path().join(MEMOS);
        let positive = |x: f32| x.is_finite() && x > 0.0;
        let calls = std::cell::Cell::new(0);
        let get = |v: f32| {
            number_in(&dir, &key, positive, || {
                calls.set(calls.get() + 1);
                v
            })
        };
        assert_eq!(get(2.5), 2.5);
        // Remembered: the second computation is not asked for.
        assert_eq!(get(7.0), 2.5);
        assert_eq!(calls.get(), 1);
        // A damaged memo is worked out again and replaced.
        std::fs::write(dir.join(key.to_hex()), b"xx").unwrap();
        assert_eq!(get(3.0), 3.0);
        assert_eq!(get(9.0), 3.0);
        assert_eq!(calls.get(), 2);
        // A value that is not positive is returned but not remembered.
        let other = ContentHash::of(b"another key");
        assert_eq!(number_in(&dir, &other, positive, || 0.0), 0.0);
        assert!(!dir.join(other.to_hex()).exists());
        // Nothing but the memos is left in the folder.
        let names: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, vec![std::ffi::OsString::from(key.to_hex())]);
    }
}
