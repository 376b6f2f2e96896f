//! The embedded AMB digital twin (under construction).
