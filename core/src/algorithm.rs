//! The identity of a node's algorithm: its name and its version, both part of every key the
//! pipeline computes. Each stage file that a node runs exports its own (`NODE`), so a change
//! to an algorithm and the bump of its version are made in the same file.

/// An algorithm's name and version. Bump `version` whenever the output for the same inputs
/// and parameters changes: every cached result of the old version is then recomputed, and
/// the lock files that pin it change with it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Algorithm {
    pub name: &'static str,
    pub version: u32,
}

impl Algorithm {
    pub const fn new(name: &'static str, version: u32) -> Self {
        Algorithm { name, version }
    }
}
