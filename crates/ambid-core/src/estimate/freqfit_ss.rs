//! State-space models fitted to frequency-response data (work in progress).
