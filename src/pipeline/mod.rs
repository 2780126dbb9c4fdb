//! The make-like pipeline: content-hashed nodes in a DAG (DESIGN.md, "Content-hashed nodes").
//!
//! A method's wiring (`src/methods/`) expands a config into a [`Dag`]. Each [`Node`] is one
//! algorithm of one stage with its canonical parameter bytes and its inputs: files (hashed by
//! their bytes) or other nodes (hashed by their artifacts' content). A node's key is
//! blake3(stage, algorithm, code version, parameters, input content hashes; for a node that
//! exports files also [`crate::artifact::BUNDLE_FORMAT`]); the node's
//! output is stored in the cache under that key. Because keys are built from input
//! *content*, an upstream node that reruns and produces identical bytes leaves everything
//! downstream cached (early cutoff).
//!
//! Departure from DESIGN.md: the key hashes the *algorithm* name rather than the method name,
//! so two methods that run the same algorithm on the same inputs (the jump map is shared by
//! `jump_maps` and `synth2d`) share one cache object. Input files are first turned into
//! artifacts by `import` nodes (parsed, validated meshes and decoded images), so a mesh
//! converted from OBJ to OFF with identical content does not invalidate anything downstream.

pub mod executor;
pub mod node;
pub mod outputs;
pub mod pieces;
pub mod progress;
pub mod shard;
pub mod stamps;

use crate::artifact::{Artifact, ContentHash};
use crate::cache::Key;
pub use executor::{
    NodeReport, NodeStatus, PieceReport, RunOptions, RunResult, ShardResult, ShardedNode, run,
    run_shard, status,
};
pub use node::{FileHandle, Handle, Inputs, Keyed, NodeSpec, WithTail};
pub use pieces::{PieceCounts, PieceStore};
pub use progress::{Progress, ProgressMode};
pub use shard::{Shard, ShardError, ShardMode};
use std::path::{Path, PathBuf};

/// The pipeline stages (DESIGN.md, "A run"), plus `import` for turning input files into
/// artifacts.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Stage {
    Import,
    Parameterize,
    Extract,
    AnalyseExemplar,
    Field,
    Synthesize,
    Reconstruct,
}

impl Stage {
    pub fn name(self) -> &'static str {
        match self {
            Stage::Import => "import",
            Stage::Parameterize => "parameterize",
            Stage::Extract => "extract",
            Stage::AnalyseExemplar => "analyse_exemplar",
            Stage::Field => "field",
            Stage::Synthesize => "synthesize",
            Stage::Reconstruct => "reconstruct",
        }
    }
}

/// Where a node input comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum InputRef {
    /// The artifact of another node (index into [`Dag::nodes`]).
    Node(usize),
    /// An input file (index into [`Dag::files`]).
    File(usize),
}

/// An input file, read and hashed once when the DAG is built.
#[derive(Debug)]
pub struct FileInput {
    pub path: PathBuf,
    pub bytes: Vec<u8>,
    pub hash: ContentHash,
}

/// An error from a node's computation. Messages name the input file and element when the
/// problem is in user input; the error a stage returned is kept as the source.
#[derive(Debug, thiserror::Error)]
pub enum NodeError {
    /// The user's input or parameters are at fault.
    #[error(transparent)]
    Input(Box<dyn std::error::Error + Send + Sync>),
    /// A bug in texsyn (artifacts that disagree, a wiring mistake).
    #[error("internal error: {0}")]
    Internal(String),
    /// Not a failure: a node run as one shard ([`shard`]) computed its share of pieces and
    /// stops before storing an artifact, which would be partial; the value says what its
    /// share was. The executor stores nothing for the node and skips what depends on it.
    #[error("computed its share of shard {shard} and stopped")]
    Sharded {
        shard: Shard,
        share: serde_json::Value,
    },
}

impl NodeError {
    /// Any error (a stage's typed error, or a message) as the user's fault.
    pub fn input(e: impl Into<Box<dyn std::error::Error + Send + Sync>>) -> Self {
        NodeError::Input(e.into())
    }
    pub fn internal(msg: impl std::fmt::Display) -> Self {
        NodeError::Internal(msg.to_string())
    }
    /// A stage's error, as the user's fault unless the stage says it is texsyn's
    /// (`internal`, e.g. the error type's `is_internal`).
    pub fn classify<E>(e: E, internal: impl Fn(&E) -> bool) -> Self
    where
        E: std::error::Error + Send + Sync + 'static,
    {
        if internal(&e) {
            NodeError::internal(e)
        } else {
            NodeError::input(e)
        }
    }
}

impl From<texsyn_core::algorithm::Failure> for NodeError {
    fn from(e: texsyn_core::algorithm::Failure) -> Self {
        match e {
            texsyn_core::algorithm::Failure::Input(e) => NodeError::Input(e),
            texsyn_core::algorithm::Failure::Internal(m) => NodeError::Internal(m),
        }
    }
}

impl From<crate::artifact::ArtifactError> for NodeError {
    fn from(e: crate::artifact::ArtifactError) -> Self {
        NodeError::Internal(format!("reading an input artifact: {e}"))
    }
}

/// What a node's computation sees besides its inputs (which it receives as typed views, see
/// [`node`]): progress reporting and its pieces.
pub struct NodeContext<'a> {
    pub(crate) inputs: Vec<InputData<'a>>,
    pub progress: &'a Progress,
    pub(crate) cache: &'a crate::cache::Cache,
    /// Content hashes of the inputs, in declared order.
    pub(crate) input_hashes: Vec<ContentHash>,
    pub(crate) node: &'a Node,
    pub(crate) piece_counts: PieceCounts,
    /// Set when the run is one shard of a split run ([`shard`]).
    pub(crate) shard: Option<ShardMode>,
}

#[derive(Clone, Copy)]
pub(crate) enum InputData<'a> {
    Artifact(&'a Artifact),
    File(&'a FileInput),
}

impl<'a> NodeContext<'a> {
    /// The shard this run computes, if it is one shard of a split run. A node with pieces
    /// that honours it computes only its share, then returns [`NodeContext::shard_done`];
    /// one that ignores it computes its whole (correct) result, which is stored as usual.
    pub fn shard(&self) -> Option<ShardMode> {
        self.shard
    }

    /// The "error" that ends a node's share of a sharded run (see [`NodeError::Sharded`]),
    /// with what the node says about its share.
    pub fn shard_done(&self, share: &impl serde::Serialize) -> NodeError {
        match self.shard {
            Some(m) => NodeError::Sharded {
                shard: m.shard,
                share: serde_json::to_value(share).unwrap_or_default(),
            },
            None => {
                NodeError::internal(format!("{}: a share outside a sharded run", self.node.name))
            }
        }
    }

    /// The store of the node's pieces, which it declared with [`NodeSpec::pieces`]. `extra`
    /// is what the pieces depend on beyond the declared parameters and keyed inputs that is
    /// only known while computing (it goes into every piece's key).
    pub fn pieces<K, F>(
        &self,
        extra: &impl serde::Serialize,
    ) -> Result<PieceStore<'_, K, F>, NodeError>
    where
        K: serde::Serialize + Eq + std::hash::Hash + Clone,
        F: crate::artifact::ReadOwned,
    {
        let decl =
            self.node.pieces.as_ref().ok_or_else(|| {
                NodeError::internal(format!("{} declared no pieces", self.node.name))
            })?;
        let keyed: Vec<ContentHash> = self
            .node
            .keyed
            .iter()
            .zip(&self.input_hashes)
            .filter(|(k, _)| **k)
            .map(|(_, h)| *h)
            .collect();
        let prefix = pieces::prefix(
            decl.name,
            self.node.version,
            &decl.params,
            &keyed,
            &crate::artifact::canonical_bytes(extra),
        );
        Ok(PieceStore::new(self.cache, prefix, &self.piece_counts))
    }
}

pub(crate) type ComputeFn =
    Box<dyn Fn(&NodeContext) -> Result<crate::artifact::AlignedBytes, NodeError> + Send + Sync>;

/// One node of the DAG.
pub struct Node {
    /// Unique within the DAG; what reports, lock files and `--set` name.
    pub name: String,
    pub stage: Stage,
    pub algorithm: &'static str,
    /// Bumped whenever the algorithm's output for the same input changes.
    pub version: u32,
    /// Canonical bytes of the parameters (part of the key).
    pub params: Vec<u8>,
    /// The same parameters for people (graph, status, --json).
    pub params_json: serde_json::Value,
    pub inputs: Vec<InputRef>,
    /// Per input: whether its content hash is part of the key of the node's pieces.
    pub(crate) keyed: Vec<bool>,
    pub(crate) pieces: Option<node::PieceDecl>,
    /// The output is a file bundle to write into the run's output directory.
    pub exports: bool,
    /// The kind of artifact the node's output format writes: a cached object of any other
    /// kind is damaged (the header's kind code is outside the payload hash).
    pub(crate) kind: crate::artifact::Kind,
    pub(crate) compute: ComputeFn,
}

impl Node {
    /// Whether a sharded run ([`shard`]) can split this node's work: it caches pieces.
    pub fn splits_into_shards(&self) -> bool {
        self.pieces.is_some()
    }
}

/// Mixed into every node key: a change to arithmetic that every node shares changes every key,
/// as a version bump of every algorithm would. v2: transcendental functions from the pure-Rust
/// libm (`texsyn_core::math`) instead of the platform's C library.
pub const KEY_EPOCH: &[u8] = b"texsyn node key v2\0";

/// A method's nodes in topological order (every input refers to an earlier node).
#[derive(Default)]
pub struct Dag {
    pub nodes: Vec<Node>,
    pub files: Vec<FileInput>,
}

impl Dag {
    /// Reads and hashes an input file, returning its reference (the same path twice gives the
    /// same input).
    pub(crate) fn add_file(&mut self, path: &Path, role: &str) -> Result<InputRef, std::io::Error> {
        if let Some(i) = self.files.iter().position(|f| f.path == path) {
            return Ok(InputRef::File(i));
        }
        // Not a FIFO or device: those would block or never end.
        let bytes = crate::geom::io::read_regular_file(path).map_err(|e| {
            std::io::Error::new(e.kind(), format!("{} ({role}): {e}", path.display()))
        })?;
        let hash = ContentHash::of(&bytes);
        self.files.push(FileInput {
            path: path.to_owned(),
            bytes,
            hash,
        });
        Ok(InputRef::File(self.files.len() - 1))
    }

    /// Appends a node; its inputs must already be in the DAG. Methods use [`Dag::node`].
    pub(crate) fn add(&mut self, node: Node) -> InputRef {
        for input in &node.inputs {
            match *input {
                InputRef::Node(i) => assert!(i < self.nodes.len(), "node input out of order"),
                InputRef::File(i) => assert!(i < self.files.len(), "file input unknown"),
            }
        }
        assert!(
            self.nodes.iter().all(|n| n.name != node.name),
            "duplicate node name {}",
            node.name
        );
        self.nodes.push(node);
        InputRef::Node(self.nodes.len() - 1)
    }

    pub fn node_index(&self, name: &str) -> Option<usize> {
        self.nodes.iter().position(|n| n.name == name)
    }

    /// The node's key, given the content hashes of its inputs. [`KEY_EPOCH`] comes first.
    pub fn key(&self, node: &Node, input_hashes: &[ContentHash]) -> Key {
        let mut h = blake3::Hasher::new();
        h.update(KEY_EPOCH);
        h.update(node.stage.name().as_bytes());
        h.update(b"\0");
        h.update(node.algorithm.as_bytes());
        h.update(b"\0");
        h.update(&node.version.to_le_bytes());
        if node.exports {
            // How a bundle stores its files is part of what an exporting node makes.
            h.update(b"bundle format\0");
            h.update(&crate::artifact::BUNDLE_FORMAT.to_le_bytes());
        }
        h.update(&(node.params.len() as u64).to_le_bytes());
        h.update(&node.params);
        for (input, hash) in node.inputs.iter().zip(input_hashes) {
            h.update(match input {
                InputRef::Node(_) => b"N",
                InputRef::File(_) => b"F",
            });
            h.update(&hash.0);
        }
        ContentHash(*h.finalize().as_bytes())
    }

    /// Graphviz DOT of the DAG.
    pub fn to_dot(&self) -> String {
        let mut s = String::from(
            "digraph texsyn {\n  rankdir=LR;\n  node [shape=box, fontname=\"monospace\"];\n",
        );
        for (i, f) in self.files.iter().enumerate() {
            s += &format!(
                "  f{i} [shape=note, label=\"{}\"];\n",
                escape(&f.path.display().to_string())
            );
        }
        for (i, n) in self.nodes.iter().enumerate() {
            s += &format!(
                "  n{i} [label=\"{}\\n{} / {} v{}\"];\n",
                escape(&n.name),
                n.stage.name(),
                n.algorithm,
                n.version
            );
            for input in &n.inputs {
                match input {
                    InputRef::Node(j) => s += &format!("  n{j} -> n{i};\n"),
                    InputRef::File(j) => s += &format!("  f{j} -> n{i};\n"),
                }
            }
        }
        s += "}\n";
        s
    }
}

fn escape(s: &str) -> String {
    s.replace('\\', "\\\\").replace('"', "\\\"")
}
