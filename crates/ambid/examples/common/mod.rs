//! What the rig-sweep examples share.

/// The rigs (or seeds) of a command-line argument: `A-B` (inclusive) or `a,b,c`.
pub fn range(s: &str) -> Vec<u64> {
    match s.split_once('-') {
        Some((a, b)) => (a.parse().expect("a number")..=b.parse().expect("a number")).collect(),
        None => s.split(',').map(|x| x.parse().expect("a number")).collect(),
    }
}
