//! Every integration test of `ambid-core` in one binary: one link instead of 35, and libtest
//! runs the tests of all files side by side. Each file is a module, so one file's tests run with
//! `cargo test -p ambid-core --test all <file>::` (e.g. `--test all data_preprocessing::`).

mod common;
mod data_preprocessing;
mod estimate_arx;
mod estimate_ballbeam;
mod estimate_order;
mod estimate_pem;
mod estimate_ss_pem;
mod estimate_ss_pem_mimo;
mod estimate_subspace;
mod frd_matrix;
mod freqfit_real;
mod freqfit_sml;
mod freqfit_ss;
mod freqfit_tf;
mod freqfit_unstable;
mod frf_bla;
mod frf_lpm;
mod frf_lrm;
mod frf_stepped_sine;
mod frf_welch;
mod iodata_contract;
mod linalg_dare;
mod lti_fixtures;
mod lti_freqresp;
mod lti_pid;
mod lti_properties;
mod mimo_frf;
mod mimo_frf_fixture;
mod mimo_frf_real;
mod mimo_frf_threads;
#[path = "common/mimo_loop.rs"]
mod mimo_loop;
mod mimo_lpm;
mod signal_multi;
mod signal_prbs;
mod signal_spec;
mod signal_waveforms;
#[path = "../../ambid/tests/common/skip.rs"]
mod skip;
mod structure;
mod validate_cancelling;
mod validate_pz;
mod validate_residuals;
