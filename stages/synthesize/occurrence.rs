//! How much more than its fair share each block of an exemplar is copied, and the factor on a
//! match's distance that follows: J. Kopf et al., "Solid texture synthesis from 2D exemplars"
//! (SIGGRAPH 2007) §3.3, which re-weights a match by how far its source is over-represented
//! so that rarely used parts of the exemplar stay in play. Blocks rather than single texels:
//! where there are more exemplar texels than matches a single texel's count says nothing, and
//! a copied run spreads its use over neighbouring texels anyway.

/// Use counts of the `block × block` blocks of a `width × height` exemplar, against each
/// block's fair share.
pub struct BlockUse {
    width: usize,
    height: usize,
    block: usize,
    columns: usize,
    used: Vec<u32>,
    fair: Vec<f32>,
}

impl BlockUse {
    /// Counts the exemplar positions `used` (one per match). A block's fair share is
    /// proportional to how many of the positions in `domain` (those a match may take) it holds,
    /// at least 1.
    pub fn new(
        width: usize,
        height: usize,
        block: usize,
        used: impl IntoIterator<Item = (usize, usize)>,
        domain: impl IntoIterator<Item = (usize, usize)>,
    ) -> BlockUse {
        let block = block.max(1);
        let columns = width.div_ceil(block);
        let blocks = columns * height.div_ceil(block);
        let index = |(x, y): (usize, usize)| (y / block) * columns + x / block;
        let mut counts = vec![0u32; blocks];
        let mut matches = 0usize;
        for p in used {
            counts[index(p)] += 1;
            matches += 1;
        }
        let mut size = vec![0u32; blocks];
        let mut positions = 0usize;
        for p in domain {
            size[index(p)] += 1;
            positions += 1;
        }
        let per_position = matches as f32 / positions.max(1) as f32;
        let fair = size
            .iter()
            .map(|&s| (s as f32 * per_position).max(1.0))
            .collect();
        BlockUse {
            width,
            height,
            block,
            columns,
            used: counts,
            fair,
        }
    }

    /// `1 + weight · max(0, use / fair − 1)` for the block holding `(x, y)`.
    #[inline]
    pub fn factor(&self, x: usize, y: usize, weight: f32) -> f32 {
        self.block_factor((y / self.block) * self.columns + x / self.block, weight)
    }

    #[inline]
    fn block_factor(&self, b: usize, weight: f32) -> f32 {
        1.0 + weight * (self.used[b] as f32 / self.fair[b] - 1.0).max(0.0)
    }

    /// [`Self::factor`] of every position of the exemplar, row by row: one lookup per match
    /// tried instead of the block arithmetic.
    pub fn factors(&self, weight: f32) -> Vec<f32> {
        let (width, height) = (self.width, self.height);
        let per_block: Vec<f32> = (0..self.used.len())
            .map(|b| self.block_factor(b, weight))
            .collect();
        (0..height)
            .flat_map(|y| {
                let row = (y / self.block) * self.columns;
                let per_block = &per_block;
                (0..width).map(move |x| per_block[row + x / self.block])
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_blocks_used_beyond_their_share_are_penalized() {
        // A 4 × 4 exemplar in 2 × 2 blocks, every position allowed (4 per block); 8 matches,
        // so each block's fair share is 2. Block 0 is used 5 times, block 3 three times,
        // block 1 none.
        let used: Vec<(usize, usize)> = [(0, 0); 5].into_iter().chain([(3, 3); 3]).collect();
        let domain = (0..16).map(|k| (k % 4, k / 4));
        let b = BlockUse::new(4, 4, 2, used, domain);
        assert_eq!(b.factor(1, 1, 2.0), 1.0 + 2.0 * (5.0 / 2.0 - 1.0));
        assert_eq!(b.factor(2, 2, 2.0), 1.0 + 2.0 * (3.0 / 2.0 - 1.0));
        assert_eq!(b.factor(3, 0, 2.0), 1.0);
        assert_eq!(b.factor(1, 1, 0.0), 1.0);
        let all = b.factors(2.0);
        for k in 0..16 {
            assert_eq!(all[k], b.factor(k % 4, k / 4, 2.0), "position {k}");
        }
    }

    #[test]
    fn a_block_outside_the_domain_has_a_share_of_one() {
        // Only the left column of blocks may be matched: 4 matches over 8 positions. The right
        // blocks hold none, so their share is the floor of 1, and one use there is not over it.
        let domain = (0..16).map(|k| (k % 4, k / 4)).filter(|&(x, _)| x < 2);
        let used = vec![(0, 0), (0, 0), (0, 3), (3, 0)];
        let b = BlockUse::new(4, 4, 2, used, domain);
        assert_eq!(b.factor(0, 0, 1.0), 1.0); // 2 uses against a share of 2
        assert_eq!(b.factor(3, 0, 1.0), 1.0); // 1 use against the floor of 1
    }
}
