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
//! A file could be modified within the same clock tick (file times are coarse, a few
//! milliseconds) as it was last written, after texsyn looked at it, and keep its stat. So a
//! stamp is recorded only for a file whose modification and change times are both older than
//! the output folder's clock, read ([`folder_clock`], off the folder's own filesystem, which may
//! not be the cache's) before the file's stat and bytes were: any later change then moves a
//! time. A file written or touched in the run's own tick is left out and hashed on the next
//! run, which then records it ("racily clean", as git calls it). A rerun whose files are all
//! vouched for reads no clock.
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
const HEAD: &str = "texsyn output stamps 2";

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

/// The output folder's clock now, in nanoseconds: the modification time of a probe file
/// made (and removed) in `dir`, so it is the time of the filesystem the outputs are on.
/// `None` when no file can be made there (nothing is recorded then).
pub fn folder_clock(dir: &Path) -> Option<i128> {
    let probe = dir.join(format!(
        ".texsyn-probe.tmp-{}",
        crate::owner::Owner::this_tag()
    ));
    let made = fs::write(&probe, b"").ok();
    let time = made
        .and_then(|()| fs::metadata(&probe).ok())
        .and_then(|m| FileStat::of(&m))
        .map(|s| s.mtime_ns);
    let _ = fs::remove_file(&probe);
    time
}

/// The stamps of one output folder, by file name. Only stamps whose file was older than the
/// folder's clock when they were taken are held (see the module doc).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Stamps {
    files: BTreeMap<String, (FileStat, ContentHash)>,
}

impl Stamps {
    /// The record at `path`; empty when there is none or it cannot be read.
    pub fn read(path: &Path) -> Stamps {
        let Ok(text) = fs::read_to_string(path) else {
            return Stamps::default();
        };
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
        Stamps { files }
    }

    /// Whether the file `name` with metadata `meta` is known to hold content `hash`.
    pub fn vouches(&self, name: &str, meta: &fs::Metadata, hash: &ContentHash) -> bool {
        let Some(stat) = FileStat::of(meta) else {
            return false;
        };
        self.files
            .get(name)
            .is_some_and(|(s, h)| *s == stat && h == hash)
    }

    /// Records that `name` (metadata `meta`) holds `hash`, when its times are older than
    /// `clock`, the folder's clock before it was looked at; otherwise (or without a usable
    /// stat) forgets it, so the next run reads it.
    pub fn record(
        &mut self,
        name: &str,
        meta: Option<&fs::Metadata>,
        hash: ContentHash,
        clock: i128,
    ) {
        match meta.and_then(FileStat::of) {
            Some(stat) if stat.mtime_ns.max(stat.ctime_ns) < clock => {
                self.files.insert(name.to_owned(), (stat, hash));
            }
            _ => {
                self.files.remove(name);
            }
        }
    }

    /// Whether writing `other` over this record would change nothing: every stamp of `other`
    /// is here, and no name `other` forgot is.
    pub fn covers(&self, other: &Stamps, names: &[&str]) -> bool {
        names
            .iter()
            .all(|n| self.files.get(*n) == other.files.get(*n))
    }

    /// Takes `other`'s stamp (or its lack of one) for each of `names`.
    pub fn merge(&mut self, other: &Stamps, names: &[&str]) {
        for n in names {
            match other.files.get(*n) {
                Some(s) => {
                    self.files.insert((*n).to_owned(), *s);
                }
                None => {
                    self.files.remove(*n);
                }
            }
        }
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
    fn a_record_reads_back_and_vouches_only_for_unchanged_files_older_than_the_clock() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a b.png");
        fs::write(&path, b"one").unwrap();
        let hash = ContentHash::of(b"one");
        let meta = fs::metadata(&path).unwrap();
        let clock = folder_clock(dir.path()).unwrap();
        // Written in this run's tick or just before: only a clock after its times trusts it.
        let mut racy = Stamps::default();
        racy.record(
            "a b.png",
            Some(&meta),
            hash,
            FileStat::of(&meta).unwrap().ctime_ns,
        );
        assert!(
            !racy.vouches("a b.png", &meta, &hash),
            "a racy stamp was kept"
        );

        let mut stamps = Stamps::default();
        stamps.record("a b.png", Some(&meta), hash, clock + 1_000_000_000);
        let record = dir.path().join("records").join("one");
        stamps.write(&record);
        let read = Stamps::read(&record);
        assert!(read.vouches("a b.png", &meta, &hash));
        assert!(read.covers(&stamps, &["a b.png"]));
        assert!(!read.vouches("a b.png", &meta, &ContentHash::of(b"two")));
        assert!(!read.vouches("other", &meta, &hash));
        // Rewritten with the same length and the old modification time: the change time moved.
        let modified = meta.modified().unwrap();
        std::thread::sleep(std::time::Duration::from_millis(20));
        fs::write(&path, b"two").unwrap();
        fs::File::options()
            .write(true)
            .open(&path)
            .unwrap()
            .set_modified(modified)
            .unwrap();
        assert!(!read.vouches("a b.png", &fs::metadata(&path).unwrap(), &hash));
        // The probe leaves nothing behind.
        let left: Vec<_> = fs::read_dir(dir.path())
            .unwrap()
            .flatten()
            .map(|e| e.file_name())
            .collect();
        assert_eq!(left.len(), 2, "{left:?}");

        // A damaged record is no record.
        fs::write(&record, "texsyn output stamps 2\nnot a line\n").unwrap();
        assert_eq!(Stamps::read(&record).files.len(), 0);
    }
}
