//! A plot's tally: per species, how many trees, their mean and quadratic mean diameter and
//! their basal area.
//!
//! A tree is counted once, with its **last** reading in the plot: a re-measure (a reading
//! filed again under the tree's number) supersedes the earlier ones, and a held trigger's
//! readings, all filed under one number, count as its last. Quadratic mean diameter
//! `Dq = √(Σd²/n)` (the diameter of the tree of mean basal area), basal area
//! `G = Σ π d²/4` in m² (`docs/field-app.md`).

use serde::Serialize;

use crate::record::{Record, TreeRecord};

/// The tally of one species (or of the whole plot).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SpeciesTally {
    /// Species code (empty: no species given; `"all"` in [`PlotTally::total`]).
    pub species: String,
    /// Trees.
    pub count: u32,
    /// Arithmetic mean diameter (mm).
    pub mean_mm: f64,
    /// Quadratic mean diameter (mm).
    pub quadratic_mean_mm: f64,
    /// Basal area (m²).
    pub basal_area_m2: f64,
}

/// The tally of one plot.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PlotTally {
    /// Plot id.
    pub plot_id: String,
    /// Per species, in order of first appearance.
    pub species: Vec<SpeciesTally>,
    /// All trees.
    pub total: SpeciesTally,
}

/// The trees of plot `plot_id` with the reading that counts for each (its last), in order
/// of tree number.
pub fn trees_of<'a>(records: &'a [Record], plot_id: &str) -> Vec<&'a TreeRecord> {
    let mut out: Vec<&TreeRecord> = Vec::new();
    for r in records {
        if let Record::Tree(t) = r {
            if t.plot_id != plot_id {
                continue;
            }
            match out.iter_mut().find(|k| k.tree_id == t.tree_id) {
                Some(k) => *k = t,
                None => out.push(t),
            }
        }
    }
    out.sort_by_key(|t| t.tree_id);
    out
}

fn tally_of(species: &str, diameters_mm: &[f64]) -> SpeciesTally {
    let n = diameters_mm.len();
    let (sum, sum_sq) = diameters_mm
        .iter()
        .fold((0.0, 0.0), |(s, q), d| (s + d, q + d * d));
    let (mean_mm, quadratic_mean_mm) = if n == 0 {
        (0.0, 0.0)
    } else {
        (sum / n as f64, (sum_sq / n as f64).sqrt())
    };
    SpeciesTally {
        species: species.to_string(),
        count: n as u32,
        mean_mm,
        quadratic_mean_mm,
        basal_area_m2: core::f64::consts::PI / 4.0 * sum_sq * 1e-6,
    }
}

/// The tally of plot `plot_id`.
pub fn tally(records: &[Record], plot_id: &str) -> PlotTally {
    let trees = trees_of(records, plot_id);
    let mut order: Vec<&str> = Vec::new();
    for t in &trees {
        if !order.contains(&t.species.as_str()) {
            order.push(&t.species);
        }
    }
    let species = order
        .iter()
        .map(|s| {
            let d: Vec<f64> = trees
                .iter()
                .filter(|t| t.species == *s)
                .map(|t| t.diameter_mm)
                .collect();
            tally_of(s, &d)
        })
        .collect();
    let all: Vec<f64> = trees.iter().map(|t| t.diameter_mm).collect();
    PlotTally {
        plot_id: plot_id.to_string(),
        species,
        total: tally_of("all", &all),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tree(id: u32, species: &str, d: f64) -> Record {
        Record::Tree(TreeRecord {
            plot_id: "P1".into(),
            tree_id: id,
            species: species.into(),
            diameter_mm: d,
            uncertainty_mm: 1.0,
            tilt_deg: 0.0,
            flags: 0,
            time: String::new(),
            device_id: "emulated".into(),
            calib_id: 1,
            seq: id,
            device_time_ms: 0,
            kind: "stem".into(),
            measurement: None,
            label: String::new(),
        })
    }

    #[test]
    fn last_reading_counts_and_sums_are_right() {
        let records = vec![
            tree(1, "PIAB", 300.0),
            tree(2, "PIAB", 400.0),
            tree(3, "FASY", 200.0),
            // Tree 1 re-measured.
            tree(1, "PIAB", 320.0),
        ];
        let t = tally(&records, "P1");
        assert_eq!(t.species.len(), 2);
        let piab = &t.species[0];
        assert_eq!((piab.species.as_str(), piab.count), ("PIAB", 2));
        assert!((piab.mean_mm - 360.0).abs() < 1e-9);
        let dq = ((320.0f64 * 320.0 + 400.0 * 400.0) / 2.0).sqrt();
        assert!((piab.quadratic_mean_mm - dq).abs() < 1e-9);
        let g = std::f64::consts::PI / 4.0 * (0.32f64 * 0.32 + 0.4 * 0.4);
        assert!((piab.basal_area_m2 - g).abs() < 1e-12);
        assert_eq!(t.total.count, 3);
        assert_eq!(tally(&records, "P2").total.count, 0);
    }
}
