//! The recorded-capture corpus of Tangent (`tests/captures/`, described in
//! `tests/README.md`).
//!
//! This package exists so that the tests replaying the corpus live beside it and still
//! belong to a package of their own (cargo attaches `corpus.rs` here, not to `tangent-host`
//! through a `../` path); the library only says where the captures are.
#![deny(missing_docs)]

use std::path::PathBuf;

/// The corpus directory: one sub-directory per capture (`docs/formats.md`).
pub fn captures() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("captures")
}
