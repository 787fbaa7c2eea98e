//! The random sign patterns of the held-out sign-flip test
//! ([`super::decision`]), drawn once per block count and shared.
//!
//! Why: the test draws its patterns from a fixed seed (a diagnosis is
//! reproducible), so every test over the same number of blocks draws the
//! same patterns, and a diagnosis tests every candidate twice (the
//! absolute and the relative gain) over the same blocks. Drawing them
//! (one ChaCha word per block and pattern) cost more than the sums they
//! sign. Kept as bits: 20 000 patterns of 600 blocks are 1.5 MB.
//!
//! The sums keep their order: each pattern's is taken block by block as
//! before, four patterns side by side (four independent additions
//! overlap where one waits for the last), so every p-value is the same to
//! the bit as when each pattern was drawn as it was summed.

use std::sync::{Arc, Mutex};

use rand::{rngs::StdRng, Rng, SeedableRng};

/// Seed of the patterns.
const SEED: u64 = 0x5eed;

/// Largest pattern set kept for the next test (bits); a longer record's
/// patterns are drawn for its tests and dropped, so memory stays bounded.
const KEPT_BITS: usize = 1 << 27;

/// `flips` sign patterns over `blocks` blocks: bit `f·blocks + k` is set
/// where pattern `f` negates block `k`. Pattern after pattern, block
/// after block, each bit the top bit of one word of the seeded generator,
/// clear where the block keeps its sign: `rng.random::<bool>()`'s toss.
struct Patterns {
    blocks: usize,
    flips: usize,
    words: Vec<u64>,
}

impl Patterns {
    fn draw(blocks: usize, flips: usize) -> Patterns {
        let bits = blocks * flips;
        let mut words = vec![0u64; bits.div_ceil(64)];
        let mut rng = StdRng::seed_from_u64(SEED);
        for b in 0..bits {
            let negate = u64::from(!rng.next_u32() >> 31);
            words[b >> 6] |= negate << (b & 63);
        }
        Patterns {
            blocks,
            flips,
            words,
        }
    }

    /// 1 where pattern `f` negates block `k`.
    #[inline(always)]
    fn negates(&self, f: usize, k: usize) -> u64 {
        let b = f * self.blocks + k;
        (self.words[b >> 6] >> (b & 63)) & 1
    }
}

/// The last pattern set drawn (within [`KEPT_BITS`]).
static LAST: Mutex<Option<Arc<Patterns>>> = Mutex::new(None);

fn patterns(blocks: usize, flips: usize) -> Arc<Patterns> {
    let mut last = LAST.lock().unwrap_or_else(|e| e.into_inner());
    if let Some(p) = last.as_ref() {
        if p.blocks == blocks && p.flips == flips {
            return Arc::clone(p);
        }
    }
    let drawn = Arc::new(Patterns::draw(blocks, flips));
    if blocks * flips <= KEPT_BITS {
        *last = Some(Arc::clone(&drawn));
    }
    drawn
}

/// How many of `flips` seeded sign patterns give `tested` a signed sum at
/// or above `sum`; each pattern's sum taken in the blocks' order.
pub(super) fn count_at_or_above(tested: &[f64], sum: f64, flips: usize) -> usize {
    let n = tested.len();
    let p = patterns(n, flips);
    let signed = |g: f64, negate: u64| f64::from_bits(g.to_bits() ^ (negate << 63));
    let mut exceed = 0;
    let mut f = 0;
    while f + 4 <= flips {
        // `Sum for f64` starts at −0.0; so do these.
        let mut s = [-0.0f64; 4];
        for (k, &g) in tested.iter().enumerate() {
            for (q, s) in s.iter_mut().enumerate() {
                *s += signed(g, p.negates(f + q, k));
            }
        }
        exceed += s.iter().filter(|&&s| s >= sum).count();
        f += 4;
    }
    for f in f..flips {
        let s: f64 = tested
            .iter()
            .enumerate()
            .map(|(k, &g)| signed(g, p.negates(f, k)))
            .sum();
        if s >= sum {
            exceed += 1;
        }
    }
    exceed
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every count equals the count of patterns drawn as they are summed
    /// (the loop this replaced), for flip counts with and without a
    /// remainder of the four side by side, and for a block count drawn
    /// after another (the kept set is replaced, not reused).
    #[test]
    fn counts_are_those_of_patterns_drawn_while_summing() {
        let drawn_while_summing = |tested: &[f64], sum: f64, flips: usize| {
            let mut rng = StdRng::seed_from_u64(SEED);
            (0..flips)
                .filter(|_| {
                    let s: f64 = tested
                        .iter()
                        .map(|g| {
                            let negate = u64::from(!rng.next_u32() >> 31);
                            f64::from_bits(g.to_bits() ^ (negate << 63))
                        })
                        .sum();
                    s >= sum
                })
                .count()
        };
        for (blocks, flips) in [(7, 1001), (40, 2000), (7, 1003), (65, 999)] {
            let tested: Vec<f64> = (0..blocks)
                .map(|k| ((k * 37 % 11) as f64 - 4.0) * 0.1 + 0.05)
                .collect();
            let sum: f64 = tested.iter().sum();
            let expected = drawn_while_summing(&tested, sum, flips);
            assert!(expected > 0 && expected < flips, "{expected}");
            assert_eq!(count_at_or_above(&tested, sum, flips), expected);
        }
    }
}
