//! Exports of the field log in the layouts inventory software imports.

use serde::Serialize;

use crate::record::flag_names;
use tangent_core::protocol::codes;
use tangent_core::solvers::result::Flags;

use crate::record::{Record, TreeRecord};

/// Export formats.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ExportFormat {
    /// Comma-separated.
    Csv,
    /// Tab-separated (Field-Map and Haglöf imports).
    Tsv,
    /// JSON: plots with their trees.
    Json,
}

/// The tree-level columns of the CSV/TSV exports, in order (`kind` and `label`, last so that
/// the column numbers importers are set up with stay: what each row measured — `stem`,
/// `sphere`, `wall`, …; `dbh_mm` is then that reading's value — and the user's label of it).
pub const TREE_COLUMNS: [&str; 13] = [
    "tree_id",
    "species",
    "dbh_mm",
    "uncertainty_mm",
    "tilt_deg",
    "flags",
    "time",
    "device_id",
    "calib_id",
    "seq",
    "plot_id",
    "kind",
    "label",
];

/// A plot with its trees, as exported.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ExportPlot<'a> {
    /// Plot id.
    pub plot_id: &'a str,
    /// When it was started (empty when its header was lost).
    pub started: &'a str,
    /// Note.
    pub note: &'a str,
    /// True when no header of this plot could be read: the plot is known from its trees.
    pub header_lost: bool,
    /// The trees, in recording order.
    pub trees: Vec<&'a TreeRecord>,
}

/// Groups records into plots (a plot id that appears in several headers is one plot, at
/// its first header), in order of first appearance. Trees whose plot has no header (it was
/// damaged) form a plot of their own `plot_id`, marked [`ExportPlot::header_lost`].
pub fn plots(records: &[Record]) -> Vec<ExportPlot<'_>> {
    let mut out: Vec<ExportPlot> = Vec::new();
    for r in records {
        let (plot_id, header) = match r {
            Record::Plot(p) => (&p.plot_id, Some(p)),
            Record::Tree(t) => (&t.plot_id, None),
        };
        let index = match out.iter().position(|e| e.plot_id == plot_id) {
            Some(i) => i,
            None => {
                out.push(ExportPlot {
                    plot_id,
                    started: "",
                    note: "",
                    header_lost: true,
                    trees: Vec::new(),
                });
                out.len() - 1
            }
        };
        let plot = &mut out[index];
        match (header, r) {
            (Some(h), _) if plot.header_lost => {
                plot.started = &h.started;
                plot.note = &h.note;
                plot.header_lost = false;
            }
            (_, Record::Tree(t)) => plot.trees.push(t),
            _ => {}
        }
    }
    out
}

fn field(value: &str, sep: char) -> String {
    // RFC 4180 quoting for CSV; TSV fields cannot hold tabs or newlines, so they become
    // spaces there.
    if sep == '\t' {
        return value.replace(['\t', '\n', '\r'], " ");
    }
    if value.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", value.replace('"', "\"\""))
    } else {
        value.to_string()
    }
}

/// Exports the log.
///
/// CSV/TSV follow the two-level layout of caliper software (Haglöf Versio "header" and
/// "data" levels; Field-Map's "lines to skip" before the tree columns): for each plot, a
/// header block of `key<sep>value` lines (`plot_id`, `started`, `note`, `trees`), a blank
/// line, the tree column names ([`TREE_COLUMNS`]) and one row per tree; plots are separated
/// by a blank line. Diameters and uncertainties in mm to 0.1 mm, tilt in degrees to 0.1°,
/// flags as names joined by `+`. JSON is `{"format":"tangent-field-log","version":1,
/// "plots":[{plot_id, started, note, trees:[{...TreeRecord, flag_names}]}]}`, with
/// `"header_lost": true` on a plot known only from its trees.
pub fn export(records: &[Record], format: ExportFormat) -> String {
    let plots = plots(records);
    match format {
        ExportFormat::Json => export_json(&plots),
        ExportFormat::Csv => export_table(&plots, ','),
        ExportFormat::Tsv => export_table(&plots, '\t'),
    }
}

fn export_table(plots: &[ExportPlot], sep: char) -> String {
    let mut out = String::new();
    for (i, p) in plots.iter().enumerate() {
        if i > 0 {
            out.push('\n');
        }
        let s = sep;
        out += &format!("plot_id{s}{}\n", field(p.plot_id, s));
        out += &format!("started{s}{}\n", field(p.started, s));
        out += &format!("note{s}{}\n", field(p.note, s));
        out += &format!("trees{s}{}\n\n", p.trees.len());
        out += &TREE_COLUMNS.join(&sep.to_string());
        out.push('\n');
        for t in &p.trees {
            let row = [
                t.tree_id.to_string(),
                field(&t.species, s),
                format!("{:.1}", t.diameter_mm),
                format!("{:.1}", t.uncertainty_mm),
                format!("{:.1}", t.tilt_deg),
                flag_names(t.flags),
                field(&t.time, s),
                field(&t.device_id, s),
                t.calib_id.to_string(),
                t.seq.to_string(),
                field(&t.plot_id, s),
                field(&t.kind, s),
                field(&t.label, s),
            ];
            out += &row.join(&sep.to_string());
            out.push('\n');
        }
    }
    out
}

fn export_json(plots: &[ExportPlot]) -> String {
    let plots: Vec<serde_json::Value> = plots
        .iter()
        .map(|p| {
            let trees: Vec<serde_json::Value> = p
                .trees
                .iter()
                .map(|t| {
                    let mut v = serde_json::to_value(t).unwrap_or_default();
                    if let Some(obj) = v.as_object_mut() {
                        let names: Vec<String> = codes::flag_names(Flags(t.flags))
                            .map(str::to_ascii_uppercase)
                            .collect();
                        obj.insert("flag_names".into(), names.into());
                    }
                    v
                })
                .collect();
            let mut plot = serde_json::json!({
                "plot_id": p.plot_id,
                "started": p.started,
                "note": p.note,
                "trees": trees,
            });
            if p.header_lost {
                plot["header_lost"] = true.into();
            }
            plot
        })
        .collect();
    let doc = serde_json::json!({
        "format": "tangent-field-log",
        "version": 1,
        "plots": plots,
    });
    let mut s = serde_json::to_string_pretty(&doc).unwrap_or_default();
    s.push('\n');
    s
}

/// The plot asked for is not in the log.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NoSuchPlot(pub String);

impl std::fmt::Display for NoSuchPlot {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "no plot {}", self.0)
    }
}

impl std::error::Error for NoSuchPlot {}

/// What `tangent log export` writes for the records read from a log: every plot, or only
/// `plot_id`'s.
pub fn export_records(
    records: &[Record],
    plot_id: Option<&str>,
    format: ExportFormat,
) -> Result<String, NoSuchPlot> {
    match plot_id {
        None => Ok(export(records, format)),
        Some(id) => {
            let selected = crate::record::select_plot(records, id);
            if selected.is_empty() {
                return Err(NoSuchPlot(id.to_string()));
            }
            Ok(export(&selected, format))
        }
    }
}
