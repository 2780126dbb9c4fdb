//! What an output folder's files looked like when texsyn last wrote or read them, so a rerun
//! with nothing changed trusts a file by its stat instead of reading and hashing it, as make
//! and ninja trust a timestamp.
//!
//! The record holds, per output name, its content hash and the stat it had (length,
//! modification and change times in nanoseconds, inode and device). A file is trusted when its
//! stat is the recorded one and the recorded hash is the one the run wants. Anything that
//! rewrites a file changes its change time (which no user call can set back), copying a folder
//! changes the inodes, so an edited, replaced or copied file is read again.
//!
//! Records live in the cache, not in the output folder, so the folder holds nothing but the
//! outputs (a CI job may compare two folders byte for byte): `CACHE/output-stamps/HASH`, the
//! hash being that of the folder's canonical path. Another cache, or a moved folder, has no
//! record and reads the files once.
//!
//! A file modified within the same clock tick as the record was written could keep its
//! stat (file times are coarse, a few milliseconds); as git does with its index, a stamp whose
//! file is not older than the record itself is not trusted ("racily clean"): such a file is
//! hashed on the next run, which then writes a record it can trust.
//!
//! The record is a cache: losing it, or a damaged one, costs one full read; it is written
//! without fsync (temporary file, then rename) and only when it changes. `texsyn run
//! --recheck` and `texsyn verify` ignore it.

use crate::artifact::ContentHash;
use std::collections::BTreeMap;
use std::fs;
use std::path::Path;

/// The folder of the records inside a cache.
pub const RECORDS: &str = "output-stamps";
const HEAD: &str = "texsyn output stamps 1";

/// Where the record of output folder `dir` is kept among `records` (a cache's
/// [`RECORDS`] folder); `None` when `dir` cannot be resolved (then nothing is trusted).
pub fn record_path(records: &Path, dir: &Path) -> Option<std::path::PathBuf> {
    let canonical = dir.canonicalize().ok()?;
    let hash = ContentHash::of(canonical.as_os_str().as_encoded_bytes());
    Some(records.join(hash.to_hex()))
}

/// A file's stat, as far as trusting it goes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FileStat {
    len: u64,
    mtime_ns: i128,
    ctime_ns: i128,
    ino: u64,
    dev: u64,
}

impl FileStat {
    /// The stat of a regular file; `None` for anything else, and where the platform does
    /// not give inodes and change times (nothing is trusted there).
    pub fn of(meta: &fs::Metadata) -> Option<FileStat> {
        #[cfg(unix)]
        {
            use std::os::unix::fs::MetadataExt;
            meta.is_file().then(|| FileStat {
                len: meta.len(),
                mtime_ns: meta.mtime() as i128 * 1_000_000_000 + meta.mtime_nsec() as i128,
                ctime_ns: meta.ctime() as i128 * 1_000_000_000 + meta.ctime_nsec() as i128,
                ino: meta.ino(),
                dev: meta.dev(),
            })
        }
        #[cfg(not(unix))]
        {
            let _ = meta;
            None
        }
    }
}

/// The stamps of one output folder, by file name.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Stamps {
    files: BTreeMap<String, (FileStat, ContentHash)>,
    /// The record's own modification time when read (stamps of files not older are racy).
    written_ns: Option<i128>,
}

impl Stamps {
    /// The record at `path`; empty when there is none or it cannot be read.
    pub fn read(path: &Path) -> Stamps {
        let Ok(text) = fs::read_to_string(path) else {
            return Stamps::default();
        };
        let written_ns = fs::metadata(path)
            .ok()
            .and_then(|m| FileStat::of(&m))
            .map(|s| s.mtime_ns);
        let mut lines = text.lines();
        if lines.next() != Some(HEAD) {
            return Stamps::default();
        }
        let mut files = BTreeMap::new();
        for line in lines {
            match parse_line(line) {
                Some((name, stat, hash)) => {
                    files.insert(name, (stat, hash));
                }
                None => return Stamps::default(),
            }
        }
        Stamps { files, written_ns }
    }

    /// Whether the file `name` with metadata `meta` is known to hold content `hash`.
    pub fn vouches(&self, name: &str, meta: &fs::Metadata, hash: &ContentHash) -> bool {
        let (Some(stat), Some(written)) = (FileStat::of(meta), self.written_ns) else {
            return false;
        };
        self.files
            .get(name)
            .is_some_and(|(s, h)| *s == stat && h == hash && stat.mtime_ns < written)
    }

    /// Records that `name` (metadata `meta`) holds `hash`; a file without a usable stat is
    /// forgotten instead.
    pub fn record(&mut self, name: &str, meta: Option<&fs::Metadata>, hash: ContentHash) {
        match meta.and_then(FileStat::of) {
            Some(stat) => {
                self.files.insert(name.to_owned(), (stat, hash));
            }
            None => {
                self.files.remove(name);
            }
        }
    }

    /// Whether every stamp of `other` is in this record, unchanged and trusted: writing
    /// `other` would change nothing.
    pub fn covers(&self, other: &Stamps) -> bool {
        other.files.iter().all(|(name, (stat, hash))| {
            self.files.get(name) == Some(&(*stat, *hash))
                && self.written_ns.is_some_and(|w| stat.mtime_ns < w)
        })
    }

    /// Adds every stamp of `other`, replacing the ones of the same name.
    pub fn merge(&mut self, other: Stamps) {
        self.files.extend(other.files);
    }

    /// Writes the record to `path` (temporary file, then rename; no fsync: see the module
    /// doc). Failures are ignored: the next run reads the files again.
    pub fn write(&self, path: &Path) {
        let mut text = String::from(HEAD);
        text.push('\n');
        for (name, (s, hash)) in &self.files {
            text.push_str(&format!(
                "{} {} {} {} {} {} {}\n",
                hash.to_hex(),
                s.len,
                s.mtime_ns,
                s.ctime_ns,
                s.ino,
                s.dev,
                name
            ));
        }
        let Some(parent) = path.parent() else { return };
        let _ = fs::create_dir_all(parent);
        let mut tmp = path.as_os_str().to_owned();
        tmp.push(format!(".tmp-{}", crate::owner::Owner::this_tag()));
        let tmp = std::path::PathBuf::from(tmp);
        if fs::write(&tmp, text).is_ok() && fs::rename(&tmp, path).is_err() {
            let _ = fs::remove_file(&tmp);
        }
    }
}

/// One line: `HASH LEN MTIME CTIME INO DEV NAME` (the name last: it may hold spaces).
fn parse_line(line: &str) -> Option<(String, FileStat, ContentHash)> {
    let mut parts = line.splitn(7, ' ');
    let hash = ContentHash::from_hex(parts.next()?)?;
    let len = parts.next()?.parse().ok()?;
    let mtime_ns = parts.next()?.parse().ok()?;
    let ctime_ns = parts.next()?.parse().ok()?;
    let ino = parts.next()?.parse().ok()?;
    let dev = parts.next()?.parse().ok()?;
    let name = parts.next()?.to_owned();
    let stat = FileStat {
        len,
        mtime_ns,
        ctime_ns,
        ino,
        dev,
    };
    Some((name, stat, hash))
}

#[cfg(all(test, unix))]
mod tests {
    use super::*;

    #[test]
    fn a_record_reads_back_and_vouches_only_for_unchanged_older_files() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a b.png");
        fs::write(&path, b"one").unwrap();
        let old = std::time::SystemTime::now() - std::time::Duration::from_secs(60);
        fs::File::options()
            .write(true)
            .open(&path)
            .unwrap()
            .set_modified(old)
            .unwrap();
        let hash = ContentHash::of(b"one");
        let mut stamps = Stamps::default();
        stamps.record("a b.png", Some(&fs::metadata(&path).unwrap()), hash);
        let record = dir.path().join("records").join("one");
        stamps.write(&record);

        let read = Stamps::read(&record);
        let meta = fs::metadata(&path).unwrap();
        assert!(read.vouches("a b.png", &meta, &hash));
        assert!(read.covers(&stamps));
        assert!(!read.vouches("a b.png", &meta, &ContentHash::of(b"two")));
        assert!(!read.vouches("other", &meta, &hash));

        // Rewritten with the same length: the times moved.
        fs::write(&path, b"two").unwrap();
        assert!(!read.vouches("a b.png", &fs::metadata(&path).unwrap(), &hash));
        // A file not older than the record is racy: not trusted even with its own stat.
        let mut racy = Stamps::default();
        racy.record("a b.png", Some(&fs::metadata(&path).unwrap()), hash);
        racy.write(&record);
        fs::File::options()
            .write(true)
            .open(&record)
            .unwrap()
            .set_modified(old)
            .unwrap();
        let read = Stamps::read(&record);
        assert!(!read.vouches("a b.png", &fs::metadata(&path).unwrap(), &hash));

        // A damaged record is no record.
        fs::write(&record, "texsyn output stamps 1\nnot a line\n").unwrap();
        assert_eq!(Stamps::read(&record).files.len(), 0);
    }
}
