//! What Tangent's field companions share — the `tangent` CLI (`listen`, `log`) and the
//! browser field app (`app/`, compiled to WebAssembly): one implementation of
//!
//! * the field log: its records and lines ([`record`]), reading a damaged log ([`scan`]) and
//!   the exports inventory software imports ([`export`]);
//! * the order of readings on the link: each once, gaps recovered from the device's history
//!   ([`seq`]);
//! * the plot tally ([`tally`]) and the quality flags in words ([`advice`]).
//!
//! No file, clock or port: the callers bring the bytes and the time, so this builds for
//! `wasm32-unknown-unknown` as for the host.

pub mod advice;
pub mod export;
pub mod record;
pub mod scan;
pub mod seq;
pub mod tally;

pub use export::{
    export, export_records, plots, ExportFormat, ExportPlot, NoSuchPlot, TREE_COLUMNS,
};
pub use record::{
    board_device_id, decode_line, encode_line, flag_names, reading_line, select_plot, Filing,
    PlotHeader, Record, TreeRecord, MAGIC_LINE,
};
pub use scan::{
    is_foreign, scan, DamageKind, DamagedSpan, Duplicate, HeaderlessPlot, Located, Scan, Tolerated,
};
