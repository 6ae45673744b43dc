//! The paper's **splits** (V.A) and the per-pair randomness they rest on. Everything here is a pure function of the
//! global seed, the pair index and the object set, so neither thread counts nor resuming can change a split.
//!
//! * Pair seed: `pair_seed(seed, i)` (SplitMix64 of the seed and the index). The pair's ChaCha8 stream first draws
//!   its object (uniform over the set, or by the objects' weights when any differs from 1), then the contact
//!   ([`super::sample`]).
//! * Split: pairs of `unseen` objects go to `unseen_objects`. For each `seen` object, its pairs in index order are cut
//!   into blocks of `holdout_every` (10); in block `b` exactly one pair, at position `hash(seed, object, b) mod 10`,
//!   goes to `unseen_poses` and the others to `train`. So every seen object is split 9:1 exactly, up to its last
//!   incomplete block (which holds out its one pair only if its position falls inside the block).

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::SplitName;
use crate::objects::Split;

pub use crate::seed::mix64;

/// The seed of pair `index` in a dataset generated with `seed`.
pub fn pair_seed(seed: u64, index: usize) -> u64 {
    mix64(mix64(seed) ^ mix64(index as u64 ^ 0x5041_4952_5345_4544))
}

/// How a pair draws its object from the set: uniformly (every weight 1: the original rule, so existing datasets
/// regenerate byte for byte) or in proportion to the objects' weights ([`crate::objects::ObjectEntry::weight`]).
#[derive(Clone, Debug, PartialEq)]
pub struct ObjectDraw {
    n: usize,
    /// Cumulative normalised weights, `None` for the uniform draw.
    cumulative: Option<Vec<f64>>,
}

impl ObjectDraw {
    /// The draw for objects with these relative weights (non-finite or negative weights count as 0; all zero falls
    /// back to uniform).
    pub fn new(weights: &[f64]) -> Self {
        let clean: Vec<f64> = weights
            .iter()
            .map(|&w| if w.is_finite() && w > 0.0 { w } else { 0.0 })
            .collect();
        let total: f64 = clean.iter().sum();
        let uniform = weights.iter().all(|&w| w == 1.0) || total <= 0.0;
        let cumulative = (!uniform).then(|| {
            let mut acc = 0.0;
            clean
                .iter()
                .map(|w| {
                    acc += w / total;
                    acc
                })
                .collect()
        });
        Self {
            n: weights.len(),
            cumulative,
        }
    }

    /// Uniform over `n` objects.
    pub fn uniform(n: usize) -> Self {
        Self {
            n,
            cumulative: None,
        }
    }

    fn draw(&self, rng: &mut ChaCha8Rng) -> usize {
        match &self.cumulative {
            None => rng.random_range(0..self.n.max(1)),
            Some(c) => {
                let u: f64 = rng.random();
                c.partition_point(|&x| x <= u).min(self.n.saturating_sub(1))
            }
        }
    }
}

/// The pair's random stream, positioned after the object draw, and the drawn object index.
pub fn pair_stream(pair_seed: u64, objects: &ObjectDraw) -> (ChaCha8Rng, usize) {
    let mut rng = ChaCha8Rng::seed_from_u64(pair_seed);
    let object = objects.draw(&mut rng);
    (rng, object)
}

/// One planned pair: what is fixed before simulating it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PlannedPair {
    /// Global index.
    pub index: usize,
    /// Pair seed.
    pub seed: u64,
    /// Index into the object set's entries.
    pub object: usize,
    pub split: SplitName,
}

/// Plan `pairs` pairs over objects with the given splits and draw weights (in object-set order).
pub fn plan(
    seed: u64,
    pairs: usize,
    object_splits: &[Split],
    draw: &ObjectDraw,
    holdout_every: usize,
) -> Vec<PlannedPair> {
    let seeds: Vec<u64> = (0..pairs).map(|i| pair_seed(seed, i)).collect();
    let objects: Vec<usize> = seeds.iter().map(|&s| pair_stream(s, draw).1).collect();
    let splits = assign(seed, &objects, object_splits, holdout_every);
    (0..pairs)
        .map(|index| PlannedPair {
            index,
            seed: seeds[index],
            object: objects[index],
            split: splits[index],
        })
        .collect()
}

/// The split of each pair given its object (index into `object_splits`), by the rule in the module docs.
pub fn assign(
    seed: u64,
    objects: &[usize],
    object_splits: &[Split],
    holdout_every: usize,
) -> Vec<SplitName> {
    let k = holdout_every.max(1);
    let mut rank = vec![0usize; object_splits.len()];
    objects
        .iter()
        .map(|&object| match object_splits.get(object) {
            Some(Split::Unseen) | None => SplitName::UnseenObjects,
            Some(Split::Seen) => {
                let r = rank[object];
                rank[object] += 1;
                let block = (r / k) as u64;
                let pick = mix64(
                    mix64(seed ^ 0x484f_4c44)
                        ^ mix64(object as u64)
                        ^ block.wrapping_mul(0x9e37_79b9),
                ) % k as u64;
                if (r % k) as u64 == pick {
                    SplitName::UnseenPoses
                } else {
                    SplitName::Train
                }
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn splits_are_disjoint_and_nine_to_one_per_object() {
        let splits = [Split::Seen, Split::Unseen, Split::Seen, Split::Seen];
        let p = plan(7, 20_000, &splits, &ObjectDraw::uniform(4), 10);
        for (o, &s) in splits.iter().enumerate() {
            let mine: Vec<_> = p.iter().filter(|q| q.object == o).collect();
            match s {
                Split::Unseen => assert!(mine.iter().all(|q| q.split == SplitName::UnseenObjects)),
                Split::Seen => {
                    let held = mine
                        .iter()
                        .filter(|q| q.split == SplitName::UnseenPoses)
                        .count();
                    let n = mine.len();
                    assert!(mine.iter().all(|q| q.split != SplitName::UnseenObjects));
                    // Exactly one per complete block of 10, at most one in the last partial block.
                    assert!(held == n / 10 || held == n / 10 + 1, "{held} of {n}");
                }
            }
        }
        // A prefix of a longer plan is the shorter plan (splits do not depend on the total).
        assert_eq!(
            plan(7, 500, &splits, &ObjectDraw::uniform(4), 10)[..],
            p[..500]
        );
        // Another seed, another plan.
        assert_ne!(
            plan(8, 500, &splits, &ObjectDraw::uniform(4), 10)[..],
            p[..500]
        );
    }

    #[test]
    fn pair_seeds_are_distinct() {
        let mut seen = std::collections::HashSet::new();
        for i in 0..10_000 {
            assert!(seen.insert(pair_seed(0, i)));
        }
        assert_ne!(pair_seed(0, 1), pair_seed(1, 0));
    }

    #[test]
    fn weighted_draw_follows_the_weights_and_unit_weights_are_the_uniform_rule() {
        let splits = [Split::Seen; 3];
        let uniform = plan(5, 3000, &splits, &ObjectDraw::uniform(3), 10);
        let ones = plan(5, 3000, &splits, &ObjectDraw::new(&[1.0, 1.0, 1.0]), 10);
        assert_eq!(uniform, ones);
        let weighted = plan(5, 30_000, &splits, &ObjectDraw::new(&[6.0, 3.0, 1.0]), 10);
        let share = |o: usize| weighted.iter().filter(|p| p.object == o).count() as f64 / 30_000.0;
        // Binomial standard error at n = 30 000 is below 0.003.
        assert!((share(0) - 0.6).abs() < 0.015, "{}", share(0));
        assert!((share(1) - 0.3).abs() < 0.015, "{}", share(1));
        assert!((share(2) - 0.1).abs() < 0.015, "{}", share(2));
        let zero = plan(5, 2000, &splits, &ObjectDraw::new(&[0.0, 1.0, 0.0]), 10);
        assert!(zero.iter().all(|p| p.object == 1));
    }
}
