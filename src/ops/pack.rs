//! `texsyn pack` and `texsyn unpack`: a run in one file, so that a reader of a paper gets its
//! figures without recomputing them, or recomputes them (`verify --fresh`) and compares.
//!
//! # The archive
//!
//! A tar stream inside one zstd frame (level 3, with zstd's frame checksum), then a zstd
//! skippable frame, the *seal*, holding `TXSNPACK` and the blake3 hash of every byte before
//! it (decompressors skip it: `zstd -dc results.tar.zst | tar x` works). Every entry is a
//! regular file under `texsyn-pack/`, written with mode 0644, owner 0 and time 0, in a fixed
//! order, so packing the same run twice gives the same bytes:
//!
//! ```text
//! texsyn-pack/MANIFEST.json      always the first entry (below)
//! texsyn-pack/run.lock           the lock file of the run (what `texsyn hashes` prints, with
//!                                its `# set:` lines for the --set overrides)
//! texsyn-pack/files/…            the config and every input file it reads (meshes, exemplars,
//!                                maps, masks, curve files…), at their paths relative to the
//!                                deepest folder holding all of them, so the config's relative
//!                                paths still lead to them
//! texsyn-pack/outputs/NAME       the run's outputs (what `run` writes into out/<config name>/),
//!                                as the run's exported bundles hold them
//! texsyn-pack/objects/KEY        the cache object of every node of the plan, named by its key
//! ```
//!
//! The manifest is JSON: `magic` (`"texsyn-pack"`), `format` (1), the texsyn version that
//! wrote it, the method, the config's entry, the `--set` overrides, and every other entry
//! with its role (`lock`, `config`, `input`, `output`, `object`), size and blake3 hash (of the
//! entry's bytes; for an object, of the whole cache file). Solid bricks (a node's keyed
//! pieces) are not packed: they only matter to a node that computes, and every node's result
//! is in the archive. Input paths must be relative to the config (an absolute path in the
//! config, or in a `--set`, is refused by `pack`: the archive could not reproduce it).
//!
//! # Unpacking
//!
//! `unpack` reads the whole archive into a temporary folder (in `$TMPDIR`, which needs room
//! for the archive's uncompressed size; removed afterwards, or by the next unpack if this one
//! was killed) and checks everything before it imports anything. `pack` runs the same checks
//! on the archive it wrote before moving it into place, so it never leaves an archive that
//! `unpack` would refuse:
//!
//! 1. The file starts with zstd's magic number and its first entry is the manifest, whose
//!    magic names this format: otherwise it is *not a texsyn pack archive* (a foreign
//!    tar.zst, a plain tar). Another `format` is named as such.
//! 2. The seal is there and matches the bytes before it; every entry is a regular file listed
//!    in the manifest, once, with the listed size and blake3 hash; every listed entry is
//!    there; the zstd stream decodes to its end and its checksum holds. Otherwise the archive
//!    is *damaged or truncated*: any byte changed anywhere breaks the seal (even one that
//!    zstd would decode to the same content), a file cut short has none.
//! 3. The packed config is planned again from the extracted files, with the lock's recorded
//!    overrides (equal to the manifest's). It must read exactly the packed input files.
//! 4. The graph's keys are derived node by node, as a run would: a node's key from its
//!    parameters and its inputs' content hashes (input files as extracted, upstream nodes
//!    from their packed objects, each re-hashed in full and of the node's output kind). Every
//!    node's object must be packed, the derived (node, key, content hash) lines must equal
//!    the packed lock, and every object entry must carry a key the graph derives: an object
//!    under any other key is refused, naming the entry, so a crafted archive cannot plant an
//!    object under a key it does not earn. (What an archive can still do is claim a content
//!    for a node that its code would not compute: `texsyn verify --fresh` recomputes
//!    everything and compares with the lock.)
//! 5. The outputs must be exactly the files of the packed exported bundles.
//!
//! Any failure refuses the whole archive and imports nothing. Then each object is stored with
//! [`Cache::put`] (atomic), and with `-o DIR` the config and inputs are written under `DIR`
//! (a file already there with other bytes is an error before anything is imported), the lock
//! beside the config as `<config name>.lock`, and the outputs into `DIR/out/<config name>/`
//! as `run` writes them (one set). `texsyn verify DIR/…/NAME.toml DIR/…/NAME.lock` then
//! passes without computing, and `texsyn run` (with the recorded `--set` overrides) computes
//! nothing.

use crate::artifact::{Artifact, Backing, Bundle, ContentHash, Format};
use crate::cache::{Cache, CacheError, Key, Lookup};
use crate::config::{Config, ConfigError};
use crate::methods::{self, MethodError, Plan};
use crate::ops::lockfile::{LockEntry, LockError, LockFile};
use crate::pipeline::executor::PipelineError;
use crate::pipeline::outputs::TempDir;
use crate::pipeline::{self, InputRef, ProgressMode, RunOptions, outputs};
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, HashMap, HashSet};
use std::fs::{self, File};
use std::io::{self, Read, Write};
use std::path::{Component, Path, PathBuf};

/// The manifest's `magic`.
pub const MAGIC: &str = "texsyn-pack";
/// The archive format this texsyn writes and reads.
pub const FORMAT: u64 = 1;
/// The folder every entry is in.
pub const ROOT: &str = "texsyn-pack/";
/// The first entry.
pub const MANIFEST: &str = "texsyn-pack/MANIFEST.json";
/// The lock file's entry (under [`ROOT`]).
pub const LOCK: &str = "run.lock";
const ZSTD_MAGIC: [u8; 4] = [0x28, 0xB5, 0x2F, 0xFD];
/// The closing seal: a zstd skippable frame (magic 0x184D2A5E, 40 bytes of content) holding
/// [`SEAL_TAG`] and the blake3 hash of every byte of the archive before it.
const SEAL_MAGIC: [u8; 4] = [0x5E, 0x2A, 0x4D, 0x18];
const SEAL_TAG: &[u8; 8] = b"TXSNPACK";
const SEAL_LEN: usize = 8 + 8 + 32;
const LEVEL: i32 = 3;
/// A manifest larger than this is not one texsyn wrote.
const MAX_MANIFEST: u64 = 64 << 20;

/// The archive's table of contents (the first entry, JSON).
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Manifest {
    pub magic: String,
    pub format: u64,
    /// The version of texsyn that wrote the archive.
    pub texsyn: String,
    pub method: String,
    /// The config's entry (a `files/…` path).
    pub config: String,
    /// The `--set` overrides of the run (also in the lock file).
    pub sets: Vec<String>,
    pub entries: Vec<ManifestEntry>,
}

/// One entry besides the manifest; `path` is under [`ROOT`].
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, Eq)]
#[serde(deny_unknown_fields)]
pub struct ManifestEntry {
    pub path: String,
    pub role: Role,
    pub size: u64,
    /// blake3 of the entry's bytes, 64 lowercase hex digits.
    pub blake3: String,
    /// Objects: the nodes whose result it is (for people; unpack derives its own).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub nodes: Vec<String>,
}

#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum Role {
    Lock,
    Config,
    Input,
    Output,
    Object,
}

#[derive(Debug, thiserror::Error)]
pub enum PackError {
    #[error("{path}: {source}")]
    Io { path: PathBuf, source: io::Error },
    #[error("{archive} is not a texsyn pack archive ({why})")]
    Foreign { archive: PathBuf, why: String },
    #[error(
        "{archive} was written in pack format {found}, which this texsyn does not read (it \
         reads format {FORMAT}); use a texsyn at least as new as the one that packed it"
    )]
    OtherFormat { archive: PathBuf, found: u64 },
    #[error("{archive} is damaged or truncated: {why}")]
    Damaged { archive: PathBuf, why: String },
    #[error(
        "{path}: {source}: unpack reads the whole archive into a temporary folder first; make \
         room there, or point TMPDIR at a folder with room (the archive itself was not judged)"
    )]
    TempSpace { path: PathBuf, source: io::Error },
    #[error("{archive}: entry {entry}: {why}; the whole archive is refused")]
    Refused {
        archive: PathBuf,
        entry: String,
        why: String,
    },
    #[error("cannot pack {config}: {why}")]
    NotPackable { config: PathBuf, why: String },
    #[error("{path}: {why}")]
    Destination { path: PathBuf, why: String },
    #[error("{0}; nothing was imported")]
    NothingImported(Box<PackError>),
    #[error(transparent)]
    Config(#[from] ConfigError),
    #[error(transparent)]
    Method(#[from] MethodError),
    #[error(transparent)]
    Pipeline(#[from] PipelineError),
    #[error(transparent)]
    Cache(#[from] CacheError),
    #[error(transparent)]
    Lock(#[from] LockError),
    #[error(transparent)]
    Output(#[from] outputs::OutputError),
}

fn io_at(path: &Path) -> impl FnOnce(io::Error) -> PackError + '_ {
    move |source| PackError::Io {
        path: path.to_owned(),
        source,
    }
}

/// What `pack` did.
#[derive(Clone, Debug, Serialize)]
pub struct PackReport {
    pub archive: PathBuf,
    pub bytes: u64,
    pub objects: usize,
    pub inputs: usize,
    pub outputs: usize,
    /// Nodes computed because they were not cached.
    pub computed: usize,
    pub sets: Vec<String>,
}

/// What `unpack` did.
#[derive(Clone, Debug, Serialize)]
pub struct UnpackReport {
    pub archive: PathBuf,
    pub cache: PathBuf,
    /// Objects stored in the cache.
    pub imported: usize,
    /// Objects the cache already held, whole and identical.
    pub present: usize,
    /// With `-o`: where the config, its lock and the outputs were written.
    pub config: Option<PathBuf>,
    pub lock: Option<PathBuf>,
    pub outputs: Option<PathBuf>,
    pub sets: Vec<String>,
}

/// Where one entry's bytes come from while packing.
enum Source<'a> {
    Bytes(&'a [u8]),
    /// A file of an exported bundle, decompressed (and checked) when written.
    Output(&'a Artifact, crate::artifact::kinds::BundleEntry),
}

/// Runs `config` (with `sets`) in `cache`, computing what is missing and re-hashing every
/// cached object, and writes the archive to `archive` (atomically; see the module doc).
/// Before it is moved into place the archive is read back and checked as `unpack` checks it.
pub fn pack(
    config: &Path,
    sets: &[String],
    cache: &Cache,
    archive: &Path,
    progress: ProgressMode,
) -> Result<PackReport, PackError> {
    let not_packable = |why: String| PackError::NotPackable {
        config: config.to_owned(),
        why,
    };
    let config_bytes = crate::geom::io::read_regular_file(config).map_err(io_at(config))?;
    let text = std::str::from_utf8(&config_bytes)
        .map_err(|e| not_packable(format!("not UTF-8 text (byte {})", e.valid_up_to())))?;
    let cfg = Config::from_str(config, text, sets)?;
    let plan = methods::plan(&cfg)?;
    let result = pipeline::run(
        &plan.dag,
        cache,
        RunOptions {
            progress,
            verify_all: true,
            defer_export_checks: false,
        },
    )?;
    let computed = result
        .reports
        .iter()
        .filter(|r| r.status == pipeline::NodeStatus::Ran)
        .count();
    let lock = LockFile::of_reports(&result.reports, sets).to_text();

    // The config and its inputs, relative to the deepest folder that holds them all.
    let config_abs = absolute(config).map_err(io_at(config))?;
    let mut inputs_abs = Vec::new();
    for f in &plan.dag.files {
        inputs_abs.push(absolute(&f.path).map_err(io_at(&f.path))?);
    }
    let dirs: Vec<&Path> = std::iter::once(&config_abs)
        .chain(&inputs_abs)
        .map(|p| p.parent().unwrap_or(Path::new("/")))
        .collect();
    let base = common_dir(&dirs);
    let rel = |p: &Path| -> Result<String, PackError> {
        let r = p.strip_prefix(&base).unwrap_or(p);
        let parts: Option<Vec<&str>> = r
            .components()
            .map(|c| match c {
                Component::Normal(s) => s.to_str(),
                _ => None,
            })
            .collect();
        match parts {
            Some(parts) if parts.iter().all(|s| valid_part(s)) => {
                Ok(format!("files/{}", parts.join("/")))
            }
            _ => Err(not_packable(format!(
                "{} cannot be named in an archive (a path part that is not UTF-8, or holds \
                 a backslash)",
                p.display()
            ))),
        }
    };

    let mut entries: Vec<(ManifestEntry, Source)> = Vec::new();
    let bytes_entry = |path: String, role: Role, b: &[u8]| ManifestEntry {
        path,
        role,
        size: b.len() as u64,
        blake3: ContentHash::of(b).to_hex(),
        nodes: Vec::new(),
    };
    entries.push((
        bytes_entry(LOCK.into(), Role::Lock, lock.as_bytes()),
        Source::Bytes(lock.as_bytes()),
    ));
    let config_entry = rel(&config_abs)?;
    entries.push((
        bytes_entry(config_entry.clone(), Role::Config, &config_bytes),
        Source::Bytes(&config_bytes),
    ));
    let archive_abs = absolute(archive).map_err(io_at(archive))?;
    if archive_abs == config_abs || inputs_abs.contains(&archive_abs) {
        return Err(not_packable(format!(
            "the archive {} would overwrite the config or one of its input files",
            archive.display()
        )));
    }
    for (f, abs) in plan.dag.files.iter().zip(&inputs_abs) {
        let path = rel(abs)?;
        if path == config_entry {
            return Err(not_packable(format!(
                "the config reads itself as an input ({})",
                f.path.display()
            )));
        }
        // One file named two ways (`a.png`, `./a.png`) is packed once.
        if entries.iter().any(|(e, _)| e.path == path) {
            continue;
        }
        entries.push((
            bytes_entry(path, Role::Input, &f.bytes),
            Source::Bytes(&f.bytes),
        ));
    }
    for (name, (artifact, entry)) in export_files(&plan, &result.artifacts)? {
        if !valid_part(&name) {
            return Err(not_packable(format!(
                "output {name:?} cannot be named in an archive"
            )));
        }
        entries.push((
            ManifestEntry {
                path: format!("outputs/{name}"),
                role: Role::Output,
                size: entry.len,
                blake3: entry.hash.to_hex(),
                nodes: Vec::new(),
            },
            Source::Output(artifact, entry),
        ));
    }
    // One object per key (two nodes with the same key share it), in node order.
    let mut object_at: HashMap<String, usize> = HashMap::new();
    for (report, artifact) in result.reports.iter().zip(&result.artifacts) {
        if let Some(&i) = object_at.get(&report.key) {
            entries[i].0.nodes.push(report.node.clone());
            continue;
        }
        let mut e = bytes_entry(
            format!("objects/{}", report.key),
            Role::Object,
            artifact.file_bytes(),
        );
        e.nodes.push(report.node.clone());
        object_at.insert(report.key.clone(), entries.len());
        entries.push((e, Source::Bytes(artifact.file_bytes())));
    }
    let manifest = Manifest {
        magic: MAGIC.into(),
        format: FORMAT,
        texsyn: env!("CARGO_PKG_VERSION").into(),
        method: plan.method.clone(),
        config: config_entry,
        sets: sets.to_vec(),
        entries: entries.iter().map(|(e, _)| e.clone()).collect(),
    };
    let manifest_json = serde_json::to_vec_pretty(&manifest).expect("a manifest serializes");

    let tmp = TempFile::beside(archive);
    let write = || -> io::Result<u64> {
        if let Some(dir) = archive.parent().filter(|d| !d.as_os_str().is_empty()) {
            fs::create_dir_all(dir)?;
        }
        let file = HashingWriter {
            inner: io::BufWriter::new(File::create(tmp.path())?),
            hasher: blake3::Hasher::new(),
        };
        let mut enc = zstd::stream::write::Encoder::new(file, LEVEL)?;
        enc.include_checksum(true)?;
        let mut tar = tar::Builder::new(enc);
        append(&mut tar, MANIFEST, &manifest_json)?;
        for (e, source) in &entries {
            let path = format!("{ROOT}{}", e.path);
            match source {
                Source::Bytes(b) => append(&mut tar, &path, b)?,
                Source::Output(artifact, entry) => {
                    let bytes = Bundle::view(artifact)
                        .and_then(|v| v.file(entry))
                        .map_err(|e| io::Error::other(format!("output {}: {e}", entry.name)))?;
                    append(&mut tar, &path, &bytes)?
                }
            }
        }
        let HashingWriter { mut inner, hasher } = tar.into_inner()?.finish()?;
        inner.write_all(&seal(&hasher))?;
        let file = inner.into_inner().map_err(|e| e.into_error())?;
        file.sync_all()?;
        Ok(file.metadata()?.len())
    };
    let bytes = write().map_err(io_at(tmp.path()))?;
    // What unpack would refuse (an input outside the folder the config names, …) is refused
    // here, before the archive is moved into place.
    check_archive(tmp.path(), archive).map_err(|e| {
        not_packable(format!(
            "the archive would not unpack, so none was written: {e}"
        ))
    })?;
    fs::rename(tmp.path(), archive).map_err(io_at(archive))?;
    tmp.disarm();
    Ok(PackReport {
        archive: archive.to_owned(),
        bytes,
        objects: object_at.len(),
        inputs: manifest
            .entries
            .iter()
            .filter(|e| e.role == Role::Input)
            .count(),
        outputs: manifest
            .entries
            .iter()
            .filter(|e| e.role == Role::Output)
            .count(),
        computed,
        sets: sets.to_vec(),
    })
}

/// The files of the plan's exported bundles as `run` writes them: each name once, the later
/// bundle's file winning (as [`outputs::materialize_all`] does), sorted by name.
fn export_files<'a>(
    plan: &Plan,
    artifacts: &'a [Artifact],
) -> Result<BTreeMap<String, (&'a Artifact, crate::artifact::kinds::BundleEntry)>, PackError> {
    let mut files = BTreeMap::new();
    for (node, artifact) in plan.dag.nodes.iter().zip(artifacts) {
        if !node.exports {
            continue;
        }
        let view = Bundle::view(artifact).map_err(|e| {
            outputs::OutputError::Bundle(e) // an exported bundle that does not read
        })?;
        for entry in view.entries {
            files.insert(entry.name.clone(), (artifact, entry));
        }
    }
    Ok(files)
}

/// The closing frame (see [`SEAL_MAGIC`]) for the bytes `hasher` has seen.
fn seal(hasher: &blake3::Hasher) -> [u8; SEAL_LEN] {
    let mut out = [0u8; SEAL_LEN];
    out[..4].copy_from_slice(&SEAL_MAGIC);
    out[4..8].copy_from_slice(&((SEAL_LEN - 8) as u32).to_le_bytes());
    out[8..16].copy_from_slice(SEAL_TAG);
    out[16..].copy_from_slice(hasher.finalize().as_bytes());
    out
}

/// Hashes what it writes (the archive's bytes, for its seal).
struct HashingWriter<W> {
    inner: W,
    hasher: blake3::Hasher,
}

impl<W: Write> Write for HashingWriter<W> {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        let n = self.inner.write(buf)?;
        self.hasher.update(&buf[..n]);
        Ok(n)
    }
    fn flush(&mut self) -> io::Result<()> {
        self.inner.flush()
    }
}

/// Whether the archive at `path` ends with a seal that matches the bytes before it.
enum Seal {
    Holds,
    Missing,
    Broken,
}

fn check_seal(path: &Path) -> io::Result<Seal> {
    let mut file = File::open(path)?;
    let len = file.metadata()?.len();
    if len < SEAL_LEN as u64 {
        return Ok(Seal::Missing);
    }
    let body = len - SEAL_LEN as u64;
    let mut hasher = blake3::Hasher::new();
    io::copy(&mut (&mut file).take(body), &mut hasher)?;
    let mut tail = [0u8; SEAL_LEN];
    file.read_exact(&mut tail)?;
    if tail[..16] != seal(&blake3::Hasher::new())[..16] {
        return Ok(Seal::Missing);
    }
    Ok(if tail == seal(&hasher) {
        Seal::Holds
    } else {
        Seal::Broken
    })
}

fn append<W: Write>(tar: &mut tar::Builder<W>, path: &str, bytes: &[u8]) -> io::Result<()> {
    let mut h = tar::Header::new_gnu();
    h.set_entry_type(tar::EntryType::Regular);
    h.set_size(bytes.len() as u64);
    h.set_mode(0o644);
    h.set_mtime(0);
    h.set_uid(0);
    h.set_gid(0);
    tar.append_data(&mut h, path, bytes)
}

/// An archive read into a temporary folder and checked (module doc, steps 1–5).
pub struct Checked {
    dir: TempDir,
    pub manifest: Manifest,
    pub plan: Plan,
    pub lock: LockFile,
    /// The packed lock file's bytes.
    lock_bytes: Vec<u8>,
    /// Each key the graph derives, once, in node order, with its packed object.
    objects: Vec<(Key, Artifact)>,
    /// Per node of the plan, its object's index in `objects`.
    node_objects: Vec<usize>,
}

impl Checked {
    /// The extracted config and input files: (entry path under `files/`, extracted file).
    fn files(&self) -> impl Iterator<Item = (&str, PathBuf)> {
        self.manifest
            .entries
            .iter()
            .filter(|e| matches!(e.role, Role::Config | Role::Input))
            .map(|e| (&e.path["files/".len()..], self.dir.path().join(&e.path)))
    }
}

/// Reads `archive` into a temporary folder and checks all of it (module doc, steps 1–5),
/// without touching any cache.
pub fn read_archive(archive: &Path) -> Result<Checked, PackError> {
    check_archive(archive, archive)
}

/// [`read_archive`] of the file at `path`, named `archive` in errors.
fn check_archive(path: &Path, archive: &Path) -> Result<Checked, PackError> {
    let damaged = |why: String| PackError::Damaged {
        archive: archive.to_owned(),
        why,
    };
    let refused = |entry: &str, why: String| PackError::Refused {
        archive: archive.to_owned(),
        entry: entry.to_owned(),
        why,
    };
    let foreign = |why: String| PackError::Foreign {
        archive: archive.to_owned(),
        why,
    };
    let meta = fs::metadata(path).map_err(io_at(archive))?;
    if !meta.is_file() {
        return Err(foreign("not a regular file".into()));
    }
    let mut file = File::open(path).map_err(io_at(archive))?;
    let mut magic = [0u8; 4];
    let mut got = 0;
    while got < 4 {
        match file.read(&mut magic[got..]).map_err(io_at(archive))? {
            0 => break,
            n => got += n,
        }
    }
    if got < 4 || magic != ZSTD_MAGIC {
        return Err(foreign("not zstd-compressed".into()));
    }
    drop(file);
    // A seal that is there but does not match: texsyn wrote this file, and bytes changed.
    let seal = check_seal(path).map_err(io_at(archive))?;
    if let Seal::Broken = seal {
        return Err(damaged(
            "its checksum (blake3 of the compressed bytes, in its closing frame) does not \
             match: bytes were changed"
                .into(),
        ));
    }
    let file = File::open(path).map_err(io_at(archive))?;
    let decoder = zstd::stream::read::Decoder::new(file).map_err(io_at(archive))?;
    let mut tar = tar::Archive::new(decoder);
    let dir = TempDir::create("texsyn-unpack").map_err(|(p, e)| io_at(&p)(e))?;

    let mut entries = tar
        .entries()
        .map_err(|e| damaged(format!("reading the tar stream: {e}")))?;
    // 1. The manifest, first.
    let mut first = match entries.next() {
        None => return Err(foreign("no entries".into())),
        Some(Err(e)) => return Err(damaged(format!("reading the first entry: {e}"))),
        Some(Ok(e)) => e,
    };
    let first_path = String::from_utf8_lossy(&first.path_bytes()).into_owned();
    if first_path != MANIFEST || !is_regular(&first) {
        return Err(foreign(format!(
            "its first entry is {first_path:?}, not the manifest {MANIFEST}"
        )));
    }
    if first.size() > MAX_MANIFEST {
        return Err(foreign(format!(
            "its manifest is {} bytes, more than a texsyn manifest's {MAX_MANIFEST}",
            first.size()
        )));
    }
    let mut manifest_bytes = Vec::new();
    first
        .read_to_end(&mut manifest_bytes)
        .map_err(|e| damaged(format!("reading {MANIFEST}: {e}")))?;
    let value: serde_json::Value = serde_json::from_slice(&manifest_bytes)
        .map_err(|e| damaged(format!("{MANIFEST} is not JSON: {e}")))?;
    if value.get("magic").and_then(|m| m.as_str()) != Some(MAGIC) {
        return Err(foreign(format!(
            "its {MANIFEST} does not name the format {MAGIC:?}"
        )));
    }
    match value.get("format").and_then(|f| f.as_u64()) {
        Some(FORMAT) => {}
        Some(found) => {
            return Err(PackError::OtherFormat {
                archive: archive.to_owned(),
                found,
            });
        }
        None => return Err(damaged(format!("{MANIFEST} has no numeric `format`"))),
    }
    // The archive is texsyn's: any byte changed or cut off anywhere is damage.
    match seal {
        Seal::Holds => {}
        Seal::Missing => {
            return Err(damaged(
                "its closing checksum frame is missing (the file was cut short, or its end \
                 changed)"
                    .into(),
            ));
        }
        Seal::Broken => unreachable!("refused above"),
    }
    let manifest: Manifest = serde_json::from_value(value)
        .map_err(|e| damaged(format!("{MANIFEST} does not read: {e}")))?;
    let listed = check_manifest(&manifest).map_err(|(entry, why)| refused(&entry, why))?;

    // 2. Every other entry: listed, once, with its size and hash.
    let mut seen: HashSet<String> = HashSet::new();
    for entry in entries {
        let mut entry = entry.map_err(|e| damaged(format!("reading an entry: {e}")))?;
        let raw = String::from_utf8_lossy(&entry.path_bytes()).into_owned();
        let Some(m) = raw
            .strip_prefix(ROOT)
            .and_then(|p| listed.get(p))
            .map(|&i| &manifest.entries[i])
        else {
            return Err(refused(&raw, "not listed in the manifest".into()));
        };
        if !is_regular(&entry) {
            return Err(refused(
                &raw,
                format!(
                    "a {:?} entry: a pack archive holds only regular files",
                    entry.header().entry_type()
                ),
            ));
        }
        if !seen.insert(m.path.clone()) {
            return Err(refused(&raw, "in the archive twice".into()));
        }
        if entry.size() != m.size {
            return Err(damaged(format!(
                "entry {raw} is {} bytes, the manifest says {}",
                entry.size(),
                m.size
            )));
        }
        let dest = dir.path().join(&m.path);
        let hash = extract(&mut entry, &dest).map_err(|e| match e {
            ExtractError::Read(e) => damaged(format!("reading entry {raw}: {e}")),
            ExtractError::Write(source) => PackError::TempSpace {
                path: dest.clone(),
                source,
            },
        })?;
        if hash.to_hex() != m.blake3 {
            return Err(damaged(format!(
                "entry {raw}: its blake3 hash {} differs from the manifest's {}",
                hash.to_hex(),
                m.blake3
            )));
        }
    }
    // The rest of the stream, so that zstd's checksum at the frame's end is checked.
    let mut decoder = tar.into_inner();
    io::copy(&mut decoder, &mut io::sink()).map_err(|e| damaged(format!("decompressing: {e}")))?;
    if let Some(missing) = manifest.entries.iter().find(|e| !seen.contains(&e.path)) {
        return Err(damaged(format!(
            "entry {ROOT}{} is listed in the manifest but missing",
            missing.path
        )));
    }

    // 3. The packed config, planned again from the extracted files.
    let lock_path = dir.path().join(LOCK);
    let lock_bytes = fs::read(&lock_path).map_err(io_at(&lock_path))?;
    let lock = LockFile::read(&lock_path).map_err(|e| refused(LOCK, e.to_string()))?;
    if lock.sets != manifest.sets {
        return Err(refused(
            LOCK,
            format!(
                "its recorded overrides {:?} differ from the manifest's {:?}",
                lock.sets, manifest.sets
            ),
        ));
    }
    let config_path = dir.path().join(&manifest.config);
    let plan = Config::load(&config_path, &lock.sets)
        .map_err(MethodError::from)
        .and_then(|cfg| methods::plan(&cfg))
        .map_err(|e| {
            refused(
                &manifest.config,
                format!("the packed config does not plan: {e}"),
            )
        })?;
    if plan.method != manifest.method {
        return Err(refused(
            &manifest.config,
            format!(
                "the config's method {:?} is not the manifest's {:?}",
                plan.method, manifest.method
            ),
        ));
    }
    let files_root = absolute(&dir.path().join("files")).map_err(io_at(dir.path()))?;
    let mut read: HashSet<String> = HashSet::new();
    for f in &plan.dag.files {
        let abs = absolute(&f.path).map_err(io_at(&f.path))?;
        let entry = abs.strip_prefix(&files_root).ok().and_then(|r| {
            let parts: Option<Vec<&str>> = r.components().map(|c| c.as_os_str().to_str()).collect();
            parts.map(|p| format!("files/{}", p.join("/")))
        });
        match entry
            .as_ref()
            .and_then(|e| listed.get(e.as_str()))
            .map(|&i| &manifest.entries[i])
        {
            Some(m) if m.role == Role::Input => {
                read.insert(m.path.clone());
            }
            _ => {
                return Err(refused(
                    &manifest.config,
                    format!(
                        "the packed config reads {}, which is not a packed input file (an \
                         absolute path in the config or a --set? input paths must be relative \
                         to the config)",
                        f.path.display()
                    ),
                ));
            }
        }
    }
    if let Some(unused) = manifest
        .entries
        .iter()
        .find(|e| e.role == Role::Input && !read.contains(&e.path))
    {
        return Err(refused(
            &unused.path,
            "an input file the packed config does not read".into(),
        ));
    }

    // 4. The graph's keys, derived as a run would, from the extracted inputs and objects.
    let mut content: Vec<ContentHash> = Vec::with_capacity(plan.dag.nodes.len());
    let mut derived: Vec<LockEntry> = Vec::new();
    let mut objects: Vec<(Key, Artifact)> = Vec::new();
    let mut index_of: HashMap<Key, usize> = HashMap::new();
    // Per node, its object's index in `objects`.
    let mut node_objects: Vec<usize> = Vec::with_capacity(plan.dag.nodes.len());
    for node in &plan.dag.nodes {
        let input_hashes: Vec<ContentHash> = node
            .inputs
            .iter()
            .map(|i| match *i {
                InputRef::Node(j) => content[j],
                InputRef::File(j) => plan.dag.files[j].hash,
            })
            .collect();
        let key = plan.dag.key(node, &input_hashes);
        let entry = format!("objects/{}", key.to_hex());
        let k = match index_of.get(&key) {
            Some(&k) => {
                objects[k].1.expect_kind(node.kind).map_err(|e| {
                    refused(&entry, format!("not node {}'s result: {e}", node.name))
                })?;
                k
            }
            None => {
                if !listed.contains_key(entry.as_str()) {
                    return Err(refused(
                        &entry,
                        format!(
                            "missing: the packed config's node {} has this key, and the archive \
                             does not hold its object",
                            node.name
                        ),
                    ));
                }
                let path = dir.path().join(&entry);
                let artifact = open_mapped(&path).map_err(|why| {
                    refused(&entry, format!("not a readable texsyn artifact: {why}"))
                })?;
                artifact
                    .expect_kind(node.kind)
                    .and_then(|()| artifact.verify())
                    .map_err(|e| {
                        refused(&entry, format!("not node {}'s result: {e}", node.name))
                    })?;
                index_of.insert(key, objects.len());
                objects.push((key, artifact));
                objects.len() - 1
            }
        };
        let hash = objects[k].1.content_hash();
        node_objects.push(k);
        content.push(hash);
        derived.push(LockEntry {
            node: node.name.clone(),
            key: key.to_hex(),
            content_hash: hash.to_hex(),
        });
    }
    let derived = LockFile {
        sets: lock.sets.clone(),
        entries: derived,
    };
    let differences = lock.compare(&derived);
    if !differences.is_empty() {
        let list: Vec<String> = differences.iter().map(|d| d.to_string()).collect();
        return Err(refused(
            LOCK,
            format!(
                "does not match the graph derived from the packed config and objects: {}",
                list.join("; ")
            ),
        ));
    }
    for e in &manifest.entries {
        if e.role != Role::Object {
            continue;
        }
        let hex = &e.path["objects/".len()..];
        if !objects.iter().any(|(k, _)| k.to_hex() == hex) {
            return Err(refused(
                &e.path,
                "carries a key that the packed config's graph does not produce".into(),
            ));
        }
    }

    // 5. The outputs are the exported bundles' files.
    let mut expected: BTreeMap<String, (u64, String)> = BTreeMap::new();
    for (node, &k) in plan.dag.nodes.iter().zip(&node_objects) {
        if !node.exports {
            continue;
        }
        let (key, artifact) = &objects[k];
        let view = Bundle::view(artifact)
            .map_err(|e| refused(&format!("objects/{}", key.to_hex()), e.to_string()))?;
        for entry in view.entries {
            expected.insert(
                format!("outputs/{}", entry.name),
                (entry.len, entry.hash.to_hex()),
            );
        }
    }
    for e in manifest.entries.iter().filter(|e| e.role == Role::Output) {
        match expected.remove(&e.path) {
            Some((size, hash)) if size == e.size && hash == e.blake3 => {}
            Some(_) => {
                return Err(refused(
                    &e.path,
                    "differs from the file the packed run exported under that name".into(),
                ));
            }
            None => {
                return Err(refused(
                    &e.path,
                    "an output the packed run does not export".into(),
                ));
            }
        }
    }
    if let Some((missing, _)) = expected.into_iter().next() {
        return Err(refused(
            &missing,
            "an output of the packed run that the archive does not hold".into(),
        ));
    }
    Ok(Checked {
        dir,
        manifest,
        plan,
        lock,
        lock_bytes,
        objects,
        node_objects,
    })
}

/// Checks the manifest's entries (paths, roles, hashes, one lock, one config) and indexes
/// them by path; the error names the offending entry.
fn check_manifest(m: &Manifest) -> Result<HashMap<&str, usize>, (String, String)> {
    let mut listed = HashMap::new();
    for (i, e) in m.entries.iter().enumerate() {
        let bad = |why: &str| Err((e.path.clone(), format!("the manifest lists it {why}")));
        let parts: Vec<&str> = e.path.split('/').collect();
        if !parts.iter().all(|p| valid_part(p)) {
            return bad("under a path that is not a plain relative path");
        }
        let shaped = match e.role {
            Role::Lock => e.path == LOCK,
            Role::Config | Role::Input => parts.len() >= 2 && parts[0] == "files",
            Role::Output => parts.len() == 2 && parts[0] == "outputs",
            Role::Object => parts.len() == 2 && parts[0] == "objects" && is_hex_hash(parts[1]),
        };
        if !shaped {
            return bad(&format!(
                "as {:?}, which entries at that path are not",
                e.role
            ));
        }
        if !is_hex_hash(&e.blake3) {
            return bad("with a hash that is not 64 lowercase hex digits");
        }
        if listed.insert(e.path.as_str(), i).is_some() {
            return bad("twice");
        }
    }
    let count = |r: Role| m.entries.iter().filter(|e| e.role == r).count();
    if count(Role::Lock) != 1 {
        return Err((LOCK.into(), "the manifest must list one lock file".into()));
    }
    if count(Role::Config) != 1
        || listed
            .get(m.config.as_str())
            .is_none_or(|&i| m.entries[i].role != Role::Config)
    {
        return Err((
            m.config.clone(),
            "the manifest's `config` must name its one config entry".into(),
        ));
    }
    Ok(listed)
}

/// Checks `archive` (see [`read_archive`]), then imports its objects into the cache at
/// `cache_dir` and, with `out`, writes the config, its inputs, its lock and its outputs under
/// `out` (module doc). Nothing is imported or written unless every check passes.
pub fn unpack(
    archive: &Path,
    cache_dir: &Path,
    out: Option<&Path>,
) -> Result<UnpackReport, PackError> {
    let nothing = |e: PackError| PackError::NothingImported(Box::new(e));
    let checked = read_archive(archive).map_err(nothing)?;
    let config_rel = &checked.manifest.config["files/".len()..];
    let stem = Path::new(config_rel)
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "run".into());
    let lock_rel = match config_rel.rsplit_once('/') {
        Some((d, _)) => format!("{d}/{stem}.lock"),
        None => format!("{stem}.lock"),
    };
    // The files to write under `out`, checked before anything is imported.
    let mut writes: Vec<(PathBuf, Vec<u8>)> = Vec::new();
    if let Some(out) = out {
        let mut planned: Vec<(PathBuf, Option<PathBuf>)> = checked
            .files()
            .map(|(rel, src)| (out.join(rel), Some(src)))
            .collect();
        planned.push((out.join(&lock_rel), None));
        // The outputs folder itself included: its files are written inside it.
        // `outputs` stands for any file in the run's output folder, so that the folder itself
        // is checked too.
        let outputs = checked.plan.default_out().map_err(|e| nothing(e.into()))?;
        no_link_below(out, &out.join(outputs).join("outputs")).map_err(nothing)?;
        for (dest, src) in planned {
            no_link_below(out, &dest).map_err(nothing)?;
            let bytes = match src {
                Some(src) => fs::read(&src).map_err(io_at(&src))?,
                None => checked.lock_bytes.clone(),
            };
            if writes.iter().any(|(p, _)| *p == dest) {
                return Err(nothing(PackError::Destination {
                    path: dest,
                    why: "the packed lock file would overwrite a packed input file".into(),
                }));
            }
            match fs::symlink_metadata(&dest) {
                Err(e) if e.kind() == io::ErrorKind::NotFound => {}
                Err(e) => return Err(nothing(io_at(&dest)(e))),
                Ok(m) if !m.is_file() => {
                    return Err(nothing(PackError::Destination {
                        path: dest,
                        why: "exists and is not a regular file".into(),
                    }));
                }
                Ok(_) => {
                    if fs::read(&dest).map_err(io_at(&dest))? != bytes {
                        return Err(nothing(PackError::Destination {
                            path: dest,
                            why: "exists with other content; unpack into an empty folder, or \
                                  move the file away"
                                .into(),
                        }));
                    }
                }
            }
            writes.push((dest, bytes));
        }
    }

    let cache = Cache::open(cache_dir)?;
    // A healthy object already cached under one of the archive's keys with other content is
    // never replaced: either this code computes something else than the archive's (a version
    // not bumped) or the archive was not made by it, and the user's own result must stay.
    for (node, &k) in checked.plan.dag.nodes.iter().zip(&checked.node_objects) {
        let (key, artifact) = &checked.objects[k];
        if let Lookup::Hit(a) = cache.peek(key)
            && a.verify().is_ok()
            && a.content_hash() != artifact.content_hash()
        {
            return Err(nothing(PackError::Destination {
                path: cache.object_path(key),
                why: format!(
                    "the cache already holds node {}'s object under this key with other \
                     content than the archive's (a code change without a version bump, or an \
                     archive not made by this texsyn); unpack into another --cache",
                    node.name
                ),
            }));
        }
    }
    let (mut imported, mut present) = (0, 0);
    for (key, artifact) in &checked.objects {
        let same = match cache.peek(key) {
            Lookup::Hit(a) => a.content_hash() == artifact.content_hash() && a.verify().is_ok(),
            _ => false,
        };
        if same {
            present += 1;
        } else {
            cache.put(key, artifact.file_bytes())?;
            imported += 1;
        }
    }
    let mut report = UnpackReport {
        archive: archive.to_owned(),
        cache: cache_dir.to_owned(),
        imported,
        present,
        config: None,
        lock: None,
        outputs: None,
        sets: checked.lock.sets.clone(),
    };
    if let Some(out) = out {
        for (dest, bytes) in &writes {
            write_atomic(dest, bytes)?;
        }
        let out_dir = out.join(checked.plan.default_out()?);
        outputs::recover(&out_dir)?;
        let bundles: Vec<&Artifact> = checked
            .plan
            .dag
            .nodes
            .iter()
            .zip(&checked.node_objects)
            .filter(|(n, _)| n.exports)
            .map(|(_, &k)| &checked.objects[k].1)
            .collect();
        outputs::materialize_all(&bundles, &out_dir)?;
        report.config = Some(out.join(config_rel));
        report.lock = Some(out.join(&lock_rel));
        report.outputs = Some(out_dir);
    }
    Ok(report)
}

/// Copies an entry's bytes to `dest` (creating its folder), returning their blake3 hash.
/// Why an entry could not be extracted: the archive's side (a damaged stream) or the
/// temporary folder's (full, or not writable), which must not be blamed on the archive.
#[derive(Debug)]
enum ExtractError {
    Read(io::Error),
    Write(io::Error),
}

fn extract(entry: &mut impl Read, dest: &Path) -> Result<ContentHash, ExtractError> {
    use ExtractError::{Read as R, Write as W};
    if let Some(dir) = dest.parent() {
        fs::create_dir_all(dir).map_err(W)?;
    }
    let mut file = io::BufWriter::new(File::create_new(dest).map_err(W)?);
    let mut hasher = blake3::Hasher::new();
    let mut buf = vec![0u8; 1 << 16];
    loop {
        let n = entry.read(&mut buf).map_err(R)?;
        if n == 0 {
            break;
        }
        hasher.update(&buf[..n]);
        file.write_all(&buf[..n]).map_err(W)?;
    }
    file.flush().map_err(W)?;
    Ok(ContentHash(*hasher.finalize().as_bytes()))
}

fn open_mapped(path: &Path) -> Result<Artifact, String> {
    let file = File::open(path).map_err(|e| e.to_string())?;
    // Safety: the file is in this process's own temporary folder and nothing writes to it.
    let map = unsafe { memmap2::Mmap::map(&file) }.map_err(|e| e.to_string())?;
    Artifact::open(Backing::Mapped(map)).map_err(|e| e.to_string())
}

fn is_regular<R: Read>(entry: &tar::Entry<R>) -> bool {
    matches!(
        entry.header().entry_type(),
        tar::EntryType::Regular | tar::EntryType::Continuous
    )
}

/// A path part texsyn writes: not empty, `.` or `..`, no separator or NUL.
fn valid_part(s: &str) -> bool {
    !s.is_empty() && s != "." && s != ".." && !s.contains(['/', '\\', '\0'])
}

fn is_hex_hash(s: &str) -> bool {
    s.len() == 64 && s.bytes().all(|b| matches!(b, b'0'..=b'9' | b'a'..=b'f'))
}

/// `p` made absolute (against the working directory) with `.` and `..` removed lexically, the
/// way the config's relative paths are joined to its folder.
fn absolute(p: &Path) -> io::Result<PathBuf> {
    let joined = if p.is_absolute() {
        p.to_owned()
    } else {
        std::env::current_dir()?.join(p)
    };
    let mut out = PathBuf::new();
    for c in joined.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir => {
                out.pop();
            }
            other => out.push(other),
        }
    }
    Ok(out)
}

/// The deepest folder that holds every one of `dirs` (absolute, clean).
fn common_dir(dirs: &[&Path]) -> PathBuf {
    let mut common: Vec<Component> = dirs[0].components().collect();
    for d in &dirs[1..] {
        let n = common
            .iter()
            .zip(d.components())
            .take_while(|(a, b)| **a == *b)
            .count();
        common.truncate(n);
    }
    common.iter().collect()
}

/// Refuses a symbolic link at any folder between `root` (itself allowed to be one) and
/// `path`: writing through it would put files outside `root`.
fn no_link_below(root: &Path, path: &Path) -> Result<(), PackError> {
    let Ok(rel) = path.strip_prefix(root) else {
        return Ok(());
    };
    let mut at = root.to_owned();
    for part in rel.parent().into_iter().flat_map(Path::components) {
        at.push(part);
        match fs::symlink_metadata(&at) {
            Ok(m) if m.file_type().is_symlink() => {
                return Err(PackError::Destination {
                    path: at,
                    why: format!(
                        "is a symbolic link; unpack writes only inside {} and follows no link \
                         there (remove it, or unpack into an empty folder)",
                        root.display()
                    ),
                });
            }
            Ok(_) => {}
            Err(e) if e.kind() == io::ErrorKind::NotFound => break,
            Err(e) => return Err(io_at(&at)(e)),
        }
    }
    Ok(())
}

fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), PackError> {
    if let Some(dir) = path.parent() {
        fs::create_dir_all(dir).map_err(io_at(dir))?;
    }
    let tmp = TempFile::beside(path);
    let write = || -> io::Result<()> {
        let mut f = File::create(tmp.path())?;
        f.write_all(bytes)?;
        f.sync_all()?;
        fs::rename(tmp.path(), path)
    };
    write().map_err(io_at(path))?;
    tmp.disarm();
    Ok(())
}

/// A temporary file beside its destination (`.NAME.tmp-OWNER`, [`crate::owner`]), removed on drop unless
/// disarmed (after it was renamed into place).
struct TempFile(PathBuf, std::cell::Cell<bool>);

impl TempFile {
    /// Also removes the temporaries killed writers of `dest` left
    /// ([`crate::owner::remove_stale_beside`]).
    fn beside(dest: &Path) -> TempFile {
        crate::owner::remove_stale_beside(dest);
        TempFile(
            crate::owner::temporary_beside(dest),
            std::cell::Cell::new(true),
        )
    }
    fn path(&self) -> &Path {
        &self.0
    }
    fn disarm(&self) {
        self.1.set(false);
    }
}

impl Drop for TempFile {
    fn drop(&mut self) {
        if self.1.get() {
            let _ = fs::remove_file(&self.0);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_temporary_folder_that_cannot_take_an_entry_is_not_blamed_on_the_archive() {
        // The entry's folder cannot be made (a file is in the way): a write-side error, which
        // unpack reports as the temporary folder's, not as a damaged archive.
        let d = tempfile::tempdir().unwrap();
        fs::write(d.path().join("blocker"), b"x").unwrap();
        let dest = d.path().join("blocker").join("entry");
        let e = extract(&mut &b"payload"[..], &dest).unwrap_err();
        assert!(matches!(e, ExtractError::Write(_)), "{e:?}");
        // A stream that fails mid-read is the archive's.
        struct Broken;
        impl Read for Broken {
            fn read(&mut self, _: &mut [u8]) -> io::Result<usize> {
                Err(io::Error::new(io::ErrorKind::UnexpectedEof, "cut short"))
            }
        }
        let e = extract(&mut Broken, &d.path().join("ok")).unwrap_err();
        assert!(matches!(e, ExtractError::Read(_)), "{e:?}");
        let msg = PackError::TempSpace {
            path: dest,
            source: io::Error::other("No space left on device"),
        }
        .to_string();
        assert!(msg.contains("TMPDIR") && !msg.contains("damaged"), "{msg}");
    }

    #[test]
    fn common_dir_and_absolute_are_lexical() {
        let a = absolute(Path::new("/x/y/./z/../w")).unwrap();
        assert_eq!(a, Path::new("/x/y/w"));
        let c = common_dir(&[Path::new("/x/y/w"), Path::new("/x/y"), Path::new("/x/q/r")]);
        assert_eq!(c, Path::new("/x"));
    }

    #[test]
    fn manifest_paths_are_checked_by_role() {
        let entry = |path: &str, role| ManifestEntry {
            path: path.into(),
            role,
            size: 0,
            blake3: "0".repeat(64),
            nodes: vec![],
        };
        let manifest = |extra: ManifestEntry| Manifest {
            magic: MAGIC.into(),
            format: FORMAT,
            texsyn: "0".into(),
            method: "m".into(),
            config: "files/c.toml".into(),
            sets: vec![],
            entries: vec![
                entry(LOCK, Role::Lock),
                entry("files/c.toml", Role::Config),
                extra,
            ],
        };
        assert!(check_manifest(&manifest(entry("files/a/b.png", Role::Input))).is_ok());
        for bad in [
            entry("files/../x", Role::Input),
            entry("/etc/passwd", Role::Input),
            entry("objects/abc", Role::Object),
            entry("outputs/a/b", Role::Output),
            entry("files/c.toml", Role::Input),
            entry("run.lock", Role::Input),
        ] {
            let path = bad.path.clone();
            let (named, _) = check_manifest(&manifest(bad)).unwrap_err();
            assert_eq!(named, path);
        }
    }
}
