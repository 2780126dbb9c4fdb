//! Key locks: one process computes a missing key while the others that need it wait for it
//! and then read it from the cache.
//!
//! The primitive is an exclusive `flock` ([`std::fs::File::lock`]) on a per-key lock file,
//! `locks/ab/<key>.lock` under the cache root. It is advisory and only orders the writers:
//! correctness never depends on it, since objects are published by an atomic rename and
//! checked when read (see the module above). So every way locking can fail degrades to what
//! texsyn did without it, a key possibly computed twice:
//! - the kernel drops a lock when its holder dies (killed, crashed), so a stale lock needs no
//!   recovery: the next process takes it at once;
//! - where no lock file can be made (a read-only or foreign-owned cache, `locks` not a folder)
//!   or the filesystem has no locks (`ENOLCK`, `EOPNOTSUPP`, `ENOSYS` on some NFS mounts),
//!   [`KeyLocks::lock`] says [`Locking::Unavailable`] and the caller goes on unlocked;
//! - lock files left behind are harmless; `gc` removes those nobody holds. A file removed
//!   between a waiter's `open` and its `flock` would let two processes hold "the" lock, so a
//!   lock is only taken as held once the locked file is still the one at the path.
//!
//! On NFS (README, "Several processes on one cache"), Linux implements `flock` with the
//! protocol's byte-range locks (NLM for v3, the lock operations of v4), which are seen by
//! every client; a dead client's locks go when its lease expires.

use super::Key;
use std::fs::{self, File};
use std::path::{Path, PathBuf};

pub(crate) const LOCKS_DIR: &str = "locks";
const LOCK_SUFFIX: &str = ".lock";

/// The lock files of one cache.
#[derive(Debug, Clone)]
pub struct KeyLocks {
    dir: PathBuf,
}

/// A held key lock; dropping it releases the lock (closing the file does). The file stays.
#[derive(Debug)]
pub struct KeyLock {
    _file: File,
}

/// The outcome of asking for a key's lock.
#[derive(Debug)]
pub enum Locking {
    /// Held by this process until the guard is dropped.
    Held(KeyLock),
    /// Held by another process (only from [`KeyLocks::try_lock`]).
    Busy,
    /// Locks cannot be used here; the reason, for the warning. Go on unlocked.
    Unavailable(String),
}

impl KeyLocks {
    pub(crate) fn new(root: &Path) -> KeyLocks {
        KeyLocks {
            dir: root.join(LOCKS_DIR),
        }
    }

    /// The lock file of `key`.
    pub fn path(&self, key: &Key) -> PathBuf {
        let hex = key.to_hex();
        self.dir.join(&hex[..2]).join(format!("{hex}{LOCK_SUFFIX}"))
    }

    /// Takes `key`'s lock, waiting as long as another process holds it. `on_wait` is called
    /// once, before waiting, if it has to wait (to say so).
    pub fn lock(&self, key: &Key, on_wait: impl FnOnce()) -> Locking {
        match self.acquire(key, false) {
            Locking::Busy => {
                on_wait();
                self.acquire(key, true)
            }
            other => other,
        }
    }

    /// Takes `key`'s lock if nobody holds it; [`Locking::Busy`] if someone does.
    pub fn try_lock(&self, key: &Key) -> Locking {
        self.acquire(key, false)
    }

    fn acquire(&self, key: &Key, wait: bool) -> Locking {
        let path = self.path(key);
        loop {
            let file = match open_lock_file(&path) {
                Ok(f) => f,
                Err(e) => {
                    return Locking::Unavailable(format!("cannot create {}: {e}", path.display()));
                }
            };
            let locked = if wait {
                file.lock().map(|()| true)
            } else {
                match file.try_lock() {
                    Ok(()) => Ok(true),
                    Err(fs::TryLockError::WouldBlock) => Ok(false),
                    Err(fs::TryLockError::Error(e)) => Err(e),
                }
            };
            match locked {
                Ok(true) if still_at_path(&file, &path) => {
                    return Locking::Held(KeyLock { _file: file });
                }
                // `gc` removed the file we locked (or waited on): take the one there now.
                Ok(true) => continue,
                Ok(false) => return Locking::Busy,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                Err(e) => {
                    return Locking::Unavailable(format!("cannot lock {}: {e}", path.display()));
                }
            }
        }
    }

    /// Removes the lock files nobody holds (`gc`); returns how many. Best effort: a lock
    /// folder that cannot be listed or cleaned is left as it is.
    pub fn remove_unused(&self) -> usize {
        let mut removed = 0;
        let Ok(shards) = fs::read_dir(&self.dir) else {
            return 0;
        };
        for shard in shards.flatten() {
            let Ok(files) = fs::read_dir(shard.path()) else {
                continue;
            };
            for f in files.flatten() {
                let path = f.path();
                if !f.file_name().to_string_lossy().ends_with(LOCK_SUFFIX) {
                    continue;
                }
                // Held while removing, so a process that opens the file now waits on it and
                // then sees (by `still_at_path`) that it was removed, and takes a new one.
                let Ok(file) = File::options().read(true).write(true).open(&path) else {
                    continue;
                };
                if file.try_lock().is_ok() && fs::remove_file(&path).is_ok() {
                    removed += 1;
                }
            }
            let _ = fs::remove_dir(shard.path()); // only if empty
        }
        removed
    }
}

fn open_lock_file(path: &Path) -> std::io::Result<File> {
    let open = || {
        File::options()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(path)
    };
    match open() {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            fs::create_dir_all(path.parent().expect("lock paths have a parent"))?;
            open()
        }
        other => other,
    }
}

/// Whether the locked `file` is still the file at `path` (not removed by `gc` meanwhile).
#[cfg(unix)]
fn still_at_path(file: &File, path: &Path) -> bool {
    use std::os::unix::fs::MetadataExt;
    match (file.metadata(), fs::metadata(path)) {
        (Ok(a), Ok(b)) => a.dev() == b.dev() && a.ino() == b.ino(),
        _ => false,
    }
}

#[cfg(not(unix))]
fn still_at_path(_: &File, path: &Path) -> bool {
    path.exists()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::artifact::ContentHash;

    #[test]
    fn a_held_lock_is_busy_for_another_handle_until_dropped() {
        let dir = tempfile::tempdir().unwrap();
        let locks = KeyLocks::new(dir.path());
        let key = ContentHash::of(b"k");
        let Locking::Held(held) = locks.lock(&key, || panic!("nobody holds it")) else {
            panic!("expected the lock");
        };
        // flock locks belong to the open file, so a second handle in this process conflicts
        // like another process would.
        assert!(matches!(locks.try_lock(&key), Locking::Busy));
        drop(held);
        assert!(matches!(locks.try_lock(&key), Locking::Held(_)));
    }

    #[test]
    fn gc_removes_only_unheld_lock_files_and_a_waiter_then_takes_a_fresh_one() {
        let dir = tempfile::tempdir().unwrap();
        let locks = KeyLocks::new(dir.path());
        let (a, b) = (ContentHash::of(b"a"), ContentHash::of(b"b"));
        let Locking::Held(held_a) = locks.try_lock(&a) else {
            panic!()
        };
        drop(locks.try_lock(&b));
        assert_eq!(locks.remove_unused(), 1);
        assert!(locks.path(&a).exists());
        assert!(!locks.path(&b).exists());
        drop(held_a);
        assert!(matches!(locks.lock(&b, || ()), Locking::Held(_)));
    }

    #[test]
    fn a_lock_folder_that_is_a_file_makes_locking_unavailable() {
        let dir = tempfile::tempdir().unwrap();
        fs::write(dir.path().join(LOCKS_DIR), b"not a folder").unwrap();
        let locks = KeyLocks::new(dir.path());
        assert!(matches!(
            locks.lock(&ContentHash::of(b"k"), || ()),
            Locking::Unavailable(_)
        ));
    }
}
