//! The object store (DESIGN.md, "The cache"): one immutable file per artifact under
//! `objects-v1/ab/cdef…`, named by its node key.
//!
//! Writes go to a temporary file in the same directory (files above 16 MiB around the page
//! cache where the filesystem allows, see [`big_write`]), are fsynced, renamed into place, and
//! the directory is fsynced: an artifact is whole or absent, after a crash too. A rename that
//! finds the target already present is success (two processes computed the same key; by
//! determinism they wrote the same bytes); anything else at the path (a directory, a damaged
//! file) is replaced, or the write is an error naming the path. Reads map the file; a header
//! that does not check out (magic, version, kind code, reserved bytes, lengths, metadata) is
//! a miss with a warning, never an error, and the object is removed. Least-recently-used order
//! for `gc` is kept in file modification times, refreshed on every hit.
//!
//! Processes sharing a cache order their work on a key with the key locks of [`lock`]; the
//! store itself needs none.

mod big_write;
mod lock;

pub(crate) use big_write::write_parallel;

pub use lock::{KeyLock, KeyLocks, Locking};

use crate::artifact::{Artifact, ArtifactError, Backing, ContentHash, HEADER_LEN, Header, Kind};
use std::fs::{self, File};
use std::io::Read;
use std::path::{Path, PathBuf};
use std::time::SystemTime;

/// The format version is in the directory name, so a future layout change starts a fresh
/// store beside the old one instead of misreading it.
const OBJECTS_DIR: &str = "objects-v1";
/// Temporary objects are named `.tmp-OWNER-N` (OWNER: [`crate::owner::Owner::tag`]).
const TMP_PREFIX: &str = ".tmp-";
/// Plan values remembered beside the objects (`crate::methods::plan_memo`): a few bytes each,
/// never counted or trimmed by [`Cache::gc`], whose dead writers' temporaries are removed as
/// the objects' are.
pub const PLAN_MEMO_DIR: &str = "plan-memo";

/// A node key: the blake3 hash naming a cache object.
pub type Key = ContentHash;

#[derive(Debug, thiserror::Error)]
pub enum CacheError {
    #[error("cache {path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error(
        "there is no cache folder {path}: run the config first (`texsyn run`), name another \
         cache with --cache, or check it from scratch with `verify --fresh`"
    )]
    Missing { path: PathBuf },
    #[error("cache {path}: cannot replace what is there with the new object: {source}")]
    Replace {
        path: PathBuf,
        source: std::io::Error,
    },
}

/// What `gc` did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct GcReport {
    pub removed: usize,
    pub removed_bytes: u64,
    pub kept_bytes: u64,
}

fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> CacheError + '_ {
    move |source| CacheError::Io {
        path: path.to_owned(),
        source,
    }
}

#[derive(Debug, Clone)]
pub struct Cache {
    root: PathBuf,
}

/// The outcome of looking a key up.
pub enum Lookup {
    Hit(Artifact),
    Miss,
    /// Present but unreadable; the file was removed and the reason is given for the warning.
    Invalid(ArtifactError),
}

impl Cache {
    /// Opens (creating if needed) a cache rooted at `root`, and removes stale temporary files.
    pub fn open(root: &Path) -> Result<Cache, CacheError> {
        let objects = root.join(OBJECTS_DIR);
        fs::create_dir_all(&objects).map_err(io_err(&objects))?;
        let cache = Cache {
            root: root.to_owned(),
        };
        cache.remove_stale_temporaries();
        Ok(cache)
    }

    /// Opens a cache that must already exist (`gc`, `verify`): a mistyped path is an error
    /// naming it, not a new empty cache. Creates nothing.
    pub fn open_existing(root: &Path) -> Result<Cache, CacheError> {
        if !root.is_dir() {
            return Err(CacheError::Missing {
                path: root.to_owned(),
            });
        }
        let cache = Cache {
            root: root.to_owned(),
        };
        cache.remove_stale_temporaries();
        Ok(cache)
    }

    pub fn root(&self) -> &Path {
        &self.root
    }

    /// The cache's key locks (`locks/` beside the objects).
    pub fn locks(&self) -> KeyLocks {
        KeyLocks::new(&self.root)
    }

    pub fn object_path(&self, key: &Key) -> PathBuf {
        let hex = key.to_hex();
        self.root.join(OBJECTS_DIR).join(&hex[..2]).join(&hex[2..])
    }

    /// Reads only the header and metadata of the object for `key`: enough to learn its
    /// content hash without touching the payload (what a rerun with nothing changed needs).
    /// Any kind is accepted; see [`Cache::peek_kind`].
    pub fn peek(&self, key: &Key) -> Lookup {
        self.peek_kind(key, None)
    }

    /// [`Cache::peek`] for an object that must hold `expected` (the node's output kind). An
    /// object that fails any check (not a regular file, header, lengths, metadata, kind) is
    /// removed and reported as [`Lookup::Invalid`].
    pub fn peek_kind(&self, key: &Key, expected: Option<Kind>) -> Lookup {
        let path = self.object_path(key);
        let meta = match fs::symlink_metadata(&path) {
            Ok(m) => m,
            Err(_) => return Lookup::Miss,
        };
        if !meta.is_file() {
            self.remove(key);
            return Lookup::Invalid(ArtifactError::NotAFile);
        }
        let mut file = match File::open(&path) {
            Ok(f) => f,
            Err(_) => return Lookup::Miss,
        };
        let len = match file.metadata() {
            Ok(m) => m.len() as usize,
            Err(_) => return Lookup::Miss,
        };
        let mut head = [0u8; HEADER_LEN];
        let read = read_up_to(&mut file, &mut head);
        let checked = Header::parse(&head[..read], Some(len)).and_then(|h| match expected {
            Some(kind) if h.kind != kind as u32 => Err(ArtifactError::WrongKind {
                found: h.kind,
                expected: kind,
            }),
            _ => Ok(h),
        });
        match checked {
            Ok(_) => {
                touch(&file);
                self.get_mapped(key, file)
            }
            Err(e) => {
                self.remove(key);
                Lookup::Invalid(e)
            }
        }
    }

    fn get_mapped(&self, key: &Key, file: File) -> Lookup {
        // Safety: cache objects are immutable once renamed into place, and texsyn never
        // writes to them afterwards; another process could only replace the path (rename),
        // which leaves our mapping of the old inode intact.
        let map = match unsafe { memmap2::Mmap::map(&file) } {
            Ok(m) => m,
            Err(e) => return Lookup::Invalid(ArtifactError::Meta(e.to_string())),
        };
        match Artifact::open(Backing::Mapped(map)) {
            Ok(a) => Lookup::Hit(a),
            Err(e) => {
                self.remove(key);
                Lookup::Invalid(e)
            }
        }
    }

    /// Removes an object (found damaged), whatever is at its path. Best effort: a path that
    /// cannot be cleared is reported by the [`Cache::put`] that replaces it.
    pub fn remove(&self, key: &Key) {
        let _ = remove_any(&self.object_path(key));
    }

    /// Stores artifact bytes under `key` atomically and returns the mapped artifact.
    pub fn put(&self, key: &Key, bytes: &[u8]) -> Result<(), CacheError> {
        let path = self.object_path(key);
        let dir = path.parent().expect("object paths have a parent");
        fs::create_dir_all(dir).map_err(io_err(dir))?;
        let tmp = dir.join(format!(
            "{TMP_PREFIX}{}-{}",
            crate::owner::Owner::this_tag(),
            unique_suffix()
        ));
        let write = || -> std::io::Result<()> {
            let f = File::create(&tmp)?;
            write_parallel(&f, bytes)?;
            f.sync_all()?;
            Ok(())
        };
        if let Err(e) = write() {
            let _ = fs::remove_file(&tmp);
            return Err(io_err(&tmp)(e));
        }
        if let Err(e) = fs::rename(&tmp, &path) {
            // Another process may have stored the same key (same bytes, by determinism):
            // success. Anything else there (a directory, other bytes) is cleared and the
            // rename retried; if that fails too, the error names the path.
            let same = fs::symlink_metadata(&path).is_ok_and(|m| m.is_file())
                && fs::read(&path).is_ok_and(|b| b == bytes);
            if !same {
                let retried = remove_any(&path).and_then(|()| fs::rename(&tmp, &path));
                if let Err(again) = retried {
                    let _ = fs::remove_file(&tmp);
                    let source = if again.kind() == std::io::ErrorKind::NotFound {
                        e
                    } else {
                        again
                    };
                    return Err(CacheError::Replace { path, source });
                }
            } else {
                let _ = fs::remove_file(&tmp);
            }
        }
        if let Ok(d) = File::open(dir) {
            let _ = d.sync_all();
        }
        Ok(())
    }

    /// All objects with their sizes and last-use times (none if the store was never
    /// written); a store that cannot be listed is an error naming the directory.
    pub fn objects(&self) -> Result<Vec<(PathBuf, u64, SystemTime)>, CacheError> {
        let mut out = Vec::new();
        let dir = self.root.join(OBJECTS_DIR);
        let shards = match fs::read_dir(&dir) {
            Ok(s) => s,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(out),
            Err(e) => return Err(io_err(&dir)(e)),
        };
        for shard in shards {
            let shard = shard.map_err(io_err(&dir))?.path();
            if !shard.is_dir() {
                continue;
            }
            let files = fs::read_dir(&shard).map_err(io_err(&shard))?;
            for f in files {
                let f = f.map_err(io_err(&shard))?;
                let name = f.file_name();
                if name.to_string_lossy().starts_with(TMP_PREFIX) {
                    continue;
                }
                if let Ok(m) = f.metadata() {
                    let t = m.modified().unwrap_or(SystemTime::UNIX_EPOCH);
                    out.push((f.path(), m.len(), t));
                }
            }
        }
        out.sort();
        Ok(out)
    }

    /// Deletes least recently used objects until the store is within `max_bytes`. An object
    /// that cannot be removed is an error naming it (a read-only cache cannot be trimmed).
    /// Also removes the key lock files no process holds (they are not counted as objects).
    pub fn gc(&self, max_bytes: u64) -> Result<GcReport, CacheError> {
        let mut objects = self.objects()?;
        // Oldest first; ties by path so the choice is deterministic.
        objects.sort_by(|a, b| a.2.cmp(&b.2).then_with(|| a.0.cmp(&b.0)));
        let mut total: u64 = objects.iter().map(|o| o.1).sum();
        let (mut removed, mut removed_bytes) = (0, 0);
        for (path, size, _) in objects {
            if total <= max_bytes {
                break;
            }
            remove_any(&path).map_err(io_err(&path))?;
            total -= size;
            removed += 1;
            removed_bytes += size;
        }
        self.locks().remove_unused();
        Ok(GcReport {
            removed,
            removed_bytes,
            kept_bytes: total,
        })
    }

    /// Removes temporary objects and plan memos whose writer is provably dead, or that are older than
    /// [`crate::owner::STALE_AGE`] (a writer on another host or in another PID namespace);
    /// never this process's own.
    fn remove_stale_temporaries(&self) {
        let shards = fs::read_dir(self.root.join(OBJECTS_DIR))
            .into_iter()
            .flatten();
        let folders = (shards.flatten().map(|s| s.path())).chain([self.root.join(PLAN_MEMO_DIR)]);
        for folder in folders {
            let Ok(files) = fs::read_dir(folder) else {
                continue;
            };
            for f in files.flatten() {
                let name = f.file_name();
                let name = name.to_string_lossy();
                let Some(rest) = name.strip_prefix(TMP_PREFIX) else {
                    continue;
                };
                let owner = rest
                    .split_once('-')
                    .and_then(|(tag, _)| crate::owner::Owner::parse(tag));
                if crate::owner::may_remove(owner.as_ref(), &f.path(), false) {
                    let _ = fs::remove_file(f.path());
                }
            }
        }
    }
}

/// Removes whatever is at `path` (a file, a link, a directory tree); absent is success.
fn remove_any(path: &Path) -> std::io::Result<()> {
    let result = match fs::symlink_metadata(path) {
        Ok(m) if m.is_dir() => fs::remove_dir_all(path),
        Ok(_) => fs::remove_file(path),
        Err(e) => Err(e),
    };
    match result {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        other => other,
    }
}

fn read_up_to(file: &mut File, buf: &mut [u8]) -> usize {
    let mut n = 0;
    while n < buf.len() {
        match file.read(&mut buf[n..]) {
            Ok(0) | Err(_) => break,
            Ok(k) => n += k,
        }
    }
    n
}

/// Marks an object as recently used (for `gc`). Best effort: a read-only cache still works.
fn touch(file: &File) {
    let _ = file.set_modified(SystemTime::now());
}

fn unique_suffix() -> u64 {
    use std::sync::atomic::{AtomicU64, Ordering};
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let nanos = SystemTime::now()
        .duration_since(SystemTime::UNIX_EPOCH)
        .map(|d| d.as_nanos() as u64)
        .unwrap_or(0);
    nanos
        ^ COUNTER
            .fetch_add(1, Ordering::Relaxed)
            .wrapping_mul(0x9E37_79B9_7F4A_7C15)
}

/// A size on the command line that cannot be read.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SizeError {
    #[error("{0:?} is not a size (examples: 500M, 2G, 1000000)")]
    NotANumber(String),
    #[error("{given:?}: unknown size unit {unit:?} (use K, M, G or T)")]
    Unit { given: String, unit: String },
}

/// Parses sizes like `500M`, `2G`, `1.5GiB`, `1000000`.
pub fn parse_size(s: &str) -> Result<u64, SizeError> {
    let t = s.trim();
    let split = t
        .find(|c: char| !(c.is_ascii_digit() || c == '.'))
        .unwrap_or(t.len());
    let (num, unit) = t.split_at(split);
    let value: f64 = num
        .parse()
        .map_err(|_| SizeError::NotANumber(s.to_owned()))?;
    let mult: f64 = match unit.trim().to_ascii_lowercase().as_str() {
        "" | "b" => 1.0,
        "k" | "kb" | "kib" => 1024.0,
        "m" | "mb" | "mib" => 1024.0 * 1024.0,
        "g" | "gb" | "gib" => 1024.0 * 1024.0 * 1024.0,
        "t" | "tb" | "tib" => 1024.0f64.powi(4),
        other => {
            return Err(SizeError::Unit {
                given: s.to_owned(),
                unit: other.to_owned(),
            });
        }
    };
    Ok((value * mult) as u64)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::artifact::{ArtifactWriter, Kind};
    use std::time::Duration;

    fn art(v: f32) -> Vec<u8> {
        ArtifactWriter::new(Kind::Image, &1u8)
            .array("x", &[v; 100])
            .finish()
            .to_vec()
    }

    #[test]
    fn put_then_peek_hits_with_the_same_content_hash() {
        let dir = tempfile::tempdir().unwrap();
        let cache = Cache::open(dir.path()).unwrap();
        let key = ContentHash::of(b"k");
        assert!(matches!(cache.peek(&key), Lookup::Miss));
        let bytes = art(1.0);
        cache.put(&key, &bytes).unwrap();
        cache.put(&key, &bytes).unwrap(); // a second writer of the same key is harmless
        match cache.peek(&key) {
            Lookup::Hit(a) => {
                assert_eq!(a.file_bytes(), &bytes[..]);
                a.verify().unwrap();
            }
            _ => panic!("expected a hit"),
        }
    }

    #[test]
    fn truncated_object_is_a_miss_and_is_removed() {
        let dir = tempfile::tempdir().unwrap();
        let cache = Cache::open(dir.path()).unwrap();
        let key = ContentHash::of(b"k");
        let bytes = art(2.0);
        cache.put(&key, &bytes).unwrap();
        fs::write(cache.object_path(&key), &bytes[..bytes.len() - 10]).unwrap();
        assert!(matches!(cache.peek(&key), Lookup::Invalid(_)));
        assert!(!cache.object_path(&key).exists());
    }

    #[test]
    fn gc_removes_least_recently_used_first() {
        let dir = tempfile::tempdir().unwrap();
        let cache = Cache::open(dir.path()).unwrap();
        let keys: Vec<Key> = (0..3u8).map(|i| ContentHash::of(&[i])).collect();
        for (i, k) in keys.iter().enumerate() {
            cache.put(k, &art(i as f32)).unwrap();
            let f = File::options()
                .write(true)
                .open(cache.object_path(k))
                .unwrap();
            f.set_modified(SystemTime::UNIX_EPOCH + Duration::from_secs(1000 + i as u64))
                .unwrap();
        }
        // Use the oldest one: it becomes the newest.
        assert!(matches!(cache.peek(&keys[0]), Lookup::Hit(_)));
        let one = fs::metadata(cache.object_path(&keys[0])).unwrap().len();
        let report = cache.gc(one).unwrap();
        assert_eq!(report.removed, 2);
        assert_eq!(report.kept_bytes, one);
        assert!(cache.object_path(&keys[0]).exists());
        assert!(!cache.object_path(&keys[1]).exists());
    }

    /// A directory where an object belongs is a miss (not "shorter than
    /// its header"), and storing the object replaces it.
    #[test]
    fn a_directory_at_an_object_path_is_replaced() {
        let dir = tempfile::tempdir().unwrap();
        let cache = Cache::open(dir.path()).unwrap();
        let key = ContentHash::of(b"k");
        let path = cache.object_path(&key);
        fs::create_dir_all(path.join("inside")).unwrap();
        fs::write(path.join("inside/file"), b"x").unwrap();
        assert!(matches!(
            cache.peek(&key),
            Lookup::Invalid(ArtifactError::NotAFile)
        ));
        fs::create_dir_all(path.join("inside")).unwrap();
        let bytes = art(3.0);
        cache.put(&key, &bytes).unwrap();
        assert_eq!(fs::read(&path).unwrap(), bytes);
    }

    /// A known kind code that is not the one expected is a miss.
    #[test]
    fn an_object_of_another_kind_is_a_miss_and_is_removed() {
        let dir = tempfile::tempdir().unwrap();
        let cache = Cache::open(dir.path()).unwrap();
        let key = ContentHash::of(b"k");
        cache.put(&key, &art(4.0)).unwrap();
        assert!(matches!(
            cache.peek_kind(&key, Some(Kind::Mesh)),
            Lookup::Invalid(ArtifactError::WrongKind { .. })
        ));
        assert!(!cache.object_path(&key).exists());
    }

    /// A live writer's temporaries stay whatever their age; others of this host, boot and
    /// namespace go once their writer is dead; the rest only past the age limit. The same
    /// holds for the plan memos' folder, whose memos stay.
    #[test]
    fn only_temporaries_of_provably_dead_writers_or_past_the_age_limit_are_removed() {
        let dir = tempfile::tempdir().unwrap();
        let memos = dir.path().join(PLAN_MEMO_DIR);
        fs::create_dir_all(&memos).unwrap();
        let memo = "00ff".repeat(16);
        fs::write(memos.join(&memo), 1.0f32.to_le_bytes()).unwrap();
        for shard in [dir.path().join(OBJECTS_DIR).join("ab"), memos] {
            fs::create_dir_all(&shard).unwrap();
            let mut left = stale_temporaries_removed_from(dir.path(), &shard);
            if shard.ends_with(PLAN_MEMO_DIR) {
                assert!(
                    left.remove(&memo),
                    "{}: the memo was removed",
                    shard.display()
                );
            }
            assert!(left.is_empty(), "{}: left {left:?}", shard.display());
        }
    }

    /// Writes temporaries of live, dead and foreign writers into `shard` of the cache at
    /// `root`, opens the cache, and returns the names left that were not expected to be.
    fn stale_temporaries_removed_from(
        root: &Path,
        shard: &Path,
    ) -> std::collections::BTreeSet<String> {
        use crate::owner::{Owner, STALE_AGE};
        let mut child = std::process::Command::new("true").spawn().unwrap();
        let dead_pid = child.id();
        child.wait().unwrap();
        let dead = format!("{TMP_PREFIX}{}-1", Owner::with_pid(dead_pid).tag());
        let mine = format!("{TMP_PREFIX}{}-2", Owner::this().tag());
        // Another PID namespace (a container, another host over NFS): not checkable here.
        let mut parts: Vec<String> = Owner::this().tag().split('_').map(String::from).collect();
        parts[2] = "1".into();
        parts[3] = dead_pid.to_string();
        let foreign = parts.join("_");
        let foreign_young = format!("{TMP_PREFIX}{foreign}-3");
        let foreign_old = format!("{TMP_PREFIX}{foreign}-4");
        let bare_pid = format!("{TMP_PREFIX}{dead_pid}-5");
        // A long-lived writer of this namespace (init is alive while the test runs).
        let alive_old = format!("{TMP_PREFIX}{}-6", Owner::with_pid(1).tag());
        for n in [
            &dead,
            &mine,
            &foreign_young,
            &foreign_old,
            &bare_pid,
            &alive_old,
        ] {
            fs::write(shard.join(n), b"half").unwrap();
        }
        let past = SystemTime::now() - STALE_AGE - std::time::Duration::from_secs(60);
        for n in [&foreign_old, &alive_old] {
            let f = File::options().write(true).open(shard.join(n)).unwrap();
            f.set_modified(past).unwrap();
        }
        Cache::open(root).unwrap();
        let mut left: std::collections::BTreeSet<String> = fs::read_dir(shard)
            .unwrap()
            .map(|e| e.unwrap().file_name().into_string().unwrap())
            .collect();
        let mut expected = vec![mine, foreign_young, bare_pid];
        if cfg!(target_os = "linux") {
            expected.push(alive_old);
        } else {
            expected.push(dead);
        }
        for e in &expected {
            assert!(left.remove(e), "{}: {e} was removed", shard.display());
        }
        left
    }

    /// `gc` and `verify` do not create a cache that is not there.
    #[test]
    fn open_existing_refuses_a_missing_cache_and_creates_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let missing = dir.path().join("typo");
        let e = Cache::open_existing(&missing).err();
        assert!(matches!(e, Some(CacheError::Missing { .. })));
        // The message names the folder it looked for and what to do.
        let msg = e.unwrap().to_string();
        assert!(
            msg.contains(&missing.display().to_string()) && msg.contains("--fresh"),
            "{msg}"
        );
        assert!(!missing.exists());
    }

    #[test]
    fn sizes_parse_with_units() {
        assert_eq!(parse_size("1000").unwrap(), 1000);
        assert_eq!(parse_size("2K").unwrap(), 2048);
        assert_eq!(parse_size("1.5G").unwrap(), 1610612736);
        assert!(parse_size("big").is_err());
        assert!(parse_size("5X").is_err());
    }
}
