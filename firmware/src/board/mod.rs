//! Board support: one module per board, selected by cargo feature.

#[cfg(feature = "h743")]
pub mod h743;
#[cfg(feature = "qemu")]
pub mod qemu;
