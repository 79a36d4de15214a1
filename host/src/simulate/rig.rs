//! What every corpus shares: the entry type and the reference rigs (calibrations and
//! indoor light). The stem corpus and the instrument corpora (sphere, wall, road) build on
//! these, so none of them imports another.

use tangent_core::calibration::Calibration;

use super::render::Lighting;
use super::SimSpec;

/// One corpus capture: directory name and spec.
#[derive(Debug, Clone)]
pub struct CorpusEntry {
    /// Directory name under `tests/captures/`.
    pub name: String,
    /// What it renders.
    pub spec: SimSpec,
}

/// The reference design with only its first plane (a one-laser caliper), id 1.
pub fn one_plane_calibration() -> Calibration {
    let mut c = Calibration::reference_design();
    c.planes.truncate(1);
    c.id = 1;
    c
}

/// The two-plane reference design (tilted-stem variant), id 2.
pub fn two_plane_calibration() -> Calibration {
    let mut c = Calibration::reference_design();
    c.id = 2;
    c
}

/// The wall head (`docs/building.md`, "The crossing line"): the two-plane reference design
/// and the third, crossing plane ([`tangent_core::calibration::reference_crossing_plane`]) as
/// plane 2, id 3.
pub fn three_plane_calibration() -> Calibration {
    let mut c = Calibration::reference_design();
    if let Ok(p) = tangent_core::calibration::reference_crossing_plane() {
        let _ = c.planes.push(p);
    }
    c.id = 3;
    c
}

/// Indoor light for calibration: 2 W/m² diffuse in band, so the board is well exposed in
/// the laser-off frame while the 1 mW stripe (≈ 0.9 W/m² at 1 m) still stands out on the
/// light squares.
pub fn lab_light() -> Lighting {
    Lighting {
        diffuse_w_m2: 2.0,
        sun_w_m2: 0.0,
        sun_direction: [0.0, -1.0, 0.0],
        background_w_m2: 0.3,
    }
}
