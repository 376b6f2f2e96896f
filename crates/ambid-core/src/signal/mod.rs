//! Excitation signals (PRBS, chirp, noise, multisine) and their analysis.
