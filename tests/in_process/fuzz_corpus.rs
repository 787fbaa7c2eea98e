//! Every fuzz target of `motorbench::fuzz` over its checked-in corpus
//! (`fuzz/corpus/<target>/`) and over fixed-seed mutations of it, so each
//! CI run exercises every parser that reads outside data with inputs no
//! one wrote by hand. The long, coverage-guided runs are `cargo fuzz`'s
//! (`fuzz/README.md`); inputs they found that once broke a promise are in
//! the corpus too.
//!
//! `MOTORBENCH_FUZZ_CASES=N` sets the mutations per target (default 1000).
//! An input that breaks a promise is written to
//! `target/fuzz-failures/<target>-<n>` and named in the failure.

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};

use motorbench::fuzz::TARGETS;
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};

fn corpus(target: &str) -> Vec<Vec<u8>> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("fuzz/corpus")
        .join(target);
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .collect();
    files.sort();
    files.iter().map(|f| std::fs::read(f).unwrap()).collect()
}

/// Bytes a parser treats specially somewhere: separators, signs, digits,
/// exponent and special-number letters, brackets, line ends, 0 and 0xff.
const INTERESTING: &[u8] = b",;=.-+0919eEinfNaN[]{}\"#*$\r\n\t \x00\xff\x7f";

/// One mutation of `input` (`others`: the corpus, for splices).
fn mutate(rng: &mut StdRng, input: &[u8], others: &[Vec<u8>]) -> Vec<u8> {
    let mut v = input.to_vec();
    for _ in 0..rng.random_range(1..=4) {
        let len = v.len();
        let at = if len == 0 {
            0
        } else {
            rng.random_range(0..len)
        };
        match rng.random_range(0..8) {
            0 if len > 0 => v[at] ^= 1 << rng.random_range(0..8),
            1 if len > 0 => v[at] = INTERESTING[rng.random_range(0..INTERESTING.len())],
            2 => {
                let n = rng.random_range(1..=16);
                let bytes: Vec<u8> = (0..n)
                    .map(|_| INTERESTING[rng.random_range(0..INTERESTING.len())])
                    .collect();
                v.splice(at..at, bytes);
            }
            3 if len > 0 => {
                let end = (at + rng.random_range(1..=64)).min(len);
                v.drain(at..end);
            }
            4 if len > 0 => {
                let end = (at + rng.random_range(1..=64)).min(len);
                let copy = v[at..end].to_vec();
                v.splice(end..end, copy);
            }
            5 => v.truncate(at),
            6 if len > 0 => {
                // A number made huge, tiny or negative where a digit was.
                let forms: [&[u8]; 5] =
                    [b"1e308", b"-0", b"1e-320", b"99999999999999999999", b"-1"];
                let f = forms[rng.random_range(0..forms.len())];
                v.splice(at..(at + 1).min(len), f.iter().copied());
            }
            _ => {
                let other = &others[rng.random_range(0..others.len())];
                if !other.is_empty() {
                    let from = rng.random_range(0..other.len());
                    v.truncate(at);
                    v.extend_from_slice(&other[from..]);
                }
            }
        }
    }
    v
}

fn run(name: &str, target: fn(&[u8]), inputs: impl Iterator<Item = Vec<u8>>) -> usize {
    let mut n = 0;
    for input in inputs {
        n += 1;
        if let Err(panic) = catch_unwind(AssertUnwindSafe(|| target(&input))) {
            let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/fuzz-failures");
            std::fs::create_dir_all(&dir).unwrap();
            let path = dir.join(format!("{name}-{n}"));
            std::fs::write(&path, &input).unwrap();
            let why = panic
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_default();
            panic!(
                "fuzz target {name} broke a promise on {}: {why}",
                path.display()
            );
        }
    }
    n
}

#[test]
fn every_fuzz_target_keeps_its_promises_on_its_corpus_and_mutations() {
    let cases: usize = std::env::var("MOTORBENCH_FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(1000);
    for (name, target) in TARGETS {
        let seeds = corpus(name);
        assert!(!seeds.is_empty(), "fuzz/corpus/{name} is empty");
        let ran = run(name, *target, seeds.clone().into_iter());
        assert_eq!(ran, seeds.len());
        let mut rng = StdRng::seed_from_u64(0x5eed_f022 ^ name.len() as u64);
        // The MCAP seed is 110 KB: fewer rounds keep its share of the run
        // like the others'.
        let rounds = if *name == "mcap_record" {
            cases / 10
        } else {
            cases
        };
        let mutations = (0..rounds).map(|k| mutate(&mut rng, &seeds[k % seeds.len()], &seeds));
        let ran = run(name, *target, mutations);
        eprintln!("{name}: {} corpus inputs, {ran} mutations", seeds.len());
    }
}

#[test]
fn a_broken_promise_is_caught_and_its_input_kept() {
    fn broken(data: &[u8]) {
        assert!(data.len() < 3, "too long");
    }
    let caught = catch_unwind(|| run("self_test", broken, [vec![1, 2, 3]].into_iter()));
    assert!(caught.is_err());
    let kept = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/fuzz-failures/self_test-1");
    assert_eq!(std::fs::read(&kept).unwrap(), vec![1, 2, 3]);
}
