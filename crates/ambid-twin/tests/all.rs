//! Every integration test of `ambid-twin` in one binary: one link instead of 17, and libtest
//! runs the tests of all files side by side. Each file is a module, so one file's tests run with
//! `cargo test -p ambid-twin --test all <file>::` (e.g. `--test all batch::`).

mod batch;
mod common;
mod design_comparison;
mod errors;
mod exp_rk4;
mod machine;
mod machine_defaults_rigs;
mod machine_mimo_frf;
mod machine_mimo_noise;
mod machine_mimo_numpy;
mod machine_scheduled;
mod machine_unbalance;
mod machine_validation;
mod machine_zipper;
mod oracle;
mod robustness;
mod simulation;
mod truth;
