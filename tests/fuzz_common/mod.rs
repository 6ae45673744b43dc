//! The mutation-fuzzing driver shared by `tests/fuzz_loaders.rs` (core loaders) and `ui/tests/fuzz_session.rs`
//! (workbench sessions), included by path so both test crates run the same mutator and checks.

#![allow(dead_code, clippy::unwrap_used, clippy::expect_used)]

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Inputs per loader.
pub fn iterations() -> usize {
    std::env::var("TND_FUZZ_ITERS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(3000)
}

/// The longest one input may take before it counts as a hang.
pub const HANG: Duration = Duration::from_secs(5);

/// The committed seed corpus of one loader: `tests/fixtures/fuzz/<kind>/` of the workspace root.
pub fn corpus_dir(kind: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .ancestors()
        .find(|d| d.join("tests/fixtures/fuzz").is_dir())
        .unwrap_or(Path::new("."))
        .join("tests/fixtures/fuzz")
        .join(kind)
}

/// The committed seeds of one loader.
fn seeds(kind: &str) -> Vec<Vec<u8>> {
    let dir = corpus_dir(kind);
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .collect();
    files.sort();
    let seeds: Vec<Vec<u8>> = files.iter().map(|p| std::fs::read(p).unwrap()).collect();
    assert!(!seeds.is_empty(), "{}: no seeds", dir.display());
    seeds
}

const INTERESTING_BYTES: [u8; 12] = [
    0, 0xff, 0x7f, 0x80, b'-', b'9', b'\n', b' ', b'e', b'.', b'"', b'{',
];
const INTERESTING_TEXT: [&str; 10] = [
    "4611686018427387904",
    "18446744073709551615",
    "-1",
    "nan",
    "inf",
    "1e308",
    "-0",
    "2147483648",
    "0",
    "999999999",
];

/// One mutated copy of `seed`.
pub fn mutate(seed: &[u8], rng: &mut ChaCha8Rng) -> Vec<u8> {
    let mut b = seed.to_vec();
    for _ in 0..rng.random_range(1..=6) {
        let len = b.len();
        let at = if len == 0 {
            0
        } else {
            rng.random_range(0..len)
        };
        match rng.random_range(0..8) {
            0 if len > 0 => b[at] ^= 1 << rng.random_range(0..8),
            1 if len > 0 => b[at] = INTERESTING_BYTES[rng.random_range(0..INTERESTING_BYTES.len())],
            2 => b.truncate(at),
            3 => {
                let n = rng.random_range(1..16);
                let extra: Vec<u8> = (0..n).map(|_| rng.random()).collect();
                b.splice(at..at, extra);
            }
            4 if len > 0 => {
                let end = (at + rng.random_range(1..64)).min(len);
                b.drain(at..end);
            }
            5 if len > 0 => {
                let end = (at + rng.random_range(1..256)).min(len);
                let chunk = b[at..end].to_vec();
                let to = rng.random_range(0..=b.len());
                b.splice(to..to, chunk);
            }
            6 => {
                let s = INTERESTING_TEXT[rng.random_range(0..INTERESTING_TEXT.len())];
                let end = (at + rng.random_range(0..4)).min(len);
                b.splice(at..end, s.bytes());
            }
            _ if len >= 8 => {
                // A little-endian u64 field overwritten with a huge or negative value (binary headers, counts).
                let at = rng.random_range(0..len - 7);
                let v: u64 = [u64::MAX, 1 << 62, 1 << 31, 0x7fff_ffff][rng.random_range(0..4)];
                b[at..at + 8].copy_from_slice(&v.to_le_bytes());
            }
            _ => {}
        }
    }
    b
}

/// Drive `load` (true: the input was accepted) with the seeds of `kind`, which must all be accepted, and their
/// mutations.
pub fn fuzz(kind: &str, load: &dyn Fn(&[u8]) -> bool) {
    let seeds = seeds(kind);
    let mut rng = ChaCha8Rng::seed_from_u64(kind.bytes().fold(0u64, |h, c| h * 31 + u64::from(c)));
    let n = iterations().max(seeds.len());
    let mut panics = 0;
    let mut slowest = Duration::ZERO;
    for i in 0..n {
        let seed = &seeds[i % seeds.len()];
        let input = if i < seeds.len() {
            seed.clone()
        } else {
            mutate(seed, &mut rng)
        };
        let t0 = Instant::now();
        let outcome = catch_unwind(AssertUnwindSafe(|| load(&input)));
        if i < seeds.len() {
            assert!(
                matches!(outcome, Ok(true)),
                "{kind}: seed {i} is not accepted"
            );
        }
        // A panic caught inside a loader and turned into an error is not a panic here; the default hook still
        // prints it, so only what reaches this point counts.
        if outcome.is_err() {
            panics += 1;
            let path = std::env::temp_dir().join(format!("tnd-fuzz-{kind}-panic-{i}"));
            std::fs::write(&path, &input).unwrap();
            eprintln!("{kind}: input {i} panicked; saved to {}", path.display());
        }
        let dt = t0.elapsed();
        slowest = slowest.max(dt);
        assert!(dt < HANG, "{kind}: input {i} took {dt:?} (a hang?)");
    }
    eprintln!("{kind}: {n} inputs, {panics} panics, slowest {slowest:?}");
    assert_eq!(panics, 0, "{kind}: {panics} of {n} inputs panicked");
}
