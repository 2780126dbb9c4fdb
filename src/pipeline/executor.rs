//! Runs a DAG against the cache: looks each node's key up, computes what is missing, and
//! recovers from corrupted objects by recomputing them.
//!
//! Nodes run one after another in topological order; each node parallelizes its own work
//! with rayon. (With two cores, node-level parallelism would only compete with that.)
//! Payloads are re-hashed before a node reads them, and the artifacts a run hands out (the
//! exported bundles and the nodes nothing else reads) are re-hashed before they are returned,
//! so a corrupted object is caught where it would do harm, while a rerun with nothing changed
//! reads nothing but headers and the outputs' payloads. `texsyn run` defers the exported
//! bundles' check to the moment it writes a file from one
//! ([`RunOptions::defer_export_checks`]): when every output is already on disk it reads none. Headers are checked on every lookup
//! (see [`Cache::peek_kind`]), including that the kind is the node's output kind. Any object
//! that fails a check is removed, recomputed and stored again, and listed in
//! [`RunResult::damaged`]; it is never an error.
//!
//! Several processes may share one cache. A node that is missing is computed under its key's
//! lock ([`crate::cache::KeyLocks`]): the first process to need it computes it, the others
//! wait, find it stored when they get the lock, and report it cached. A lock is taken only
//! once the node's inputs are resolved and held only while computing and storing it, so a
//! process holding a lock never waits for another: no cycle of waits can form. The import
//! nodes, which are stored together at the end of their phase, take their locks together
//! first, in key order, for the same reason. Where locks cannot be used, one warning says so
//! and the run goes on unlocked, as before (correct, possibly computing a key twice).
//!
//! [`run_shard`] runs one shard of a split run (`--shard i/N`, see [`super::shard`]): the
//! nodes with pieces compute their share and store no artifact, and what depends on them waits
//! for the gather run.

use super::{
    Dag, InputData, InputRef, NodeContext, NodeError, Progress, ProgressMode, Shard, ShardMode,
};
use crate::artifact::{Artifact, ContentHash};
use crate::cache::{Cache, CacheError, Key, KeyLock, KeyLocks, Locking, Lookup};
use serde::Serialize;
use std::collections::HashMap;
use std::time::Instant;

#[derive(Clone, Copy, Debug)]
pub struct RunOptions {
    pub progress: ProgressMode,
    /// Re-hash every artifact's payload, cached or not (`texsyn verify`).
    pub verify_all: bool,
    /// Hand the exported bundles out without re-hashing the cached ones: the caller checks
    /// a bundle when it reads it ([`super::outputs::materialize_checked`] does, before it
    /// writes a file from it) and reruns with this off when that check fails, which repairs
    /// the object. A rerun whose outputs are all on disk then reads no payload at all.
    pub defer_export_checks: bool,
}

impl Default for RunOptions {
    fn default() -> Self {
        RunOptions {
            progress: ProgressMode::Hidden,
            verify_all: false,
            defer_export_checks: false,
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum NodeStatus {
    /// Found in the cache.
    Cached,
    /// Computed in this run.
    Ran,
}

#[derive(Clone, Debug, Serialize)]
pub struct NodeReport {
    pub node: String,
    pub stage: &'static str,
    pub algorithm: &'static str,
    pub status: NodeStatus,
    pub seconds: f64,
    pub bytes: u64,
    pub key: String,
    pub content_hash: String,
    /// Pieces computed and reused (nodes that declare pieces; see [`super::pieces`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pieces: Option<PieceReport>,
    /// The process's peak resident memory while this node computed (Linux; nodes that ran).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub peak_memory_bytes: Option<u64>,
    /// CPU seconds of the whole process (all threads) while this node computed (Linux; nodes
    /// that ran): on a shared machine, a steadier measure of the node's work than `seconds`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cpu_seconds: Option<f64>,
}

#[derive(Clone, Copy, Debug, Serialize, PartialEq, Eq)]
pub struct PieceReport {
    pub computed: u64,
    pub reused: u64,
}

pub struct RunResult {
    pub reports: Vec<NodeReport>,
    /// Each node's artifact, by node index.
    pub artifacts: Vec<Artifact>,
    /// Cache problems met and repaired on the way (corrupted or truncated objects).
    pub warnings: Vec<String>,
    /// The damaged objects among them, each recomputed and replaced.
    pub damaged: Vec<Damage>,
}

/// A cache object found damaged (and recomputed, and replaced).
#[derive(Clone, Debug, Serialize, PartialEq, Eq)]
pub struct Damage {
    pub node: String,
    pub key: String,
    pub path: std::path::PathBuf,
    pub problem: String,
}

#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    #[error("{node}: {source}")]
    Node { node: String, source: NodeError },
    #[error(transparent)]
    Cache(#[from] CacheError),
    #[error("{node}: produced an unreadable artifact: {message} (a bug in texsyn)")]
    BadOutput { node: String, message: String },
}

struct State {
    key: Key,
    artifact: Artifact,
    verified: bool,
    status: NodeStatus,
    seconds: f64,
    pieces: Option<PieceReport>,
    /// Peak resident memory of the process while the node computed (nodes that ran).
    peak: Option<u64>,
    /// CPU seconds of the process while the node computed (nodes that ran).
    cpu: Option<f64>,
}

struct Executor<'a> {
    dag: &'a Dag,
    cache: &'a Cache,
    opts: RunOptions,
    states: Vec<Option<State>>,
    warnings: Vec<String>,
    damaged: Vec<Damage>,
    /// While set, computed artifacts are kept in memory instead of stored (see [`run`]).
    deferred: Option<Vec<(Key, usize)>>,
    locks: KeyLocks,
    /// Key locks held until the key's object is stored.
    held: HashMap<Key, KeyLock>,
    /// Set once locking failed (and was warned about): the rest of the run goes unlocked.
    unlocked: bool,
    /// Set in a sharded run ([`run_shard`]).
    shard: Option<ShardMode>,
    /// Per node, whether (and why) a sharded run stopped short of its artifact.
    stopped: Vec<Stop>,
    sharded: Vec<ShardedNode>,
}

/// Brings every node of the DAG up to date and returns their artifacts.
///
/// The import nodes (parsing the input files) run first and store nothing until all of them
/// have succeeded, so a bad input file leaves the cache exactly as it was.
pub fn run(dag: &Dag, cache: &Cache, opts: RunOptions) -> Result<RunResult, PipelineError> {
    let mut ex = Executor::new(dag, cache, opts, None);
    ex.run_all()?;
    let mut reports = Vec::new();
    let mut artifacts = Vec::new();
    for (node, state) in dag.nodes.iter().zip(ex.states) {
        let s = state.expect("every node resolved");
        reports.push(s.report(node));
        artifacts.push(s.artifact);
    }
    Ok(RunResult {
        reports,
        artifacts,
        warnings: ex.warnings,
        damaged: ex.damaged,
    })
}

/// What one shard of a split run did ([`run_shard`]).
#[derive(Clone, Debug, Serialize)]
pub struct ShardResult {
    pub shard: Shard,
    /// The nodes brought up to date, as in a whole run (those upstream of the split nodes).
    pub nodes: Vec<NodeReport>,
    /// The nodes that computed (or, planning, would compute) their share of pieces and
    /// stored no artifact.
    pub sharded: Vec<ShardedNode>,
    /// The nodes left to the gather run (downstream of a split node).
    pub skipped: Vec<String>,
    pub warnings: Vec<String>,
}

/// A node that computed its share of a sharded run.
#[derive(Clone, Debug, Serialize)]
pub struct ShardedNode {
    pub node: String,
    /// The key the whole node's artifact has (stored by the gather run, not by a shard).
    pub key: String,
    pub seconds: f64,
    /// Pieces computed and reused by this shard.
    pub pieces: PieceReport,
    /// What the node says its share was (the solid: its finest bricks, work per level).
    pub share: serde_json::Value,
}

/// Runs shard `shard` of the DAG (see [`super::shard`]): the nodes upstream of any node with
/// pieces are brought up to date as in [`run`], each node with pieces computes its share of
/// pieces and stores no artifact, and the nodes downstream of those are skipped. With
/// `plan_only` (`status --shard`), nothing is computed or stored: nodes not in the cache are
/// skipped, and a node with pieces whose inputs are all cached says what its share would
/// compute.
pub fn run_shard(
    dag: &Dag,
    cache: &Cache,
    opts: RunOptions,
    shard: Shard,
    plan_only: bool,
) -> Result<ShardResult, PipelineError> {
    let mode = ShardMode { shard, plan_only };
    let mut ex = Executor::new(dag, cache, opts, Some(mode));
    ex.run_all()?;
    let mut nodes = Vec::new();
    let mut skipped = Vec::new();
    for (i, node) in dag.nodes.iter().enumerate() {
        match (&ex.states[i], ex.stopped[i]) {
            (Some(s), _) => nodes.push(s.report(node)),
            (None, Stop::Skipped) => skipped.push(node.name.clone()),
            (None, _) => {}
        }
    }
    Ok(ShardResult {
        shard,
        nodes,
        sharded: ex.sharded,
        skipped,
        warnings: ex.warnings,
    })
}

impl State {
    fn report(&self, node: &super::Node) -> NodeReport {
        NodeReport {
            node: node.name.clone(),
            stage: node.stage.name(),
            algorithm: node.algorithm,
            status: self.status,
            seconds: self.seconds,
            bytes: self.artifact.len() as u64,
            key: self.key.to_hex(),
            content_hash: self.artifact.content_hash().to_hex(),
            pieces: self.pieces,
            peak_memory_bytes: self.peak,
            cpu_seconds: self.cpu,
        }
    }
}

/// Why a node of a sharded run has no artifact.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Stop {
    /// It has one (or will).
    No,
    /// It computed its share and stopped.
    Sharded,
    /// It depends on a node that stopped (or, planning, is not cached).
    Skipped,
}

impl<'a> Executor<'a> {
    fn new(dag: &'a Dag, cache: &'a Cache, opts: RunOptions, shard: Option<ShardMode>) -> Self {
        Executor {
            dag,
            cache,
            opts,
            states: (0..dag.nodes.len()).map(|_| None).collect(),
            warnings: Vec::new(),
            damaged: Vec::new(),
            deferred: Some(Vec::new()),
            locks: cache.locks(),
            held: HashMap::new(),
            unlocked: false,
            shard,
            stopped: vec![Stop::No; dag.nodes.len()],
            sharded: Vec::new(),
        }
    }

    /// Resolves every node (in a sharded run: every node not stopped).
    fn run_all(&mut self) -> Result<(), PipelineError> {
        let (dag, cache) = (self.dag, self.cache);
        let imports: Vec<usize> = (0..dag.nodes.len())
            .filter(|&i| dag.nodes[i].stage == super::Stage::Import)
            .collect();
        // Planning (`status --shard`) computes and stores nothing: it takes no lock.
        if !self.planning() {
            self.lock_missing_imports(&imports);
        }
        for &i in &imports {
            self.resolve(i)?;
        }
        for (key, i) in self.deferred.take().unwrap_or_default() {
            let state = self.states[i].as_ref().expect("resolved above");
            cache.put(&key, state.artifact.file_bytes())?;
        }
        self.held.clear();
        // What the run hands out is read by the caller (the bundles are written to the output
        // directory): re-hash it like a node's input, as soon as it is resolved, so a repair
        // that changes its content hash comes before anything downstream is keyed on it.
        let mut read = vec![false; dag.nodes.len()];
        for node in &dag.nodes {
            for input in &node.inputs {
                if let InputRef::Node(j) = *input {
                    read[j] = true;
                }
            }
        }
        for i in 0..dag.nodes.len() {
            if self.stopped[i] != Stop::No {
                continue;
            }
            let blocked = dag.nodes[i]
                .inputs
                .iter()
                .any(|input| matches!(*input, InputRef::Node(j) if self.stopped[j] != Stop::No));
            if blocked {
                self.stopped[i] = Stop::Skipped;
                continue;
            }
            if self.states[i].is_none() {
                self.resolve(i)?;
            }
            let handed_out = dag.nodes[i].exports || !read[i];
            let deferred = self.opts.defer_export_checks && dag.nodes[i].exports;
            if self.states[i].is_some() && handed_out && !deferred {
                self.ensure_verified(i)?;
            }
        }
        Ok(())
    }
}

impl Executor<'_> {
    fn input_hashes(&self, i: usize) -> Vec<ContentHash> {
        self.dag.nodes[i]
            .inputs
            .iter()
            .map(|input| match *input {
                InputRef::Node(j) => self.states[j]
                    .as_ref()
                    .expect("inputs resolve first")
                    .artifact
                    .content_hash(),
                InputRef::File(j) => self.dag.files[j].hash,
            })
            .collect()
    }

    fn warn(&mut self, msg: String) {
        tracing::warn!("{msg}");
        self.warnings.push(msg);
    }

    /// Records and warns about node `i`'s damaged object (already removed by the cache, or
    /// removed here), which the caller recomputes.
    fn damaged(&mut self, i: usize, key: &Key, problem: String) {
        let node = self.dag.nodes[i].name.clone();
        let path = self.cache.object_path(key);
        self.cache.remove(key);
        self.warn(format!(
            "{node}: cached artifact {} is damaged ({problem}); recomputing",
            path.display()
        ));
        self.damaged.push(Damage {
            node,
            key: key.to_hex(),
            path,
            problem,
        });
    }

    /// Takes the locks of the import nodes whose objects are missing, in key order (they are
    /// held until all imports are stored; one order for every process rules out a cycle).
    fn lock_missing_imports(&mut self, imports: &[usize]) {
        let mut keys: Vec<(Key, usize)> = imports
            .iter()
            .filter(|&&i| {
                let inputs = &self.dag.nodes[i].inputs;
                inputs.iter().all(|r| matches!(r, InputRef::File(_)))
            })
            .map(|&i| (self.dag.key(&self.dag.nodes[i], &self.input_hashes(i)), i))
            .filter(|(key, _)| !self.cache.object_path(key).is_file())
            .collect();
        keys.sort();
        keys.dedup_by_key(|k| k.0);
        for (key, i) in keys {
            self.lock_key(i, key, true);
        }
    }

    /// Takes `key`'s lock for node `i`, waiting for another process if `wait` (saying so);
    /// else only if free. Whether it is now held.
    fn lock_key(&mut self, i: usize, key: Key, wait: bool) -> bool {
        if self.held.contains_key(&key) {
            return true;
        }
        if self.unlocked {
            return false;
        }
        let name = &self.dag.nodes[i].name;
        let bars = self.opts.progress != ProgressMode::Hidden;
        let locking = if wait {
            self.locks.lock(&key, || {
                let msg = format!("waiting for {name} (computed by another process)");
                if bars {
                    eprintln!("{msg}");
                } else {
                    tracing::info!("{msg}");
                }
            })
        } else {
            self.locks.try_lock(&key)
        };
        match locking {
            Locking::Held(lock) => {
                self.held.insert(key, lock);
                true
            }
            Locking::Busy => false,
            Locking::Unavailable(reason) => {
                self.unlocked = true;
                self.warn(format!(
                    "key locks are unavailable ({reason}); going on without them: processes \
                     sharing this cache may compute the same node twice (with the same result)"
                ));
                false
            }
        }
    }

    /// Before computing node `i`: takes its key's lock, and if another process stored the
    /// object meanwhile (while this one waited, or between its lookup and the lock), takes
    /// that as node `i`'s result (cached, payload verified) and releases the lock. Whether
    /// it did.
    fn found_after_locking(&mut self, i: usize, key: Key, start: Instant) -> bool {
        // The imports are stored at the end of their phase: wait only in the key order of
        // `lock_missing_imports`, which took theirs; any other import goes on unlocked.
        let wait = self.deferred.is_none();
        if !self.lock_key(i, key, wait) {
            return false;
        }
        match self.cache.peek_kind(&key, Some(self.dag.nodes[i].kind)) {
            Lookup::Hit(artifact) => match artifact.verify() {
                Ok(()) => {
                    self.held.remove(&key);
                    self.states[i] = Some(State {
                        key,
                        artifact,
                        verified: true,
                        status: NodeStatus::Cached,
                        seconds: start.elapsed().as_secs_f64(),
                        pieces: None,
                        peak: None,
                        cpu: None,
                    });
                    true
                }
                Err(e) => {
                    drop(artifact);
                    self.damaged(i, &key, e.to_string());
                    false
                }
            },
            Lookup::Invalid(e) => {
                self.damaged(i, &key, e.to_string());
                false
            }
            Lookup::Miss => false,
        }
    }

    fn resolve(&mut self, i: usize) -> Result<(), PipelineError> {
        let dag = self.dag;
        let node = &dag.nodes[i];
        let key = self.dag.key(node, &self.input_hashes(i));
        let start = Instant::now();
        if self.shard.is_some() && node.pieces.is_some() {
            // A shard computes its share even when the whole node is cached (cheap then:
            // every piece is found), so it always says what its share is.
            return self.compute(i, key);
        }
        match self.cache.peek_kind(&key, Some(node.kind)) {
            Lookup::Hit(artifact) => {
                let mut verified = false;
                if self.opts.verify_all {
                    if let Err(e) = artifact.verify() {
                        drop(artifact);
                        self.damaged(i, &key, e.to_string());
                        return self.compute(i, key);
                    }
                    verified = true;
                }
                self.states[i] = Some(State {
                    key,
                    artifact,
                    verified,
                    status: NodeStatus::Cached,
                    seconds: start.elapsed().as_secs_f64(),
                    pieces: None,
                    peak: None,
                    cpu: None,
                });
                Ok(())
            }
            // Planning changes nothing in the cache: a damaged object is left to a run.
            Lookup::Invalid(_) if self.planning() => self.compute(i, key),
            Lookup::Invalid(e) => {
                self.damaged(i, &key, e.to_string());
                self.compute(i, key)
            }
            Lookup::Miss => self.compute(i, key),
        }
    }

    fn planning(&self) -> bool {
        self.shard.is_some_and(|m| m.plan_only)
    }

    /// Makes sure the payload of node `j`'s artifact is intact, recomputing it if not.
    /// Returns whether its content hash changed (only if the header itself was damaged).
    fn ensure_verified(&mut self, j: usize) -> Result<bool, PipelineError> {
        let state = self.states[j].as_ref().expect("inputs resolve first");
        if state.verified {
            return Ok(false);
        }
        match state.artifact.verify() {
            Ok(()) => {
                self.states[j].as_mut().unwrap().verified = true;
                Ok(false)
            }
            Err(e) if self.planning() => {
                // Planning repairs nothing; the run will.
                let msg = format!(
                    "{}: cached artifact is damaged ({e})",
                    self.dag.nodes[j].name
                );
                self.warn(msg);
                Ok(false)
            }
            Err(e) => {
                let (key, old) = (state.key, state.artifact.content_hash());
                self.damaged(j, &key, e.to_string());
                self.compute(j, key)?;
                let new = self.states[j].as_ref().unwrap().artifact.content_hash();
                Ok(new != old)
            }
        }
    }

    fn compute(&mut self, i: usize, key: Key) -> Result<(), PipelineError> {
        let dag = self.dag;
        let node = &dag.nodes[i];
        let mut changed = false;
        for input in &node.inputs {
            if let InputRef::Node(j) = *input {
                changed |= self.ensure_verified(j)?;
            }
        }
        if changed {
            // A repaired input came back with other content: this node's key is different.
            return self.resolve(i);
        }
        if self.planning() && node.pieces.is_none() {
            // `status --shard` computes nothing but the split nodes' plans.
            self.stopped[i] = Stop::Skipped;
            return Ok(());
        }
        let start = Instant::now();
        // A shard's split node stores no artifact under its key, so it takes no lock on it:
        // shards on one cache run side by side (their pieces are not locked; see pieces.rs).
        let splits = self.shard.is_some() && node.pieces.is_some();
        if !splits && self.found_after_locking(i, key, start) {
            return Ok(());
        }
        tracing::info!("computing {} (key {})", node.name, key.to_hex());
        let progress = Progress::new(self.opts.progress, &node.name);
        let input_hashes = self.input_hashes(i);
        let peak;
        let cpu_before = crate::memory::process_cpu_seconds();
        let (result, pieces) = {
            let inputs = node
                .inputs
                .iter()
                .map(|input| match *input {
                    InputRef::Node(j) => {
                        InputData::Artifact(&self.states[j].as_ref().unwrap().artifact)
                    }
                    InputRef::File(j) => InputData::File(&self.dag.files[j]),
                })
                .collect();
            let ctx = NodeContext {
                inputs,
                progress: &progress,
                cache: self.cache,
                input_hashes,
                node,
                piece_counts: Default::default(),
                shard: self.shard,
            };
            let measured = crate::memory::reset_peak_resident();
            let result = (node.compute)(&ctx);
            peak = if measured {
                crate::memory::peak_since_reset()
            } else {
                None
            };
            let (computed, reused) = ctx.piece_counts.get();
            let pieces = node
                .pieces
                .is_some()
                .then_some(PieceReport { computed, reused });
            (result, pieces)
        };
        let cpu = cpu_before
            .zip(crate::memory::process_cpu_seconds())
            .map(|(a, b)| b - a);
        progress.finish();
        if let Err(NodeError::Sharded { share, .. }) = result {
            self.stopped[i] = Stop::Sharded;
            self.sharded.push(ShardedNode {
                node: node.name.clone(),
                key: key.to_hex(),
                seconds: start.elapsed().as_secs_f64(),
                pieces: pieces.unwrap_or(PieceReport {
                    computed: 0,
                    reused: 0,
                }),
                share,
            });
            return Ok(());
        }
        let bytes = result.map_err(|source| PipelineError::Node {
            node: node.name.clone(),
            source,
        })?;
        let artifact = Artifact::from_bytes(bytes).map_err(|e| PipelineError::BadOutput {
            node: node.name.clone(),
            message: e.to_string(),
        })?;
        match &mut self.deferred {
            Some(pending) => pending.push((key, i)),
            None => {
                self.cache.put(&key, artifact.file_bytes())?;
                self.held.remove(&key);
            }
        }
        self.states[i] = Some(State {
            key,
            artifact,
            verified: true,
            status: NodeStatus::Ran,
            seconds: start.elapsed().as_secs_f64(),
            pieces,
            peak,
            cpu,
        });
        Ok(())
    }
}

/// What `run` would do, without doing it (like `make -n`).
#[derive(Clone, Debug, Serialize)]
pub struct StatusLine {
    pub node: String,
    pub stage: &'static str,
    pub algorithm: &'static str,
    /// "cached", "run" (its key is not in the cache) or "maybe" (an input will be recomputed;
    /// whether this node reruns depends on whether that changes the input's content).
    pub state: &'static str,
    pub key: Option<String>,
}

pub fn status(dag: &Dag, cache: &Cache) -> Vec<StatusLine> {
    let mut hashes: Vec<Option<ContentHash>> = vec![None; dag.nodes.len()];
    let mut lines = Vec::new();
    for (i, node) in dag.nodes.iter().enumerate() {
        let known: Option<Vec<ContentHash>> = node
            .inputs
            .iter()
            .map(|input| match *input {
                InputRef::Node(j) => hashes[j],
                InputRef::File(j) => Some(dag.files[j].hash),
            })
            .collect();
        let (state, key) = match known {
            None => ("maybe", None),
            Some(h) => {
                let key = dag.key(node, &h);
                match cache.peek_kind(&key, Some(node.kind)) {
                    Lookup::Hit(a) => {
                        hashes[i] = Some(a.content_hash());
                        ("cached", Some(key))
                    }
                    _ => ("run", Some(key)),
                }
            }
        };
        lines.push(StatusLine {
            node: node.name.clone(),
            stage: node.stage.name(),
            algorithm: node.algorithm,
            state,
            key: key.map(|k| k.to_hex()),
        });
    }
    lines
}
