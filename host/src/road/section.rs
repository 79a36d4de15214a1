//! Ambulatory use (`docs/road.md`, "Ambulatory use"): profile after profile along a road
//! section, the MSD of every 100 mm segment kept, the section's MPD as their running mean,
//! and profiles the standard excludes (too many drop-outs or spikes, a gap) counted apart —
//! never averaged in.

use std::collections::BTreeMap;

use serde::Serialize;
use tangent_core::instrument::road::RoadSolution;
use tangent_core::pipeline::PipelineError;
use tangent_core::solvers::mpd::estimated_texture_depth;
use tangent_core::solvers::road_profile::RoadError;

/// One road section being measured.
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct Section {
    /// Location label (e.g. "A7 km 12.4 left wheel path").
    pub label: String,
    /// MSD of every valid segment so far (metres).
    pub msd_m: Vec<f64>,
    /// Profiles taken.
    pub profiles: usize,
    /// Profiles excluded by the standard's rules (drop-outs, gaps, spikes), by reason.
    pub excluded: BTreeMap<&'static str, usize>,
    /// Profiles that gave no profile at all (no light, tilted, out of range …), by reason.
    pub failed: BTreeMap<&'static str, usize>,
}

/// Where a profile went.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Added {
    /// Its valid segments joined the section (how many).
    Segments(usize),
    /// Excluded by the standard (the reason's name).
    Excluded(&'static str),
    /// No profile (the reason's name).
    Failed(&'static str),
}

impl Section {
    /// An empty section.
    pub fn new(label: &str) -> Self {
        Section {
            label: label.to_string(),
            ..Section::default()
        }
    }

    /// Adds one profile's result.
    pub fn add(&mut self, result: &Result<RoadSolution, PipelineError>) -> Added {
        self.profiles += 1;
        let added = match result {
            Ok(s) => {
                let valid: Vec<f64> = s.segments[..s.depth.segments.min(s.segments.len())]
                    .iter()
                    .filter(|g| g.valid)
                    .map(|g| g.msd)
                    .collect();
                self.msd_m.extend(&valid);
                Added::Segments(valid.len())
            }
            Err(PipelineError::Road(e)) => match e {
                RoadError::TooManyDropouts { .. } => Added::Excluded("drop-outs"),
                RoadError::DropoutGap { .. } => Added::Excluded("gap (wet patch or hole)"),
                RoadError::TooManySpikes { .. } => Added::Excluded("spikes"),
                RoadError::Tilted { .. } => Added::Failed("head tilted"),
                RoadError::OutOfRange { .. } => Added::Failed("out of range"),
                _ => Added::Failed("no profile"),
            },
            Err(_) => Added::Failed("no laser line"),
        };
        match added {
            Added::Excluded(r) => *self.excluded.entry(r).or_default() += 1,
            Added::Failed(r) => *self.failed.entry(r).or_default() += 1,
            Added::Segments(_) => {}
        }
        added
    }

    /// Valid segments so far (the running count).
    pub fn segments(&self) -> usize {
        self.msd_m.len()
    }

    /// The section's MPD (metres): the mean MSD of its valid segments; `None` before the
    /// first.
    pub fn mpd(&self) -> Option<f64> {
        (!self.msd_m.is_empty()).then(|| self.msd_m.iter().sum::<f64>() / self.msd_m.len() as f64)
    }

    /// Standard deviation of the segments' MSD (metres), from two segments.
    pub fn msd_std(&self) -> Option<f64> {
        let n = self.msd_m.len();
        let m = self.mpd()?;
        (n >= 2).then(|| {
            (self.msd_m.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / (n - 1) as f64).sqrt()
        })
    }

    /// Profiles excluded or failed.
    pub fn not_used(&self) -> usize {
        self.excluded.values().sum::<usize>() + self.failed.values().sum::<usize>()
    }

    /// The counts behind the MPD: `14 profiles, 2 excluded (drop-outs 1, spikes 1), 1 failed
    /// (head tilted 1)`.
    pub fn tally(&self) -> String {
        let list = |m: &BTreeMap<&'static str, usize>, what: &str| {
            let n: usize = m.values().sum();
            if n == 0 {
                return format!("0 {what}");
            }
            let items: Vec<String> = m.iter().map(|(r, k)| format!("{r} {k}")).collect();
            format!("{n} {what} ({})", items.join(", "))
        };
        format!(
            "{} profiles, {}, {}",
            self.profiles,
            list(&self.excluded, "excluded"),
            list(&self.failed, "failed")
        )
    }

    /// One line: label, MPD, ETD, counts.
    pub fn summary(&self) -> String {
        let mut s = match self.mpd() {
            Some(m) => format!(
                "section {}: MPD = {:.3} mm (ETD {:.3} mm) from {} segments",
                self.label,
                m * 1e3,
                estimated_texture_depth(m) * 1e3,
                self.segments()
            ),
            None => format!("section {}: no valid segment yet", self.label),
        };
        if let Some(sd) = self.msd_std() {
            s += &format!(", MSD s.d. {:.3} mm", sd * 1e3);
        }
        s += &format!(", {} profiles", self.profiles);
        for (reason, n) in self.excluded.iter().chain(&self.failed) {
            s += &format!(", {n} excluded ({reason})");
        }
        s
    }
}

/// Kind of the field-log record of a section ([`crate::fieldlog::TreeRecord::kind`]).
pub const SECTION_KIND: &str = "road_section";

impl Section {
    /// Stores the section in the field log: a plot header named by its location label (if
    /// the log's current plot is another), then one record of kind [`SECTION_KIND`] filed
    /// under the label (and labelled with it), whose size column holds the section's MPD (mm), its uncertainty
    /// column the MSD's standard error (mm), its tree number the running count of valid
    /// segments, its sequence number the profiles taken and its note-like species column
    /// `MPD; ` and the [`Section::tally`] (the excluded and failed profiles by reason).
    /// Nothing is stored before the first valid segment.
    pub fn log_to(
        &self,
        log: &mut crate::fieldlog::FieldLog,
        calib_id: u32,
    ) -> Result<bool, crate::fieldlog::FieldLogError> {
        use crate::fieldlog::{now_rfc3339, PlotHeader, Record, TreeRecord};
        let Some(mpd) = self.mpd() else {
            return Ok(false);
        };
        if log.current_plot().map(|p| p.plot_id.as_str()) != Some(self.label.as_str()) {
            log.append(Record::Plot(PlotHeader {
                plot_id: self.label.clone(),
                started: now_rfc3339(),
                note: "road section (ISO 13473-1 MPD)".into(),
            }))?;
        }
        let n = self.segments();
        let standard_error = self.msd_std().map_or(0.0, |s| s / (n as f64).sqrt());
        log.append(Record::Tree(TreeRecord {
            plot_id: self.label.clone(),
            tree_id: n as u32,
            species: format!("MPD; {}", self.tally()),
            diameter_mm: mpd * 1e3,
            uncertainty_mm: standard_error * 1e3,
            tilt_deg: 0.0,
            flags: 0,
            time: now_rfc3339(),
            device_id: "host".into(),
            calib_id,
            seq: self.profiles as u32,
            device_time_ms: 0,
            kind: SECTION_KIND.into(),
            measurement: None,
            label: self.label.clone(),
        }))?;
        Ok(true)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tangent_core::instrument::road::{RoadSolution, MAX_SEGMENTS};
    use tangent_core::solvers::mpd::{MeanProfileDepth, SegmentDepth};
    use tangent_core::solvers::road_profile::ProfileSummary;

    fn solution(msd: f64) -> RoadSolution {
        let mut segments = [SegmentDepth::default(); MAX_SEGMENTS];
        segments[0] = SegmentDepth {
            msd,
            valid: true,
            ..SegmentDepth::default()
        };
        RoadSolution {
            profile: ProfileSummary {
                samples: 667,
                dropouts: 0,
                spacing: 0.15e-3,
                mean_height: 0.0,
                tilt: 0.0,
                longest_gap: (0.0, 0.0),
            },
            depth: MeanProfileDepth {
                segments: 1,
                valid_segments: 1,
                mpd: msd,
                etd: estimated_texture_depth(msd),
                resampled: 200,
                spikes: 0,
            },
            segments,
            rms_height: 0.0,
            micro: None,
            standoff: 0.3,
            uncertainty: 5e-6,
            flags: Default::default(),
        }
    }

    #[test]
    fn excluded_profiles_are_counted_never_averaged() {
        let mut s = Section::new("test strip");
        assert_eq!(s.mpd(), None);
        assert_eq!(s.add(&Ok(solution(1.0e-3))), Added::Segments(1));
        assert_eq!(s.add(&Ok(solution(1.2e-3))), Added::Segments(1));
        let dropouts = Err(PipelineError::Road(RoadError::TooManyDropouts {
            fraction: 0.3,
            dropouts: 200,
            runs: 180,
            span: (-0.05, 0.05),
        }));
        assert_eq!(s.add(&dropouts), Added::Excluded("drop-outs"));
        let tilted = Err(PipelineError::Road(RoadError::Tilted { angle: 0.2 }));
        assert_eq!(s.add(&tilted), Added::Failed("head tilted"));
        assert!((s.mpd().unwrap() - 1.1e-3).abs() < 1e-12);
        assert_eq!((s.profiles, s.segments(), s.not_used()), (4, 2, 2));
        assert_eq!(
            s.tally(),
            "4 profiles, 1 excluded (drop-outs 1), 1 failed (head tilted 1)"
        );
        let line = s.summary();
        assert!(
            line.contains("MPD = 1.100 mm") && line.contains("1 excluded (drop-outs)"),
            "{line}"
        );
    }

    #[test]
    fn the_field_log_stores_the_section_under_its_label_with_its_exclusions() {
        use crate::fieldlog::{FieldLog, Record};
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("road.log");
        let mut s = Section::new("A7 km 12.4 left wheel path");
        let mut log = FieldLog::open(&path).unwrap();
        // Nothing before the first valid segment.
        s.add(&Err(PipelineError::Road(RoadError::TooManySpikes {
            fraction: 0.08,
        })));
        assert!(!s.log_to(&mut log, 12).unwrap());
        s.add(&Ok(solution(0.8e-3)));
        s.add(&Ok(solution(1.0e-3)));
        assert!(s.log_to(&mut log, 12).unwrap());
        drop(log);
        let records = FieldLog::read(&path).unwrap();
        let plot = records.iter().find_map(|r| match r {
            Record::Plot(p) => Some(p),
            _ => None,
        });
        assert_eq!(plot.unwrap().plot_id, "A7 km 12.4 left wheel path");
        let row = records
            .iter()
            .find_map(|r| match r {
                Record::Tree(t) => Some(t),
                _ => None,
            })
            .unwrap();
        assert_eq!(row.plot_id, "A7 km 12.4 left wheel path");
        assert_eq!(row.kind, SECTION_KIND);
        assert!((row.diameter_mm - 0.9).abs() < 1e-9, "{}", row.diameter_mm);
        assert_eq!((row.tree_id, row.seq), (2, 3));
        assert_eq!(
            row.species,
            "MPD; 3 profiles, 1 excluded (spikes 1), 0 failed"
        );
    }
}
