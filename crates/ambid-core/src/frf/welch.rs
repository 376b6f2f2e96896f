//! (temporary interface stub; replaced by the Welch implementation)
#![allow(missing_docs, dead_code)]
use faer::c64;
#[derive(Debug, Clone)]
pub struct CrossSpectra {
    f_hz: Vec<f64>,
    s: Vec<Vec<c64>>,
    n: usize,
    fs: f64,
}
impl CrossSpectra {
    pub fn n_channels(&self) -> usize {
        self.n
    }
    pub fn f_hz(&self) -> &[f64] {
        &self.f_hz
    }
    pub fn get(&self, i: usize, j: usize) -> &[c64] {
        &self.s[i * self.n + j]
    }
    pub fn fs(&self) -> f64 {
        self.fs
    }
    pub fn effective_averages(&self) -> f64 {
        1.0
    }
    pub fn n_segments(&self) -> usize {
        1
    }
}
