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

/// Why a stage's node function failed: the user's input or parameters (the message names the
/// file, the element and what was wrong), or texsyn itself (artifacts that disagree with each
/// other, which no input can cause). The pipeline reports the first as a bad input and the
/// second as an internal error.
#[derive(Debug, thiserror::Error)]
pub enum Failure {
    #[error(transparent)]
    Input(Box<dyn std::error::Error + Send + Sync>),
    #[error("{0}")]
    Internal(String),
}

impl Failure {
    /// Any error (a stage's typed error, or a message) as the user's fault.
    pub fn input(e: impl Into<Box<dyn std::error::Error + Send + Sync>>) -> Self {
        Failure::Input(e.into())
    }

    pub fn internal(msg: impl std::fmt::Display) -> Self {
        Failure::Internal(msg.to_string())
    }

    /// A stage's typed error: texsyn's own fault when `internal` says so, else the user's.
    pub fn classify<E>(e: E, internal: impl Fn(&E) -> bool) -> Self
    where
        E: std::error::Error + Send + Sync + 'static,
    {
        if internal(&e) {
            Failure::internal(e)
        } else {
            Failure::input(e)
        }
    }
}
