//! # formats
//!
//! Readers and writers that turn files into `volume-core` types.
