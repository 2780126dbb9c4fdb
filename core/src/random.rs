//! Counter-based randomness (DESIGN.md, "Determinism"): every random number is a pure
//! function of (seed, stream, index), never drawn from a shared generator, so results do not
//! depend on the order in which threads happen to run.

/// A 64-bit hash of (seed, stream, index) in which every input bit affects every output bit:
/// three chained rounds of the splitmix64 finalizer. Streams separate the uses within one
/// algorithm (e.g. "which entry" vs "which fallback address").
#[inline]
pub fn counter_hash(seed: u64, stream: u64, index: u64) -> u64 {
    let h = splitmix64(seed);
    let h = splitmix64(h ^ stream.wrapping_mul(0xD6E8_FEB8_6659_FD93));
    splitmix64(h ^ index.wrapping_mul(0xA076_1D64_78BD_642F))
}

#[inline]
fn splitmix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// A uniform number in [0, 1) from (seed, stream, index).
#[inline]
pub fn counter_unit(seed: u64, stream: u64, index: u64) -> f32 {
    (counter_hash(seed, stream, index) >> 40) as f32 * (1.0 / (1u64 << 24) as f32)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn units_are_in_range_and_roughly_uniform() {
        let n = 100_000;
        let mut buckets = [0u32; 10];
        for i in 0..n {
            let u = counter_unit(42, 1, i);
            assert!((0.0..1.0).contains(&u));
            buckets[(u * 10.0) as usize] += 1;
        }
        for b in buckets {
            assert!((9_000..11_000).contains(&b), "{buckets:?}");
        }
    }

    #[test]
    fn seeds_streams_and_indices_decorrelate() {
        let a: Vec<u64> = (0..64).map(|i| counter_hash(1, 0, i)).collect();
        let b: Vec<u64> = (0..64).map(|i| counter_hash(2, 0, i)).collect();
        let c: Vec<u64> = (0..64).map(|i| counter_hash(1, 1, i)).collect();
        let same = |x: &[u64], y: &[u64]| x.iter().zip(y).filter(|(p, q)| p == q).count();
        assert_eq!(same(&a, &b), 0);
        assert_eq!(same(&a, &c), 0);
        // Neighbouring indices differ in about half their bits.
        let flips: u32 = a.windows(2).map(|w| (w[0] ^ w[1]).count_ones()).sum();
        let mean = flips as f64 / 63.0;
        assert!((24.0..40.0).contains(&mean), "{mean}");
    }
}
