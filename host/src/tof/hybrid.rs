//! Hybrid reconstruction (in progress).
