//! Every random seed of a workflow run, derived in one place from the workflow's seed.

use serde::Serialize;

/// The seeds of every experiment and study of one workflow run, each the workflow seed `s` plus
/// a fixed offset (the offsets `ambid run` has always used, so the numbers do not move):
///
/// | what | seed |
/// |---|---|
/// | excitation comparison, amplitude study, identification excitation | `s` |
/// | validation excitation (random phases / noise) | `s + 7` |
/// | operating-point study | `s + 100` |
/// | identification record (twin noise) | `s + 200` |
/// | validation record (twin noise) | `s + 300` |
/// | noise-only record (output SNR) | `s + 400` |
/// | robust BLA study | `s + 600` |
///
/// Each stage draws its random numbers from a `ChaCha8Rng` seeded with its own seed, so the
/// stages can run in any order and in parallel with the same results.
///
/// ```
/// use ambid::stage::Seeds;
/// let s = Seeds::from_workflow_seed(42);
/// assert_eq!((s.identification_record, s.validation_record, s.noise_record), (242, 342, 442));
/// assert_eq!((s.validation_excitation, s.operating_point, s.bla), (49, 142, 642));
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct Seeds {
    /// The workflow's seed.
    pub workflow: u64,
    /// The four-signal excitation comparison.
    pub comparison: u64,
    /// The amplitude study on the twin.
    pub amplitude: u64,
    /// The identification excitation (random kinds).
    pub identification_excitation: u64,
    /// The validation excitation (random kinds).
    pub validation_excitation: u64,
    /// The operating-point study.
    pub operating_point: u64,
    /// The twin's noise in the identification record.
    pub identification_record: u64,
    /// The twin's noise in the validation record.
    pub validation_record: u64,
    /// The twin's record without excitation.
    pub noise_record: u64,
    /// The robust BLA study.
    pub bla: u64,
}

impl Seeds {
    /// The seeds of a run with workflow seed `seed`.
    pub fn from_workflow_seed(seed: u64) -> Self {
        Self {
            workflow: seed,
            comparison: seed,
            amplitude: seed,
            identification_excitation: seed,
            validation_excitation: seed.wrapping_add(7),
            operating_point: seed.wrapping_add(100),
            identification_record: seed.wrapping_add(200),
            validation_record: seed.wrapping_add(300),
            noise_record: seed.wrapping_add(400),
            bla: seed.wrapping_add(600),
        }
    }
}
