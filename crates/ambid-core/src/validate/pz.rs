//! Pole-zero analysis of discrete models (work in progress).
