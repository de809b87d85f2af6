//! # data-samples
//!
//! Generators for synthetic datasets.
