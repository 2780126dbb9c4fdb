//! Writes exported file bundles into the run's output directory, as one set.
//!
//! The files one run exports are a set: after any failure or kill, the output directory holds
//! either every output of the previous run or every output of the new one, never a mix. Only
//! files whose bytes differ from what is on disk are written. Files that are not texsyn's
//! outputs are never touched.
//!
//! # Protocol
//!
//! With `P` the writing process's owner tag ([`crate::owner`]: host, boot, PID namespace and
//! process id), everything below happens inside the output directory
//! `D` (one filesystem, so renames are atomic). Writers take turns: within one process through
//! a mutex, across processes through an exclusive advisory lock on `D` itself
//! ([`std::fs::File::lock`], `flock` on Unix), held from recovery to cleanup, so the second of two runs writing one folder finds the first's set complete and
//! swaps its own whole set after it. The kernel drops the lock when its holder dies, so a killed
//! run never leaves the folder locked. Where the filesystem has no such locks, writers go on
//! without it, each in its own staging folder, journal and old folder (named by their ids),
//! never removing each other's; their swaps are then not ordered (the last to swap a file wins
//! it).
//!
//! 1. **Recover** (see [`recover`]): a journal `.texsyn-swap-Q` whose owner `Q` is dead is
//!    finished first (below); then leftovers of dead owners are removed: staging and old
//!    folders without a journal, unfinished journals `.texsyn-swap-Q.tmp`, and temporary
//!    files `.NAME.tmp-Q` (written by earlier versions, and by `render`/`bench`).
//! 2. **Check**: every output name must be a plain file name, and what is at `D/NAME` must be
//!    a regular file (or a symlink, which is replaced) or nothing; a directory, FIFO or device
//!    there fails the run before anything is written.
//! 3. **Stage**: each changed file is written to `D/.texsyn-staging-P/NAME` and fsynced, then
//!    the staging folder is fsynced. A failure here (full disk…) removes the staging folder;
//!    the outputs were not touched.
//! 4. **Journal**: `D/.texsyn-old-P/` is created, then the journal is written to
//!    `D/.texsyn-swap-P.tmp`, fsynced and renamed to `D/.texsyn-swap-P` (the commit point),
//!    and `D` is fsynced. The journal lists each changed file as `replace NAME` (an older
//!    version is in `D`) or `add NAME` (none is), and ends with `end`.
//! 5. **Swap**: per file, `D/NAME` (if `replace`) is renamed to `D/.texsyn-old-P/NAME`, then
//!    `D/.texsyn-staging-P/NAME` is renamed to `D/NAME`; `D` is fsynced.
//! 6. **Clean**: the journal is removed, `D` fsynced, then the staging and old folders.
//!
//! Finishing a journal (after a kill, or when a rename fails in step 5): if every listed file
//! is either still staged or already moved in (`D/NAME` present and, for `replace`, the old
//! copy aside), the swap is completed forward; otherwise it is rolled back (old copies renamed
//! back, files added by the swap removed). Then step 6.
//!
//! An owner is dead when it is provably gone (same host, boot and PID namespace, and `/proc/Q`
//! missing), or when its leftover is older than [`crate::owner::STALE_AGE`] (an owner on another
//! host or in another namespace, or a system without `/proc`). Leftovers with this process's own
//! tag are stale too, since writers within one process are serialized and a writer cleans up
//! before returning.

use crate::artifact::Artifact;
use crate::artifact::ContentHash;
use crate::artifact::{Bundle, Format};
use crate::owner::Owner;
use crate::pipeline::Dag;
use crate::pipeline::stamps::Stamps;
use std::fs;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::SystemTime;

#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    #[error("output {path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error(
        "output {path} is {what}, not a regular file: texsyn will not replace it (remove or \
         rename it); no output was changed"
    )]
    NotAFile { path: PathBuf, what: &'static str },
    #[error("exported bundle names an invalid output file {0:?}")]
    BadName(String),
    #[error("{path}: damaged output swap journal ({message}); fix or remove it by hand")]
    Journal { path: PathBuf, message: String },
    #[error("exported bundle is damaged: {0}")]
    Bundle(#[from] crate::artifact::ArtifactError),
}

const STAGING: &str = ".texsyn-staging-";
const OLD: &str = ".texsyn-old-";
const JOURNAL: &str = ".texsyn-swap-";
const JOURNAL_HEAD: &str = "texsyn output swap 1";
/// Serializes the writers of one process (the leftovers of this process's tag are then stale).
static WRITER: Mutex<()> = Mutex::new(());

/// Takes `dir`'s writer lock, waiting for another process that holds it: an exclusive
/// advisory lock on the folder itself (so no lock file is added to the user's folder).
/// `None` where the platform cannot open or lock a folder (Windows, some network
/// filesystems): writers then go on unordered, as before the lock existed.
fn lock_folder(dir: &Path) -> Result<Option<fs::File>, OutputError> {
    let Ok(handle) = fs::File::open(dir) else {
        return Ok(None);
    };
    match handle.lock() {
        Ok(()) => Ok(Some(handle)),
        Err(e) if e.kind() == std::io::ErrorKind::Unsupported => Ok(None),
        Err(e) => Err(io(dir)(e)),
    }
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> OutputError {
    let path = path.to_owned();
    move |source| OutputError::Io { path, source }
}

/// Writes one bundle's files into `dir` as a set (see the module doc). What happened to each
/// file: (path, written?).
pub fn materialize(bundle: &Artifact, dir: &Path) -> Result<Vec<(PathBuf, bool)>, OutputError> {
    materialize_all(&[bundle], dir)
}

/// Writes the exports of one run of `dag` (the artifacts of its exporting nodes; `artifacts`
/// holds each node's, by node index) into `dir` as one set, as [`materialize_all`] does.
pub fn materialize_exports(
    dag: &Dag,
    artifacts: &[Artifact],
    dir: &Path,
    check: OutputCheck,
) -> Result<Vec<(PathBuf, bool)>, OutputError> {
    let bundles: Vec<&Artifact> = dag
        .nodes
        .iter()
        .zip(artifacts)
        .filter(|(node, _)| node.exports)
        .map(|(_, a)| a)
        .collect();
    materialize_checked(&bundles, dir, check)
}

/// How [`materialize_checked`] decides that a file on disk already holds its output.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum OutputCheck {
    /// A file whose stat is the one recorded when it was last written or read is trusted
    /// without reading it ([`super::stamps`]); others are read and hashed. The records are
    /// kept in this folder (a cache's [`super::stamps::RECORDS`]).
    Stamps(PathBuf),
    /// Every file is read and hashed (`run --recheck`, `pack`, `unpack`).
    Rehash,
}

/// Writes the files of all `bundles` (one run's exports) into `dir` as one set: afterwards
/// `dir` holds all of them, or, after an error, still exactly what it held before. When two
/// bundles name the same file, the later one's is written. What happened to each file:
/// (path, written?), in bundle order.
pub fn materialize_all(
    bundles: &[&Artifact],
    dir: &Path,
) -> Result<Vec<(PathBuf, bool)>, OutputError> {
    materialize_checked(bundles, dir, OutputCheck::Rehash)
}

/// [`materialize_all`], deciding which files are unchanged as `check` says. A bundle's
/// payload is verified before any of its files is written from it, so a bundle handed out
/// unverified (see [`super::RunOptions::defer_export_checks`]) is caught here, as
/// [`OutputError::Bundle`], before it reaches the folder.
pub fn materialize_checked(
    bundles: &[&Artifact],
    dir: &Path,
    check: OutputCheck,
) -> Result<Vec<(PathBuf, bool)>, OutputError> {
    let _writer = WRITER.lock().unwrap_or_else(|e| e.into_inner());
    fs::create_dir_all(dir).map_err(io(dir))?;
    let _folder = lock_folder(dir)?;
    recover_locked(dir)?;

    // The set: each name once, the last bundle's entry winning.
    let views = bundles
        .iter()
        .map(|b| Bundle::view(b))
        .collect::<Result<Vec<_>, _>>()?;
    let mut files = Vec::new(); // (view, entry index)
    for (v, view) in views.iter().enumerate() {
        for (e, entry) in view.entries.iter().enumerate() {
            check_name(&entry.name)?;
            match files
                .iter()
                .position(|&(w, f): &(usize, usize)| views[w].entries[f].name == entry.name)
            {
                Some(i) => files[i] = (v, e),
                None => files.push((v, e)),
            }
        }
    }

    // Check what is on disk; collect the changed files.
    let record = match &check {
        OutputCheck::Stamps(records) => super::stamps::record_path(records, dir),
        OutputCheck::Rehash => None,
    };
    // The folder's clock, read (from a probe file) before the first file that is not vouched
    // for is looked at: only files older than it get a stamp (see `stamps`). A rerun whose
    // files are all vouched for never needs it, and makes no probe.
    let mut clock: Option<i128> = None;
    let known = record.as_deref().map(Stamps::read).unwrap_or_default();
    let mut seen = Stamps::default();
    let names: Vec<&str> = files
        .iter()
        .map(|&(v, e)| views[v].entries[e].name.as_str())
        .collect();
    let mut out = Vec::new();
    let mut changed = Vec::new(); // (view, entry, had_old)
    for &(v, e) in &files {
        let entry = &views[v].entries[e];
        let path = dir.join(&entry.name);
        let had_old = match fs::symlink_metadata(&path) {
            Err(err) if err.kind() == std::io::ErrorKind::NotFound => false,
            Err(err) => return Err(io(&path)(err)),
            Ok(m) if m.is_dir() => {
                return Err(OutputError::NotAFile {
                    path,
                    what: "a directory",
                });
            }
            Ok(m) if !m.is_file() && !m.file_type().is_symlink() => {
                return Err(OutputError::NotAFile {
                    path,
                    what: "a special file (FIFO, socket or device)",
                });
            }
            Ok(_) => true,
        };
        // Read only a regular file of the right length (a symlink may point anywhere), and
        // only when its stamp does not vouch for it.
        let meta = fs::symlink_metadata(&path).ok().filter(|m| m.is_file());
        let vouched = meta
            .as_ref()
            .is_some_and(|m| known.vouches(&entry.name, m, &entry.hash));
        // A file that is read is stamped with its stat taken after the clock and before the
        // read: any later change moves a time past the clock.
        let mut read_meta = None;
        let same = had_old
            && (vouched || {
                if record.is_some() && clock.is_none() {
                    clock = Some(super::stamps::folder_clock(dir).unwrap_or(i128::MIN));
                }
                read_meta = fs::symlink_metadata(&path).ok().filter(|m| m.is_file());
                fs::metadata(&path).is_ok_and(|m| m.is_file() && m.len() == entry.len)
                    && fs::read(&path).is_ok_and(|b| ContentHash::of(&b) == entry.hash)
            });
        if vouched {
            // Its stamp stands as it was.
            seen.record(&entry.name, meta.as_ref(), entry.hash, i128::MAX);
        } else if same {
            let clock = clock.unwrap_or(i128::MIN);
            seen.record(&entry.name, read_meta.as_ref(), entry.hash, clock);
        } else {
            changed.push((v, e, had_old));
        }
        out.push((path, !same));
    }
    if changed.is_empty() {
        if let Some(record) = &record
            && !known.covers(&seen, &names)
        {
            let mut stamps = known.clone();
            stamps.merge(&seen, &names);
            stamps.write(record);
        }
        return Ok(out);
    }
    // Only now is a bundle's payload read: check it first.
    let mut checked = vec![false; views.len()];
    for &(v, _, _) in &changed {
        if !checked[v] {
            bundles[v].verify()?;
            checked[v] = true;
        }
    }

    // Stage.
    let me = Owner::this_tag();
    let staging = dir.join(format!("{STAGING}{me}"));
    let stage = || -> Result<(), OutputError> {
        fs::create_dir(&staging).map_err(io(&staging))?;
        // In parallel: one file's reading (decompression, or hashing in place) and writing overlap another's wait for the disk
        // (a million-triangle export stages 300 MB). The first error in the set's order wins.
        use rayon::prelude::*;
        let staged: Vec<Result<(), OutputError>> = changed
            .par_iter()
            .with_max_len(1)
            .map(|&(v, e, _)| {
                let entry = &views[v].entries[e];
                let bytes = views[v].file(entry)?;
                let path = staging.join(&entry.name);
                write_synced(&path, &bytes).map_err(io(&path))
            })
            .collect();
        staged.into_iter().collect::<Result<(), _>>()?;
        sync_dir(&staging).map_err(io(&staging))
    };
    if let Err(e) = stage() {
        let _ = fs::remove_dir_all(&staging);
        return Err(e);
    }

    // Journal (the commit point), then the swap.
    let old = dir.join(format!("{OLD}{me}"));
    let journal = dir.join(format!("{JOURNAL}{me}"));
    let plan: Vec<Planned> = changed
        .iter()
        .map(|&(v, e, had_old)| Planned {
            name: views[v].entries[e].name.clone(),
            had_old,
        })
        .collect();
    if let Err(e) = write_journal(dir, &journal, &old, &plan) {
        let _ = fs::remove_dir_all(&staging);
        let _ = fs::remove_dir(&old);
        let _ = fs::remove_file(unfinished(&journal));
        let _ = fs::remove_file(&journal);
        return Err(e);
    }
    let swap = || -> Result<(), OutputError> {
        for p in &plan {
            let path = dir.join(&p.name);
            if p.had_old {
                fs::rename(&path, old.join(&p.name)).map_err(io(&path))?;
            }
            fs::rename(staging.join(&p.name), &path).map_err(io(&path))?;
        }
        sync_dir(dir).map_err(io(dir))
    };
    match swap() {
        Ok(()) => finish(dir, &journal, &staging, &old)?,
        Err(e) => {
            // Put the previous outputs back (best effort: the next run retries from the journal).
            let _ = roll_back(dir, &staging, &old, &plan)
                .and_then(|()| finish(dir, &journal, &staging, &old));
            return Err(e);
        }
    }
    for &(v, e, _) in &changed {
        let entry = &views[v].entries[e];
        // Written in this run's tick: forgotten, and read once by the next run.
        let meta = fs::symlink_metadata(dir.join(&entry.name)).ok();
        seen.record(&entry.name, meta.as_ref(), entry.hash, i128::MIN);
    }
    if let Some(record) = &record {
        let mut stamps = known;
        stamps.merge(&seen, &names);
        stamps.write(record);
    }
    Ok(out)
}

/// Finishes or rolls back a swap that a killed texsyn left in `dir` and removes the leftovers
/// of dead texsyn processes (see the module doc). Run before anything else by every command
/// that writes into an output directory; a missing `dir` is fine.
pub fn recover(dir: &Path) -> Result<(), OutputError> {
    if !dir.is_dir() {
        return Ok(());
    }
    let _writer = WRITER.lock().unwrap_or_else(|e| e.into_inner());
    let _folder = lock_folder(dir)?;
    recover_locked(dir)
}

fn recover_locked(dir: &Path) -> Result<(), OutputError> {
    let names = || -> Result<Vec<String>, OutputError> {
        Ok(fs::read_dir(dir)
            .map_err(io(dir))?
            .flatten()
            .filter_map(|e| e.file_name().into_string().ok())
            .collect())
    };
    // Journals first: they decide what the staging and old folders hold.
    for name in names()? {
        let Some(tag) = name
            .strip_prefix(JOURNAL)
            .filter(|t| Owner::parse(t).is_some())
        else {
            continue;
        };
        let journal = dir.join(&name);
        if !owner_is_dead(tag, &journal) {
            continue;
        }
        let plan = read_journal(&journal)?;
        let staging = dir.join(format!("{STAGING}{tag}"));
        let old = dir.join(format!("{OLD}{tag}"));
        let complete = plan.iter().all(|p| {
            staging.join(&p.name).is_file()
                || (dir.join(&p.name).exists() && (!p.had_old || old.join(&p.name).exists()))
        });
        if complete {
            tracing::warn!(journal = %journal.display(), "completing an interrupted output swap");
            for p in &plan {
                let staged = staging.join(&p.name);
                if !staged.is_file() {
                    continue; // already moved in
                }
                let path = dir.join(&p.name);
                let aside = old.join(&p.name);
                if p.had_old && !aside.exists() && fs::symlink_metadata(&path).is_ok() {
                    fs::create_dir_all(&old).map_err(io(&old))?;
                    fs::rename(&path, &aside).map_err(io(&path))?;
                }
                fs::rename(&staged, &path).map_err(io(&path))?;
            }
            sync_dir(dir).map_err(io(dir))?;
        } else {
            tracing::warn!(journal = %journal.display(), "rolling back an interrupted output swap");
            roll_back(dir, &staging, &old, &plan)?;
        }
        finish(dir, &journal, &staging, &old)?;
    }
    // Leftovers of dead owners without a journal (or whose journal was just finished).
    for name in names()? {
        let tag = if let Some(rest) = name
            .strip_prefix(STAGING)
            .or_else(|| name.strip_prefix(OLD))
        {
            Some(rest)
        } else if let Some(rest) = name.strip_prefix(JOURNAL) {
            rest.strip_suffix(".tmp")
        } else if let Some((_, rest)) = name.rsplit_once(".tmp-")
            && name.starts_with('.')
        {
            Some(rest)
        } else {
            None
        };
        let Some(tag) = tag.filter(|t| Owner::parse(t).is_some()) else {
            continue;
        };
        let path = dir.join(&name);
        if name.starts_with(STAGING) || name.starts_with(OLD) {
            if dir.join(format!("{JOURNAL}{tag}")).exists() {
                continue; // a live owner's swap
            }
            if owner_is_dead(tag, &path) {
                let _ = fs::remove_dir_all(&path);
            }
        } else if fs::symlink_metadata(&path).is_ok_and(|m| m.is_file())
            && owner_is_dead(tag, &path)
        {
            let _ = fs::remove_file(&path);
        }
    }
    Ok(())
}

/// One changed file of a swap.
struct Planned {
    name: String,
    had_old: bool,
}

fn write_journal(
    dir: &Path,
    journal: &Path,
    old: &Path,
    plan: &[Planned],
) -> Result<(), OutputError> {
    fs::create_dir(old).map_err(io(old))?;
    let mut text = format!("{JOURNAL_HEAD}\n");
    for p in plan {
        text += if p.had_old { "replace " } else { "add " };
        text += &p.name;
        text += "\n";
    }
    text += "end\n";
    let tmp = unfinished(journal);
    write_synced(&tmp, text.as_bytes()).map_err(io(&tmp))?;
    fs::rename(&tmp, journal).map_err(io(journal))?;
    sync_dir(dir).map_err(io(dir))
}

fn read_journal(journal: &Path) -> Result<Vec<Planned>, OutputError> {
    let text = fs::read_to_string(journal).map_err(io(journal))?;
    let bad = |message: &str| OutputError::Journal {
        path: journal.to_owned(),
        message: message.into(),
    };
    let mut lines = text.lines();
    if lines.next() != Some(JOURNAL_HEAD) {
        return Err(bad("unknown header"));
    }
    let mut plan = Vec::new();
    for line in lines {
        if line == "end" {
            return Ok(plan);
        }
        let (had_old, name) = match line.split_once(' ') {
            Some(("replace", name)) => (true, name),
            Some(("add", name)) => (false, name),
            _ => return Err(bad("expected `replace NAME`, `add NAME` or `end`")),
        };
        check_name(name).map_err(|_| bad("invalid file name"))?;
        plan.push(Planned {
            name: name.to_owned(),
            had_old,
        });
    }
    Err(bad("no `end` line"))
}

/// Puts every file the swap moved back where it was.
fn roll_back(dir: &Path, staging: &Path, old: &Path, plan: &[Planned]) -> Result<(), OutputError> {
    for p in plan {
        let path = dir.join(&p.name);
        if p.had_old {
            let aside = old.join(&p.name);
            if fs::symlink_metadata(&aside).is_ok() {
                fs::rename(&aside, &path).map_err(io(&path))?;
            }
        } else if !staging.join(&p.name).exists() && fs::symlink_metadata(&path).is_ok() {
            // The new file had been moved in.
            fs::remove_file(&path).map_err(io(&path))?;
        }
    }
    sync_dir(dir).map_err(io(dir))
}

/// Step 6: the journal goes first, then the folders it described.
fn finish(dir: &Path, journal: &Path, staging: &Path, old: &Path) -> Result<(), OutputError> {
    fs::remove_file(journal).map_err(io(journal))?;
    sync_dir(dir).map_err(io(dir))?;
    for d in [staging, old] {
        match fs::remove_dir_all(d) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => return Err(io(d)(e)),
            _ => {}
        }
    }
    Ok(())
}

/// An output name is one plain file name (the bundle's files are flat).
fn check_name(name: &str) -> Result<(), OutputError> {
    let ok = !name.is_empty()
        && name != "."
        && name != ".."
        && !name.contains(['/', '\\', '\n', '\r', '\0'])
        && !name.starts_with(".texsyn-");
    if ok {
        Ok(())
    } else {
        Err(OutputError::BadName(name.to_owned()))
    }
}

/// Where a journal is written before its rename: `.texsyn-swap-OWNER.tmp`.
fn unfinished(journal: &Path) -> PathBuf {
    let mut name = journal.as_os_str().to_owned();
    name.push(".tmp");
    PathBuf::from(name)
}

/// Whether the process whose owner tag (`crate::owner`) `tag` is left `path` behind is gone,
/// or the leftover is older than [`crate::owner::STALE_AGE`], so it may be removed. This
/// process's own tag counts as dead: its writers are serialized and clean up after
/// themselves, so what carries its tag was left by an earlier process that had the same id.
pub fn owner_is_dead(tag: &str, path: &Path) -> bool {
    crate::owner::may_remove(Owner::parse(tag).as_ref(), path, true)
}

fn write_synced(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let f = fs::File::create(path)?;
    crate::cache::write_parallel(&f, bytes)?;
    f.sync_all()
}

/// Makes renames and removals in `dir` durable (a no-op where directories cannot be opened).
fn sync_dir(dir: &Path) -> std::io::Result<()> {
    #[cfg(unix)]
    fs::File::open(dir)?.sync_all()?;
    #[cfg(not(unix))]
    let _ = dir;
    Ok(())
}

/// A folder in the system's temporary folder, removed when dropped. Named
/// `PREFIX-PID-NANOS`; making one removes those a killed texsyn left behind (their process is
/// gone), never those of a live one. Used by `verify --fresh` (its cache) and `unpack` (the
/// extracted archive).
pub struct TempDir(PathBuf);

impl TempDir {
    /// A fresh path, not created (a cache creates its own root).
    pub fn new(prefix: &str) -> TempDir {
        let base = std::env::temp_dir();
        if let Ok(entries) = fs::read_dir(&base) {
            for e in entries.flatten() {
                let name = e.file_name();
                let Some(owner) = name
                    .to_str()
                    .and_then(|n| n.strip_prefix(prefix)?.strip_prefix('-')?.split_once('-'))
                    .and_then(|(tag, nanos)| {
                        nanos.bytes().all(|b| b.is_ascii_digit()).then_some(tag)
                    })
                    .and_then(Owner::parse)
                else {
                    continue;
                };
                if crate::owner::may_remove(Some(&owner), &e.path(), false) {
                    let _ = fs::remove_dir_all(e.path());
                }
            }
        }
        let nanos = SystemTime::now()
            .duration_since(SystemTime::UNIX_EPOCH)
            .map(|d| d.as_nanos())
            .unwrap_or(0);
        TempDir(base.join(format!("{prefix}-{}-{nanos}", Owner::this_tag())))
    }

    /// As [`TempDir::new`], and created (an existing folder of that name is an error).
    pub fn create(prefix: &str) -> Result<TempDir, (PathBuf, std::io::Error)> {
        let dir = TempDir::new(prefix);
        fs::create_dir(&dir.0).map_err(|e| (dir.0.clone(), e))?;
        Ok(dir)
    }

    pub fn path(&self) -> &Path {
        &self.0
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = fs::remove_dir_all(&self.0);
    }
}
