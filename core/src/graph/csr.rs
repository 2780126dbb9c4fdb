//! Compressed lists (compressed sparse rows): items bucketed by a row key into one array,
//! row `r` being `items[offsets[r]..offsets[r + 1]]`. [`Csr::from_pairs`] is the counting
//! sort that builds them (count per row, prefix sum, fill), stable, so each row keeps the
//! order in which its items were given; [`for_each_run`] works on the rows in parallel.

use rayon::prelude::*;

/// The integer type of a [`Csr`]'s offsets: `u32` for mesh-sized lists, `usize` where the
/// item count is unbounded (sparse matrices).
pub trait Offset: Copy + Default + Send + Sync {
    /// `x` as an offset; panics when it does not fit.
    fn from_usize(x: usize) -> Self;
    fn to_usize(self) -> usize;
}

impl Offset for u32 {
    fn from_usize(x: usize) -> Self {
        u32::try_from(x).expect("more items than a u32 offset can index")
    }
    fn to_usize(self) -> usize {
        self as usize
    }
}

impl Offset for usize {
    fn from_usize(x: usize) -> Self {
        x
    }
    fn to_usize(self) -> usize {
        self
    }
}

/// Items in rows: row `r` is `items[offsets[r]..offsets[r + 1]]`; `offsets` has one entry
/// per row plus one and starts at 0.
#[derive(Debug, Clone, PartialEq)]
pub struct Csr<T, O = u32> {
    pub offsets: Vec<O>,
    pub items: Vec<T>,
}

impl<T: Copy + Default, O: Offset> Csr<T, O> {
    /// `rows` rows, row `r` holding the items of the pairs `(r, item)` in the order `pairs`
    /// yields them (a stable counting sort). `pairs` is walked twice: once to count, once to
    /// fill. Panics when a key is not below `rows`.
    pub fn from_pairs<I>(rows: usize, pairs: I) -> Self
    where
        I: IntoIterator<Item = (usize, T)>,
        I::IntoIter: Clone,
    {
        let pairs = pairs.into_iter();
        let mut start = vec![0usize; rows + 1];
        for (r, _) in pairs.clone() {
            start[r + 1] += 1;
        }
        for r in 0..rows {
            start[r + 1] += start[r];
        }
        let mut next = start[..rows].to_vec();
        let mut items = vec![T::default(); start[rows]];
        for (r, x) in pairs {
            items[next[r]] = x;
            next[r] += 1;
        }
        Csr {
            offsets: start.into_iter().map(O::from_usize).collect(),
            items,
        }
    }
}

impl<T, O: Offset> Csr<T, O> {
    pub fn rows(&self) -> usize {
        self.offsets.len().saturating_sub(1)
    }

    /// Where row `r` lies in `items`.
    pub fn range(&self, r: usize) -> std::ops::Range<usize> {
        self.offsets[r].to_usize()..self.offsets[r + 1].to_usize()
    }

    pub fn row(&self, r: usize) -> &[T] {
        &self.items[self.range(r)]
    }

    pub fn row_mut(&mut self, r: usize) -> &mut [T] {
        let range = self.range(r);
        &mut self.items[range]
    }
}

/// Calls `f` on each run `items[bounds[r]..bounds[r + 1]]`, runs in parallel in groups of
/// consecutive runs (each run is handled alone, so the result is the same as in order).
pub fn for_each_run<T: Send>(items: &mut [T], bounds: &[usize], f: impl Fn(&mut [T]) + Sync) {
    const RUNS: usize = 4096;
    debug_assert_eq!(
        bounds.first().copied().unwrap_or(0),
        0,
        "runs start at item 0"
    );
    let mut groups: Vec<(usize, &mut [T])> = Vec::new();
    let mut rest = items;
    let mut at = 0;
    for r in (0..bounds.len().saturating_sub(1)).step_by(RUNS) {
        let end = bounds[(r + RUNS).min(bounds.len() - 1)];
        let (group, tail) = std::mem::take(&mut rest).split_at_mut(end - at);
        groups.push((r, group));
        rest = tail;
        at = end;
    }
    groups.into_par_iter().for_each(|(r0, group)| {
        let base = bounds[r0];
        let last = (r0 + RUNS).min(bounds.len() - 1);
        for r in r0..last {
            f(&mut group[bounds[r] - base..bounds[r + 1] - base]);
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The rows as separate lists, pushed in the order given.
    fn naive(rows: usize, pairs: &[(usize, u32)]) -> Vec<Vec<u32>> {
        let mut out = vec![Vec::new(); rows];
        for &(r, x) in pairs {
            out[r].push(x);
        }
        out
    }

    #[test]
    fn rows_keep_the_order_items_were_given_in() {
        let pairs = [(2, 10), (0, 11), (2, 12), (2, 13), (0, 14), (3, 15)];
        let c: Csr<u32> = Csr::from_pairs(5, pairs);
        assert_eq!(c.offsets, vec![0, 2, 2, 5, 6, 6]);
        assert_eq!(c.items, vec![11, 14, 10, 12, 13, 15]);
        assert_eq!(c.row(2), &[10, 12, 13]);
        assert!(c.row(1).is_empty() && c.row(4).is_empty());
        assert_eq!(c.rows(), 5);
        // No rows, no items.
        let e: Csr<u32, usize> = Csr::from_pairs(0, std::iter::empty());
        assert_eq!((e.rows(), e.offsets, e.items), (0, vec![0], vec![]));
    }

    #[test]
    #[should_panic]
    fn a_key_outside_the_rows_panics() {
        let _: Csr<u32> = Csr::from_pairs(2, [(2, 0)]);
    }

    proptest::proptest! {
        #[test]
        fn rows_equal_the_lists_pushed_one_by_one(
            rows in 0usize..20,
            raw in proptest::collection::vec((0usize..1000, proptest::num::u32::ANY), 0..200)
        ) {
            let pairs: Vec<(usize, u32)> = if rows == 0 {
                Vec::new()
            } else {
                raw.into_iter().map(|(r, x)| (r % rows, x)).collect()
            };
            let want = naive(rows, &pairs);
            let small: Csr<u32> = Csr::from_pairs(rows, pairs.iter().copied());
            let wide: Csr<u32, usize> = Csr::from_pairs(rows, pairs.iter().copied());
            proptest::prop_assert_eq!(small.rows(), rows);
            proptest::prop_assert_eq!(small.offsets[0], 0);
            proptest::prop_assert_eq!(small.items.len(), pairs.len());
            for r in 0..rows {
                proptest::prop_assert_eq!(small.row(r), want[r].as_slice());
                proptest::prop_assert_eq!(wide.row(r), want[r].as_slice());
            }
        }
    }

    #[test]
    fn runs_are_sorted_alone_and_in_place_for_any_thread_count() {
        // 10 000 runs (more than one group), some empty, of pseudo-random keys with
        // duplicates: each run sorted stably on its own equals the serial result.
        let mut bounds = vec![0usize];
        let mut items = Vec::new();
        let mut x = 12345u64;
        for r in 0..10_000 {
            let len = (r * 7919) % 9;
            for k in 0..len {
                x = x
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                items.push(((x >> 60) as u32, (r * 16 + k) as u32));
            }
            bounds.push(items.len());
        }
        let mut expected = items.clone();
        for r in 0..bounds.len() - 1 {
            expected[bounds[r]..bounds[r + 1]].sort_by_key(|p| p.0);
        }
        for threads in [1, 3] {
            let mut got = items.clone();
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| for_each_run(&mut got, &bounds, |run| run.sort_by_key(|p| p.0)));
            assert_eq!(got, expected);
        }
        assert_ne!(
            items, expected,
            "the runs were already sorted: the test checks nothing"
        );
        // No runs at all, and one empty run.
        for bounds in [vec![], vec![0]] {
            let mut none: Vec<(u32, u32)> = Vec::new();
            for_each_run(&mut none, &bounds, |run| run.sort_by_key(|p| p.0));
            assert!(none.is_empty());
        }
    }
}
