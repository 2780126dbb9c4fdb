//! One big run across machines: `texsyn run CONFIG --shard i/N`.
//!
//! A node that caches its result as keyed pieces ([`super::pieces`]; today the solid's
//! bricks) can be split: shard `i` of `N` computes a disjoint share of the pieces a whole run
//! needs, stores them in the shared cache, and stops. A later run without `--shard` (the
//! gather) finds every piece cached and only assembles them, so its result is the unsharded
//! run's, byte for byte: a piece is a pure function of its key, whoever computes it.
//!
//! # What a shard computes
//!
//! For the solid, the shares are of the *finest* bricks of the request; each shard also
//! computes the coarser bricks its share depends on (on-demand synthesis, Zhang et al. 2011
//! §5 / Lefebvre & Hoppe 2005: the dependent set, worked backwards level by level). Coarse
//! bricks that two shares both depend on are computed by both shards when they run at the
//! same time on different machines (a shard that starts after another finds them cached).
//!
//! # How pieces are assigned ([`assign`])
//!
//! By recursive coordinate bisection of the finest bricks: the set is cut across its longest
//! extent into two parts whose brick counts are proportional to the number of shards on each
//! side (`⌊N/2⌋` and `⌈N/2⌉`), and each part again, until one shard is left. So the shares
//! differ by at most a brick or two in size (balanced by the number of finest bricks each
//! must deliver), each share is a compact block of space, and the assignment is a pure
//! function of the set of bricks and `i/N` (sorted coordinates, ties broken by the other
//! axes), so every machine computes the same partition without talking to the others.
//! Compact blocks matter because neighbouring bricks share most of their coarse-level
//! dependencies: a round-robin assignment would make every shard depend on nearly every
//! coarse brick. README, "Sharded solid runs", gives the measured cost in repeated bricks.
//!
//! # Why it is a flag and not a config value
//!
//! The shard is not a parameter of any node: it goes into no key. A node computing a share
//! must therefore never store an artifact under its real key (that artifact would be
//! partial): it computes its pieces and returns [`super::NodeError::Sharded`] with a summary
//! of its share, and the executor ([`super::run_shard`]) records that, stores nothing for the
//! node, and skips every node downstream of it (their inputs do not exist). Nothing is
//! written to the output folder by a shard.

use serde::Serialize;
use std::str::FromStr;

/// Shard `index` of `count` (`0 ≤ index < count`), as `--shard index/count` gives it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct Shard {
    pub index: u32,
    pub count: u32,
}

/// How a node with pieces runs in a sharded run.
#[derive(Clone, Copy, Debug)]
pub struct ShardMode {
    pub shard: Shard,
    /// Only say what the share is and what of it is missing (`status --shard`): compute
    /// nothing.
    pub plan_only: bool,
}

/// A `--shard` value that is not `i/N` with `0 ≤ i < N`.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum ShardError {
    #[error("--shard {given:?}: expected i/N, shard i of N counting from 0 (e.g. 0/4)")]
    Syntax { given: String },
    #[error("--shard {given:?}: the shard count N must be at least 1")]
    NoShards { given: String },
    #[error(
        "--shard {given:?}: shard index {index} is out of range; shards of {count} are numbered 0 to {}",
        count - 1
    )]
    OutOfRange {
        given: String,
        index: u32,
        count: u32,
    },
}

impl FromStr for Shard {
    type Err = ShardError;

    fn from_str(s: &str) -> Result<Shard, ShardError> {
        let given = s.to_owned();
        let syntax = || ShardError::Syntax {
            given: given.clone(),
        };
        let (i, n) = s.split_once('/').ok_or_else(syntax)?;
        let number = |t: &str| {
            // Digits only: no sign, no spaces.
            if t.is_empty() || !t.bytes().all(|b| b.is_ascii_digit()) {
                return Err(syntax());
            }
            t.parse::<u32>().map_err(|_| syntax())
        };
        let (index, count) = (number(i)?, number(n)?);
        if count == 0 {
            return Err(ShardError::NoShards { given });
        }
        if index >= count {
            return Err(ShardError::OutOfRange {
                given,
                index,
                count,
            });
        }
        Ok(Shard { index, count })
    }
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

/// The share of `shard` among `cells` (3-D grid coordinates, e.g. finest bricks), sorted, by
/// recursive coordinate bisection (see the module doc). Over all shards of one count the
/// shares are disjoint and their union is `cells` (duplicates counted once).
pub fn assign(cells: &[[i32; 3]], shard: Shard) -> Vec<[i32; 3]> {
    let mut cells = cells.to_vec();
    cells.sort_unstable();
    cells.dedup();
    let (mut lo, mut hi) = (0u32, shard.count);
    let mut part: &mut [[i32; 3]] = &mut cells;
    while hi - lo > 1 && !part.is_empty() {
        let left = (hi - lo) / 2;
        let cut = part.len() * left as usize / (hi - lo) as usize;
        let axis = longest_axis(part);
        let (a, b, c) = (axis, (axis + 1) % 3, (axis + 2) % 3);
        part.sort_unstable_by_key(|p| (p[a], p[b], p[c]));
        let (first, second) = part.split_at_mut(cut);
        if shard.index < lo + left {
            part = first;
            hi = lo + left;
        } else {
            part = second;
            lo += left;
        }
    }
    let mut share = part.to_vec();
    share.sort_unstable();
    share
}

/// The axis along which `cells` extend furthest (the first of equals).
fn longest_axis(cells: &[[i32; 3]]) -> usize {
    let extent = |a: usize| {
        let (min, max) = cells
            .iter()
            .fold((i32::MAX, i32::MIN), |(l, h), p| (l.min(p[a]), h.max(p[a])));
        i64::from(max) - i64::from(min)
    };
    let e = [extent(0), extent(1), extent(2)];
    (0..3).fold(0, |best, a| if e[a] > e[best] { a } else { best })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_and_refuses() {
        assert_eq!("0/2".parse(), Ok(Shard { index: 0, count: 2 }));
        assert_eq!("1/2".parse(), Ok(Shard { index: 1, count: 2 }));
        assert!(matches!(
            "2/2".parse::<Shard>(),
            Err(ShardError::OutOfRange { .. })
        ));
        assert!(matches!(
            "1/0".parse::<Shard>(),
            Err(ShardError::NoShards { .. })
        ));
        for bad in ["", "1", "/2", "1/", "-1/2", "a/b", "1/2/3", " 1/2", "+1/2"] {
            assert!(
                matches!(bad.parse::<Shard>(), Err(ShardError::Syntax { .. })),
                "{bad:?}"
            );
        }
    }

    #[test]
    fn shares_partition_the_cells_and_are_balanced_and_compact() {
        let cells: Vec<[i32; 3]> = (0..6)
            .flat_map(|x| (0..5).flat_map(move |y| (0..3).map(move |z| [x, y, z])))
            .filter(|p| (p[0] + p[1] + p[2]) % 7 != 3)
            .collect();
        for count in 1..=7 {
            let shares: Vec<Vec<[i32; 3]>> = (0..count)
                .map(|index| assign(&cells, Shard { index, count }))
                .collect();
            let mut all: Vec<[i32; 3]> = shares.concat();
            all.sort_unstable();
            let mut want = cells.clone();
            want.sort_unstable();
            assert_eq!(all, want, "{count} shards: not a partition");
            let sizes: Vec<usize> = shares.iter().map(Vec::len).collect();
            let (min, max) = (sizes.iter().min().unwrap(), sizes.iter().max().unwrap());
            assert!(max - min <= 2, "{count} shards: sizes {sizes:?}");
        }
        // Two shards of a box longest along x: a cut across x, not interleaved.
        let a = assign(&cells, Shard { index: 0, count: 2 });
        let b = assign(&cells, Shard { index: 1, count: 2 });
        let max_a = a.iter().map(|p| p[0]).max().unwrap();
        let min_b = b.iter().map(|p| p[0]).min().unwrap();
        assert!(max_a <= min_b, "{max_a} > {min_b}");
    }
}
