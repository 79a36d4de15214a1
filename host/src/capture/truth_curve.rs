//! The truth-curve CSV of a synthetic capture (`docs/formats.md` §3): the exact laser rows
//! the simulator renders, read and written.

use super::{CaptureError, TRUTH_CURVE_HEADER};
use crate::truth::TruthPoint;

/// Parses the truth-curve CSV (`docs/formats.md`). `file` names it in errors.
pub fn parse_truth_curve(text: &str, file: &str) -> Result<Vec<TruthPoint>, CaptureError> {
    let err = |line: usize, message: String| CaptureError::TruthCurve {
        file: file.to_string(),
        line,
        message,
    };
    let mut lines = text.lines().enumerate();
    match lines.next() {
        Some((_, h)) if h.trim() == TRUTH_CURVE_HEADER => {}
        _ => return Err(err(1, format!("the header must be `{TRUTH_CURVE_HEADER}`"))),
    }
    let mut out = Vec::new();
    for (i, line) in lines {
        let n = i + 1;
        if line.trim().is_empty() {
            continue;
        }
        let f: Vec<&str> = line.split(',').map(str::trim).collect();
        if f.len() != 7 {
            return Err(err(n, format!("expected 7 fields, found {}", f.len())));
        }
        let num = |k: usize| -> Result<f64, CaptureError> {
            f[k].parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| {
                    err(
                        n,
                        format!("field {} ({:?}) is not a finite number", k + 1, f[k]),
                    )
                })
        };
        let int = |k: usize| -> Result<usize, CaptureError> {
            f[k].parse::<usize>()
                .map_err(|_| err(n, format!("field {} ({:?}) is not an index", k + 1, f[k])))
        };
        out.push(TruthPoint {
            plane: int(0)?,
            column: u32::try_from(int(1)?).map_err(|_| err(n, "column too large".into()))?,
            row_px: num(2)?,
            point_m: [num(3)?, num(4)?, num(5)?],
            object: int(6)?,
        });
    }
    Ok(out)
}

/// Formats the truth-curve CSV. Rows to 1e-6 px and points to 1e-9 m: far below any
/// estimator's resolution (0.01 px) and any object tolerance (0.1 mm), so the rounding is
/// not part of any test budget.
pub fn format_truth_curve(points: &[TruthPoint]) -> String {
    let mut s = String::with_capacity(points.len() * 48 + 64);
    s.push_str(TRUTH_CURVE_HEADER);
    s.push('\n');
    for p in points {
        s.push_str(&format!(
            "{},{},{:.6},{:.9},{:.9},{:.9},{}\n",
            p.plane, p.column, p.row_px, p.point_m[0], p.point_m[1], p.point_m[2], p.object
        ));
    }
    s
}
