//! The wall instrument's readings for people and scripts (`tangent measure` on a capture of
//! mode `wall`), and their truth from a simulated capture (`docs/building.md`, "Readings" and
//! "Truth of a simulated room").
//!
//! Degrees and millimetres here, at the user's edge; the core's SI values underneath.

use serde::Serialize;
use tangent_core::calibration::Calibration;
use tangent_core::instrument::wall::WallMeasurement;
use tangent_core::laser_plane::LaserPlane;
use tangent_core::protocol::codes;
use tangent_core::solvers::plane_pca::{orientation, Estimate};
use tangent_core::solvers::walls::{EndKind, WallSolution};

use crate::capture::Capture;
use crate::truth::{Object, TruthPoint};

type Vec3d = nalgebra::Vector3<f64>;

/// A value and its 1σ, in the unit its key names.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ValueSigma {
    /// The value.
    pub value: f64,
    /// Its 1σ.
    pub sigma: f64,
}

impl ValueSigma {
    fn deg(e: Estimate) -> Self {
        ValueSigma {
            value: e.value.to_degrees(),
            sigma: e.sigma.to_degrees(),
        }
    }
    fn mm(e: Estimate) -> Self {
        ValueSigma {
            value: e.value * 1e3,
            sigma: e.sigma * 1e3,
        }
    }
}

/// One wall as reported. The aimed wall's σ include the calibration's errors
/// (`docs/building.md`, (B10)); another wall's are its fit's alone.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct WallFace {
    /// Distance along the optical axis to the wall's plane (mm).
    pub axis_distance_mm: ValueSigma,
    /// Turn about the camera's vertical axis (degrees; positive: right part nearer).
    pub yaw_deg: ValueSigma,
    /// Tilt about the camera's horizontal axis (degrees; positive: lower part nearer).
    pub pitch_deg: ValueSigma,
    /// Quality index `1 − λ₃/λ₂` of the principal-component fit.
    pub quality: f64,
    /// Rms distance of the points from the plane (mm).
    pub rms_mm: f64,
    /// Points fitted.
    pub points: usize,
    /// The laser lines (plane indices) that lit it.
    pub lines: Vec<usize>,
}

/// The corner between two walls.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CornerReport {
    /// The two walls (indices into `walls`).
    pub walls: (usize, usize),
    /// Angle between them (degrees; 90 for a square corner).
    pub angle_deg: ValueSigma,
    /// The corner points towards the instrument (a pillar's edge).
    pub convex: bool,
}

/// A segment of the aimed wall along a laser line.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SegmentReport {
    /// The laser line (plane index).
    pub line: usize,
    /// Length between its ends (mm); a lower bound when not `bounded`.
    pub length_mm: ValueSigma,
    /// How each end was found: `corner`, `edge` or `frame_side`.
    pub ends: [&'static str; 2],
    /// Both ends are corners or edges.
    pub bounded: bool,
}

/// What the wall instrument reports for one capture.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct WallReport {
    /// The walls found, most points first.
    pub walls: Vec<WallFace>,
    /// The wall at the image centre (index into `walls`).
    pub aimed: usize,
    /// The corner between the two largest non-parallel walls.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub corner: Option<CornerReport>,
    /// Distance between the two largest parallel walls (mm).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub parallel_mm: Option<ValueSigma>,
    /// The aimed wall's segment.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub segment: Option<SegmentReport>,
    /// The aimed wall's deviation from the plumb (degrees).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub plumb_deg: Option<ValueSigma>,
    /// How the laser planes were calibrated: `board` (each plane on its own board poses; the
    /// readings' σ carry the board's budget, `docs/building.md` (B10)) or `refined` (against
    /// each other on a reference, `tangent calibrate wall`: `docs/calibration.md` §13–14).
    pub planes_calibration: &'static str,
    /// The truth, for a simulated capture.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub truth: Option<WallTruth>,
}

/// [`WallReport::planes_calibration`] of a calibration.
pub fn planes_calibration(calibration: &Calibration) -> &'static str {
    match calibration.uncertainty {
        Some(_) => "refined",
        None => "board",
    }
}

fn end_name(k: EndKind) -> &'static str {
    match k {
        EndKind::Corner => "corner",
        EndKind::Edge => "edge",
        EndKind::FrameSide => "frame_side",
        EndKind::Occluded => "occluded",
    }
}

impl WallReport {
    /// The report of a solution measured with `calibration` (`truth`: from [`wall_truth`]).
    pub fn of(s: &WallSolution, calibration: &Calibration, truth: Option<WallTruth>) -> Self {
        let walls = s
            .walls
            .iter()
            .enumerate()
            .filter_map(|(i, w)| {
                // The aimed wall's orientation is the solution's, whose σ carry the
                // calibration's errors (`docs/building.md`, (B10)); the other walls' are
                // their fits' own.
                let o = if i == s.aimed {
                    s.orientation
                } else {
                    orientation(&w.plane)?
                };
                Some(WallFace {
                    axis_distance_mm: ValueSigma::mm(o.axis_distance),
                    yaw_deg: ValueSigma::deg(o.yaw),
                    pitch_deg: ValueSigma::deg(o.pitch),
                    quality: w.plane.quality,
                    rms_mm: w.plane.rms * 1e3,
                    points: w.plane.points,
                    lines: (0..8).filter(|k| w.lines & (1 << k) != 0).collect(),
                })
            })
            .collect();
        WallReport {
            walls,
            aimed: s.aimed,
            corner: s.corner.map(|c| CornerReport {
                walls: c.walls,
                angle_deg: ValueSigma::deg(c.angle),
                convex: c.convex,
            }),
            parallel_mm: s.parallel.map(ValueSigma::mm),
            segment: s.segment.map(|g| SegmentReport {
                line: g.curve,
                length_mm: ValueSigma::mm(g.length),
                ends: g.kinds.map(end_name),
                bounded: g.bounded(),
            }),
            plumb_deg: s.plumb.map(ValueSigma::deg),
            planes_calibration: planes_calibration(calibration),
            truth,
        }
    }

    /// One line for people: the aimed wall, then each reading with its σ.
    pub fn summary(&self, flags: &[&str]) -> String {
        let mut s = match self.walls.get(self.aimed) {
            Some(w) => format!(
                "wall at {:.1} mm ± {:.1} mm, yaw {:+.2}° ± {:.2}°, pitch {:+.2}° ± {:.2}° (quality {:.3}, rms {:.2} mm)",
                w.axis_distance_mm.value,
                w.axis_distance_mm.sigma,
                w.yaw_deg.value,
                w.yaw_deg.sigma,
                w.pitch_deg.value,
                w.pitch_deg.sigma,
                w.quality,
                w.rms_mm
            ),
            None => "no wall".to_string(),
        };
        if self.walls.len() > 1 {
            s += &format!(", {} walls", self.walls.len());
        }
        if let Some(c) = &self.corner {
            s += &format!(
                "; corner {:.2}° ± {:.2}°{}",
                c.angle_deg.value,
                c.angle_deg.sigma,
                if c.convex { " (convex)" } else { "" }
            );
        }
        if let Some(p) = self.parallel_mm {
            s += &format!(
                "; parallel walls {:.1} mm ± {:.1} mm apart",
                p.value, p.sigma
            );
        }
        if let Some(g) = &self.segment {
            s += &format!(
                "; segment {}{:.1} mm ± {:.1} mm ({} to {})",
                if g.bounded { "" } else { "≥ " },
                g.length_mm.value,
                g.length_mm.sigma,
                g.ends[0],
                g.ends[1]
            );
        }
        if let Some(p) = self.plumb_deg {
            s += &format!("; plumb {:+.2}° ± {:.2}°", p.value, p.sigma);
        }
        if !flags.is_empty() {
            s += &format!(" [{}]", flags.join(", "));
        }
        if let Some(t) = &self.truth {
            s += &format!(" (truth: {})", t.summary());
        }
        s
    }
}

/// The flags of a wall measurement, named.
pub fn flag_names(m: &WallMeasurement) -> Vec<&'static str> {
    codes::flag_names(m.solution.flags).collect()
}

/// The true values of a simulated room, for the walls the instrument found.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct WallTruth {
    /// The aimed wall's true axis distance (mm), yaw and pitch (degrees).
    pub axis_distance_mm: Option<f64>,
    /// True yaw of the aimed wall (degrees).
    pub yaw_deg: Option<f64>,
    /// True pitch of the aimed wall (degrees).
    pub pitch_deg: Option<f64>,
    /// True corner angle (degrees).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub corner_deg: Option<f64>,
    /// True distance between the parallel walls (mm).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub parallel_mm: Option<f64>,
    /// True length of the segment (mm), when both its ends are in view.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub segment_mm: Option<f64>,
    /// True deviation of the aimed wall from the plumb (degrees), when the capture records
    /// the true gravity.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub plumb_deg: Option<f64>,
}

impl WallTruth {
    fn summary(&self) -> String {
        let mut parts = Vec::new();
        if let Some(z) = self.axis_distance_mm {
            parts.push(format!("{z:.1} mm"));
        }
        if let (Some(y), Some(p)) = (self.yaw_deg, self.pitch_deg) {
            parts.push(format!("yaw {y:+.2}°, pitch {p:+.2}°"));
        }
        if let Some(c) = self.corner_deg {
            parts.push(format!("corner {c:.2}°"));
        }
        if let Some(d) = self.parallel_mm {
            parts.push(format!("parallel {d:.1} mm"));
        }
        if let Some(l) = self.segment_mm {
            parts.push(format!("segment {l:.1} mm"));
        }
        if let Some(p) = self.plumb_deg {
            parts.push(format!("plumb {p:+.2}°"));
        }
        parts.join(", ")
    }
}

/// A truth plane: unit normal away from the camera and offset.
#[derive(Debug, Clone, Copy)]
struct TruePlane {
    n: Vec3d,
    d: f64,
    bounds: Option<[[f64; 3]; 2]>,
}

fn true_planes(capture: &Capture) -> Vec<Option<TruePlane>> {
    let Some(truth) = &capture.meta.truth else {
        return Vec::new();
    };
    truth
        .objects
        .iter()
        .map(|o| match o {
            Object::Plane(p) => {
                let mut n = Vec3d::from(p.normal).try_normalize(1e-12)?;
                let mut d = n.dot(&Vec3d::from(p.point_m));
                if d < 0.0 {
                    n = -n;
                    d = -d;
                }
                Some(TruePlane {
                    n,
                    d,
                    bounds: p.bounds_m,
                })
            }
            Object::Board(b) => {
                // The board's face: normal x × y through its origin (unbounded here: the
                // matching only needs its plane).
                let x = Vec3d::from(b.x_axis);
                let mut n = x.cross(&Vec3d::from(b.y_axis)).try_normalize(1e-12)?;
                let mut d = n.dot(&Vec3d::from(b.origin_m));
                if d < 0.0 {
                    n = -n;
                    d = -d;
                }
                Some(TruePlane { n, d, bounds: None })
            }
            _ => None,
        })
        .collect()
}

/// The truth plane a fitted wall lies on: the one nearest its centroid, within 20 mm and 5°
/// (a wall cut by a door is two truth pieces of one plane: either will do).
fn match_plane(planes: &[Option<TruePlane>], n: Vec3d, c: Vec3d) -> Option<usize> {
    planes
        .iter()
        .enumerate()
        .filter_map(|(i, p)| {
            let p = p.as_ref()?;
            let dist = (p.n.dot(&c) - p.d).abs();
            (dist < 0.02 && p.n.dot(&n) > 5f64.to_radians().cos()).then_some((i, dist))
        })
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(i, _)| i)
}

fn vec3(v: tangent_core::real::Vec3) -> Vec3d {
    Vec3d::new(v.x, v.y, v.z)
}

/// The truth of `capture` for the walls of `s` (`None` without truth objects).
pub fn wall_truth(capture: &Capture, s: &WallSolution) -> Option<WallTruth> {
    let planes = true_planes(capture);
    if planes.iter().all(Option::is_none) && capture.truth_curve.is_none() {
        return None;
    }
    let matched: Vec<Option<usize>> = s
        .walls
        .iter()
        .map(|w| match_plane(&planes, vec3(w.plane.normal), vec3(w.plane.centroid)))
        .collect();
    let plane_of = |w: usize| matched.get(w).copied().flatten().and_then(|i| planes[i]);
    let aimed = plane_of(s.aimed);
    let orient = aimed.map(|p| {
        let h = (p.n.x * p.n.x + p.n.z * p.n.z).sqrt();
        (
            p.d / p.n.z * 1e3,
            p.n.x.atan2(p.n.z).to_degrees(),
            p.n.y.atan2(h).to_degrees(),
        )
    });
    let corner_deg = s.corner.and_then(|c| {
        let (a, b) = (plane_of(c.walls.0)?, plane_of(c.walls.1)?);
        Some(180.0 - a.n.dot(&b.n).clamp(-1.0, 1.0).acos().to_degrees())
    });
    let parallel_mm = s.parallel.and_then(|_| {
        // The two largest parallel walls, as the solver chose them.
        let n = s.walls.len();
        let (a, b) = (0..n)
            .flat_map(|a| (a + 1..n).map(move |b| (a, b)))
            .find(|&(a, b)| {
                let (pa, pb) = (&s.walls[a].plane, &s.walls[b].plane);
                tangent_core::solvers::plane_pca::normal_angle(pa, pb).value
                    <= tangent_core::solvers::walls::WallParams::default().parallel_max
            })?;
        let (pa, pb) = (plane_of(a)?, plane_of(b)?);
        Some((pa.d - pb.d * pa.n.dot(&pb.n)).abs() * 1e3)
    });
    let segment_mm = s.segment.filter(|g| g.bounded()).and_then(|g| {
        let curve = capture.truth_curve.as_ref()?;
        let object = matched.get(s.aimed).copied().flatten()?;
        // Only a wall's (a board's printed squares cut its line where the wall's would go on).
        let truth = capture.meta.truth.as_ref()?;
        if !matches!(truth.objects.get(object), Some(Object::Plane(_))) {
            return None;
        }
        let laser = capture.calibration.planes.get(g.curve)?;
        true_segment(
            curve,
            &planes,
            object,
            g.curve,
            laser,
            vec3(g.ends[0]),
            vec3(g.ends[1]),
        )
        .map(|l| l * 1e3)
    });
    // As the solver's plumb: asin(n·ĝ), n away from the camera, ĝ down.
    let plumb_deg = s.plumb.and_then(|_| {
        let g = Vec3d::from(capture.meta.truth.as_ref()?.gravity?).try_normalize(1e-12)?;
        Some(aimed?.n.dot(&g).clamp(-1.0, 1.0).asin().to_degrees())
    });
    Some(WallTruth {
        axis_distance_mm: orient.map(|o| o.0),
        yaw_deg: orient.map(|o| o.1),
        pitch_deg: orient.map(|o| o.2),
        corner_deg,
        parallel_mm,
        segment_mm,
        plumb_deg,
    })
}

/// The true length of the run of `object` on laser line `line` between the measured ends:
/// each end where the line meets the plane of the object beyond the run (a jamb, the next
/// wall), or, when that object is no plane meeting the line there, where the run's last
/// truth point is. Clutter in front of the wall (and its shadow) does not end the run.
fn true_segment(
    curve: &[TruthPoint],
    planes: &[Option<TruePlane>],
    object: usize,
    line: usize,
    laser: &LaserPlane,
    end0: Vec3d,
    end1: Vec3d,
) -> Option<f64> {
    let pts: Vec<&TruthPoint> = curve.iter().filter(|p| p.plane == line).collect();
    let wall = planes.get(object).copied().flatten()?;
    let ln = vec3(laser.normal);
    let dir = wall.n.cross(&ln).try_normalize(1e-12)?;
    let mid = (end0 + end1) / 2.0;
    // The run of `object` containing the column nearest the measured segment's middle.
    let centre = pts
        .iter()
        .enumerate()
        .filter(|(_, p)| p.object == object)
        .min_by(|a, b| {
            let da = (Vec3d::from(a.1.point_m) - mid).norm();
            let db = (Vec3d::from(b.1.point_m) - mid).norm();
            da.total_cmp(&db)
        })?
        .0;
    // Outwards from there to the last point of `object` before another plane: a cable in
    // front (another object that is no plane) and its shadow (columns with no truth point)
    // interrupt the line but not the wall's segment, as they do not the instrument's.
    let is_plane = |o: usize| planes.get(o).copied().flatten().is_some();
    let stops = |i: usize| pts[i].object != object && is_plane(pts[i].object);
    let (mut lo, mut i) = (centre, centre);
    while i > 0 && !stops(i - 1) {
        i -= 1;
        if pts[i].object == object {
            lo = i;
        }
    }
    let (mut hi, mut i) = (centre, centre);
    while i + 1 < pts.len() && !stops(i + 1) {
        i += 1;
        if pts[i].object == object {
            hi = i;
        }
    }
    let end = |inner: usize, outer: Option<usize>| -> Vec3d {
        let p_in = Vec3d::from(pts[inner].point_m);
        outer
            .and_then(|o| {
                let other = planes.get(pts[o].object).copied().flatten()?;
                let along = dir.dot(&other.n);
                if along.abs() < 1e-3 {
                    return None;
                }
                let t = (other.d - other.n.dot(&p_in)) / along;
                let p = p_in + dir * t;
                // Only a meeting within two columns' worth of the run's end.
                ((p - p_in).norm() < 4e-3 * p_in.z).then_some(p)
            })
            .or_else(|| {
                // The wall's own edge: where the line leaves its bounding box.
                let [lo, hi] = wall.bounds?;
                (0..3)
                    .flat_map(|k| [(k, lo[k]), (k, hi[k])])
                    .filter(|&(k, _)| dir[k].abs() > 1e-9)
                    .map(|(k, at)| p_in + dir * ((at - p_in[k]) / dir[k]))
                    .filter(|p| (p - p_in).norm() < 4e-3 * p_in.z)
                    .min_by(|a, b| (a - p_in).norm().total_cmp(&(b - p_in).norm()))
            })
            .unwrap_or(p_in)
    };
    let a = end(lo, lo.checked_sub(1));
    let b = end(hi, Some(hi + 1).filter(|&i| i < pts.len()));
    Some((b - a).norm())
}
