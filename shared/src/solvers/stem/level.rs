//! The one-plane section of a vertical stem (`docs/cylinder.md`, "One plane: the level
//! section"). The laser plane is tilted by `δ` from the horizontal (it crosses the optical axis
//! at the working distance), so it cuts a vertical stem in an ellipse whose axis along the
//! plane's slope is `R/cos δ`: a circle fitted in the plane reads the front's curvature
//! `R·cos δ` (−0.22 % at δ = 3.8°). With one plane the stem's lean is unknown and the caliper is
//! held level, so the section the solver fits is the plane's points projected along the
//! camera's vertical axis onto the horizontal plane through the source: the linear map
//! `q ↦ M·q`, `M = [[a_x, b_x], [a_z, b_z]]` of the in-plane coordinates (`a`, `b` the plane's
//! axes), where a vertical stem's section is the circle of radius `R`.

#[allow(unused_imports)]
use crate::real::Float;
use crate::real::{Real, Vec2};

use crate::laser_plane::LaserPlane;

/// The map from a plane's in-plane coordinates to the level section and back.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct LevelMap {
    m: [[Real; 2]; 2],
    inv: [[Real; 2]; 2],
}

impl LevelMap {
    /// The map of `plane`; the identity for a plane too steep to project (|det M| < 0.5, a
    /// plane tilted by more than 60°: no caliper geometry).
    pub(super) fn of(plane: &LaserPlane) -> Self {
        let (a, b) = plane.plane_axes();
        let m = [[a.x, b.x], [a.z, b.z]];
        let det = m[0][0] * m[1][1] - m[0][1] * m[1][0];
        if !(det.abs() >= 0.5) {
            let id = [[1.0, 0.0], [0.0, 1.0]];
            return LevelMap { m: id, inv: id };
        }
        let inv = [
            [m[1][1] / det, -m[0][1] / det],
            [-m[1][0] / det, m[0][0] / det],
        ];
        LevelMap { m, inv }
    }

    /// In-plane coordinates (or an in-plane vector) to the level section.
    pub(super) fn to_level(self, q: Vec2) -> Vec2 {
        let m = &self.m;
        Vec2::new(m[0][0] * q.x + m[0][1] * q.y, m[1][0] * q.x + m[1][1] * q.y)
    }

    /// Level-section coordinates back to the plane's.
    pub(super) fn to_plane(self, p: Vec2) -> Vec2 {
        let m = &self.inv;
        Vec2::new(m[0][0] * p.x + m[0][1] * p.y, m[1][0] * p.x + m[1][1] * p.y)
    }
}
