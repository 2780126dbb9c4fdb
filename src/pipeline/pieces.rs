//! Keyed pieces: parts of a node's result cached one by one, so that a later node that needs
//! some of the same parts reuses them (DESIGN.md: "parts of a result cached separately (the
//! solid's bricks) are keyed pieces of a node, handled by the pipeline").
//!
//! A node declares its pieces with [`super::NodeSpec::pieces`]: a name, the part of its
//! parameters they depend on, and (by wrapping them in [`super::Keyed`]) the inputs they
//! depend on. Its computation opens a [`PieceStore`] with whatever else they depend on that
//! is only known then (the solid's volume, read from its request), and gets and puts pieces
//! by their coordinates. Each piece is an artifact in the cache like a node's, checked
//! (kind and payload hash) when read, and a damaged one is removed and computed again. The
//! run table counts pieces computed and reused per node.
//!
//! Pieces take no key locks (the node computing them holds its own): two *different* nodes
//! needing the same pieces at the same moment may both compute them, with the same bytes. A
//! level's missing bricks are computed as one batch from their joint dependent set, so locking
//! them one by one would mean holding one lock (an open file) per brick across the batch.

use crate::artifact::{ContentHash, ReadOwned, canonical_bytes};
use crate::cache::{Cache, Lookup};
use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

/// How many pieces a node computed and how many it found cached.
#[derive(Debug, Default)]
pub struct PieceCounts {
    pub computed: AtomicU64,
    pub reused: AtomicU64,
}

impl PieceCounts {
    pub fn get(&self) -> (u64, u64) {
        (
            self.computed.load(Ordering::Relaxed),
            self.reused.load(Ordering::Relaxed),
        )
    }
}

/// The pieces of one node, by coordinates `K` (any serde value: the solid's `(level,
/// brick)`), cached on disk and kept in memory for the rest of the computation.
pub struct PieceStore<'a, K, F> {
    cache: &'a Cache,
    prefix: ContentHash,
    counts: &'a PieceCounts,
    memory: Mutex<HashMap<K, Arc<F>>>,
}

impl<'a, K, F> PieceStore<'a, K, F>
where
    K: serde::Serialize + Eq + std::hash::Hash + Clone,
    F: ReadOwned,
{
    pub(crate) fn new(
        cache: &'a Cache,
        prefix: ContentHash,
        counts: &'a PieceCounts,
    ) -> PieceStore<'a, K, F> {
        PieceStore {
            cache,
            prefix,
            counts,
            memory: Mutex::new(HashMap::new()),
        }
    }

    /// The cache key of the piece at `coords`.
    pub fn key(&self, coords: &K) -> ContentHash {
        let mut h = blake3::Hasher::new();
        h.update(&self.prefix.0);
        h.update(&canonical_bytes(coords));
        ContentHash(*h.finalize().as_bytes())
    }

    /// The piece at `coords`, from memory or the cache; `None` if it must be computed.
    pub fn get(&self, coords: &K) -> Option<Arc<F>> {
        if let Some(p) = self.memory.lock().expect("piece memory").get(coords) {
            return Some(p.clone());
        }
        let key = self.key(coords);
        let Lookup::Hit(a) = self.cache.peek(&key) else {
            return None;
        };
        // A damaged piece is computed again, like any damaged object.
        let piece = match a.verify().map_err(|e| e.to_string()).and_then(|()| {
            a.expect_kind(F::KIND).map_err(|e| e.to_string())?;
            F::read(&a).map_err(|e| e.to_string())
        }) {
            Ok(p) => Arc::new(p),
            Err(e) => {
                tracing::warn!(
                    "cached piece {} is damaged ({e}); computing it again",
                    key.to_hex()
                );
                self.cache.remove(&key);
                return None;
            }
        };
        self.counts.reused.fetch_add(1, Ordering::Relaxed);
        self.memory
            .lock()
            .expect("piece memory")
            .insert(coords.clone(), piece.clone());
        Some(piece)
    }

    /// Drops the in-memory copies of the pieces whose coordinates `f` holds for (their cache
    /// artifacts stay; a later [`PieceStore::get`] reads them back), so that a node keeps
    /// resident only the pieces it still reads.
    pub fn forget(&self, f: impl Fn(&K) -> bool) {
        self.memory
            .lock()
            .expect("piece memory")
            .retain(|k, _| !f(k));
    }

    /// Stores a computed piece. A cache that cannot be written costs only reuse later, so
    /// it is a warning, not an error.
    pub fn put(&self, coords: &K, piece: Arc<F>) {
        if let Err(e) = self.cache.put(&self.key(coords), &piece.write()) {
            tracing::warn!("could not store a piece in the cache: {e}");
        }
        self.counts.computed.fetch_add(1, Ordering::Relaxed);
        self.memory
            .lock()
            .expect("piece memory")
            .insert(coords.clone(), piece);
    }
}

/// The key prefix shared by all pieces of one store. The parts are concatenated without
/// lengths, as the solid's brick keys were before pieces were a pipeline feature (so bricks
/// already in a cache stay valid); [`super::Dag::node`] makes sure one piece name belongs to
/// one algorithm and version, and that the keyed inputs are declared.
pub(crate) fn prefix(
    name: &str,
    version: u32,
    params: &[u8],
    keyed_inputs: &[ContentHash],
    extra: &[u8],
) -> ContentHash {
    let mut h = blake3::Hasher::new();
    h.update(format!("texsyn {name} v1\0").as_bytes());
    h.update(&version.to_le_bytes());
    h.update(params);
    for k in keyed_inputs {
        h.update(&k.0);
    }
    h.update(extra);
    ContentHash(*h.finalize().as_bytes())
}
