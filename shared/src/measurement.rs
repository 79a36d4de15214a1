//! One reading of any of Tangent's instruments: what the pipeline returns, the wire protocol
//! sends, the host prints and the field log keeps (`docs/architecture.md`, "Module map" and "Adding an instrument").
//!
//! Each instrument (stem today; sphere, wall and road next) is one [`Mode`] of the same head
//! and one variant of [`Measurement`]. The values are SI (metres, radians) and computed in
//! [`Real`]; on the wire every scalar travels as `f32`, whatever the build's precision, so
//! that the device (f32) and the host (f64) speak the same bytes.

use serde::{Deserialize, Serialize};

use crate::real::Real;
use crate::solvers::result::{Flags, Method};

/// The instrument a capture was taken for, or the device is set to: the capture file's
/// `mode` key.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Mode {
    /// A stem: a cylinder, possibly tilted or elliptic (thesis chapter 9).
    Cylinder,
    /// A sphere (thesis chapter 10).
    Sphere,
    /// One or more walls: planes (thesis chapter 11).
    Wall,
    /// A road-surface profile (thesis chapter 12).
    Road,
}

impl Mode {
    /// Every mode, in the order of their wire numbers.
    pub const ALL: [Mode; 4] = [Mode::Cylinder, Mode::Sphere, Mode::Wall, Mode::Road];

    /// The mode of a [`Mode::name`], `None` for any other word.
    pub fn from_name(name: &str) -> Option<Mode> {
        Mode::ALL.into_iter().find(|m| m.name() == name)
    }

    /// The name used in capture files, on the command line and in logs.
    pub fn name(self) -> &'static str {
        match self {
            Mode::Cylinder => "cylinder",
            Mode::Sphere => "sphere",
            Mode::Wall => "wall",
            Mode::Road => "road",
        }
    }
}

/// One reading of one instrument.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum Measurement {
    /// A stem diameter ([`Mode::Cylinder`]).
    Stem(StemReading),
    /// A sphere's diameter and centre ([`Mode::Sphere`]).
    Sphere(SphereReading),
    /// A road profile's texture ([`Mode::Road`]).
    Road(RoadReading),
    /// Walls: orientation, corner, parallel distance, segment ([`Mode::Wall`]).
    Wall(WallReading),
}

impl Measurement {
    /// The instrument that made the reading.
    pub fn mode(&self) -> Mode {
        match self {
            Measurement::Stem(_) => Mode::Cylinder,
            Measurement::Sphere(_) => Mode::Sphere,
            Measurement::Road(_) => Mode::Road,
            Measurement::Wall(_) => Mode::Wall,
        }
    }

    /// Quality flags of the reading (solver and image flags).
    pub fn flags(&self) -> Flags {
        match self {
            Measurement::Stem(s) => s.flags,
            Measurement::Sphere(s) => s.flags,
            Measurement::Road(r) => r.flags,
            Measurement::Wall(w) => w.flags,
        }
    }

    /// The method that produced the reading's value.
    pub fn method(&self) -> Method {
        match self {
            Measurement::Stem(s) => s.method,
            Measurement::Sphere(s) => s.method,
            Measurement::Road(_) => Method::MeanProfileDepth,
            Measurement::Wall(w) => w.method,
        }
    }

    /// What the reading is of, as logs and exports name it: `"stem"`, `"sphere"`, …
    pub fn kind(&self) -> &'static str {
        match self {
            Measurement::Stem(_) => "stem",
            Measurement::Sphere(_) => "sphere",
            Measurement::Road(_) => "road",
            Measurement::Wall(_) => "wall",
        }
    }

    /// The reading's headline number (metres): what running statistics average and the
    /// field log's size column keeps — a stem's or a sphere's diameter, a road's mean profile
    /// depth, a wall's distance on the optical axis.
    pub fn value(&self) -> Real {
        match self {
            Measurement::Stem(s) => s.diameter,
            Measurement::Sphere(s) => s.diameter,
            Measurement::Road(r) => r.mpd,
            Measurement::Wall(w) => w.distance,
        }
    }

    /// Predicted 1σ of [`Measurement::value`] (metres).
    pub fn uncertainty(&self) -> Real {
        match self {
            Measurement::Stem(s) => s.uncertainty,
            Measurement::Sphere(s) => s.uncertainty,
            Measurement::Road(r) => r.uncertainty,
            Measurement::Wall(w) => w.distance_sigma,
        }
    }
}

/// A stem's diameter and what qualifies it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct StemReading {
    /// Diameter (metres).
    #[serde(with = "wire_real")]
    pub diameter: Real,
    /// Predicted 1σ uncertainty of the diameter (metres).
    #[serde(with = "wire_real")]
    pub uncertainty: Real,
    /// The computation the diameter comes from.
    pub method: Method,
    /// Distance from the source of plane 0 to the stem's nearest point (metres).
    #[serde(with = "wire_real")]
    pub distance: Real,
    /// The stem's lean, when two planes measured it.
    pub tilt: Option<TiltAngles>,
    /// Major and minor diameters (metres) of a section found elliptic ([`Flags::ELLIPTIC`]).
    pub axes: Option<Axes>,
    /// Quality flags (solver and image).
    pub flags: Flags,
    /// Exposures (frame pairs) the reading combines (`docs/error-model.md` §6, (E7)); 1 in
    /// readings recorded before there were several (protocol version 7).
    #[serde(default = "one_exposure")]
    pub exposures: u8,
}

/// What a reading recorded without [`StemReading::exposures`] took: one frame pair.
fn one_exposure() -> u8 {
    1
}

/// A sphere's diameter, where it is, and what qualifies it (`docs/sphere.md`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SphereReading {
    /// Diameter (metres).
    #[serde(with = "wire_real")]
    pub diameter: Real,
    /// Predicted 1σ uncertainty of the diameter (metres).
    #[serde(with = "wire_real")]
    pub uncertainty: Real,
    /// The computation the diameter comes from (joint fit, sections, three-tangent).
    pub method: Method,
    /// The centre (camera frame, metres).
    pub centre: Point,
    /// Distance of the centre from the camera (metres).
    #[serde(with = "wire_real")]
    pub distance: Real,
    /// Quality flags (solver and image).
    pub flags: Flags,
}

/// A point in the camera frame (metres).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Point {
    /// Right.
    #[serde(with = "wire_real")]
    pub x: Real,
    /// Down.
    #[serde(with = "wire_real")]
    pub y: Real,
    /// Forward.
    #[serde(with = "wire_real")]
    pub z: Real,
}

/// A road profile's texture (`docs/road.md`): ISO 13473-1 depths, the profile's statistics
/// and the microtexture on its highest peak (metres, radians).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct RoadReading {
    /// Mean profile depth: the mean MSD of the profile's valid segments.
    #[serde(with = "wire_real")]
    pub mpd: Real,
    /// Predicted 1σ of the MPD from the profile's own noise.
    #[serde(with = "wire_real")]
    pub uncertainty: Real,
    /// Estimated texture depth `0.2 mm + 0.8·MPD`.
    #[serde(with = "wire_real")]
    pub etd: Real,
    /// RMS height of the filtered profile.
    #[serde(with = "wire_real")]
    pub rms_height: Real,
    /// Mean height relative to the head's stand-off (+ nearer).
    #[serde(with = "wire_real")]
    pub mean_height: Real,
    /// Tilt of the road against the head.
    #[serde(with = "wire_real")]
    pub tilt: Real,
    /// Drop-out share of the profile (0–1).
    #[serde(with = "wire_real")]
    pub dropout_fraction: Real,
    /// Valid 100 mm segments.
    pub segments: u8,
    /// Microtexture RMS height and peak curvature (1/m) on the highest peak.
    pub micro: Option<Micro>,
    /// Quality flags (image).
    pub flags: Flags,
}

/// Microtexture indicators on one macrotexture peak.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Micro {
    /// RMS height of the wavelengths below 0.5 mm (metres).
    #[serde(with = "wire_real")]
    pub rms_height: Real,
    /// Curvature of the peak's top (1/m).
    #[serde(with = "wire_real")]
    pub curvature: Real,
}

/// A stem's lean relative to plane 0 (`docs/cylinder.md`, "Tilt angles"), radians.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TiltAngles {
    /// Total angle between the stem axis and the plane normal.
    #[serde(with = "wire_real")]
    pub total: Real,
    /// Lean towards (+) or away from the instrument.
    #[serde(with = "wire_real")]
    pub theta: Real,
    /// Sideways lean.
    #[serde(with = "wire_real")]
    pub phi: Real,
}

/// The two diameters of an elliptic section (metres).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Axes {
    /// Major diameter.
    #[serde(with = "wire_real")]
    pub major: Real,
    /// Minor diameter.
    #[serde(with = "wire_real")]
    pub minor: Real,
}

/// The wall instrument's reading (`docs/building.md`): the aimed wall seen from the
/// instrument and what the capture's other walls add. Angles in radians, lengths in metres.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct WallReading {
    /// Walls found in the capture.
    pub walls: u8,
    /// The aimed wall's distance along the optical axis.
    #[serde(with = "wire_real")]
    pub distance: Real,
    /// Its 1σ.
    #[serde(with = "wire_real")]
    pub distance_sigma: Real,
    /// The aimed wall's turn about the camera's vertical axis (positive: right part nearer).
    pub yaw: ValueSigma,
    /// Its tilt about the camera's horizontal axis (positive: lower part nearer).
    pub pitch: ValueSigma,
    /// Quality index `1 − λ₃/λ₂` of its plane fit.
    #[serde(with = "wire_real")]
    pub quality: Real,
    /// Rms distance of its points from the plane.
    #[serde(with = "wire_real")]
    pub rms: Real,
    /// Angle between the two largest non-parallel walls (π/2 for a square corner).
    pub corner: Option<ValueSigma>,
    /// Distance between the two largest parallel walls.
    pub parallel: Option<ValueSigma>,
    /// Length of the aimed wall's segment along a laser line, and whether both its ends are
    /// edges or corners (otherwise a lower bound).
    pub segment: Option<(ValueSigma, bool)>,
    /// The aimed wall's deviation from the plumb, when the device knows the vertical.
    pub plumb: Option<ValueSigma>,
    /// The computation ([`Method::PlanePca`]).
    pub method: Method,
    /// Quality flags (solver and image).
    pub flags: Flags,
}

/// A value and its 1σ (metres or radians).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ValueSigma {
    /// The value.
    #[serde(with = "wire_real")]
    pub value: Real,
    /// Its 1σ.
    #[serde(with = "wire_real")]
    pub sigma: Real,
}

/// Serialises a [`Real`] as `f32` so the wire format does not depend on the build's
/// precision (the device computes in f32, the host in f64).
mod wire_real {
    use super::Real;
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(value: &Real, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_f32(*value as f32)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(deserializer: D) -> Result<Real, D::Error> {
        Ok(f32::deserialize(deserializer)? as Real)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stem() -> Measurement {
        Measurement::Stem(StemReading {
            diameter: 0.3001,
            uncertainty: 0.0012,
            method: Method::CircleFit,
            distance: 1.5,
            tilt: Some(TiltAngles {
                total: 0.2,
                theta: 0.1,
                phi: -0.17,
            }),
            axes: None,
            flags: Flags::TILT_IGNORED,
            exposures: 1,
        })
    }

    #[test]
    fn scalars_travel_as_f32() {
        let mut buf = [0u8; 64];
        let bytes = postcard::to_slice(&stem(), &mut buf).expect("fits");
        // Variant (1) + 3 f32 + method (1) + Some (1) + 3 f32 + None (1) + flags varint (1)
        // + exposures (1): 4 bytes per scalar whatever `Real` is.
        assert_eq!(bytes.len(), 1 + 12 + 1 + 1 + 12 + 1 + 1 + 1);
        let back: Measurement = postcard::from_bytes(bytes).expect("decodes");
        let Measurement::Stem(b) = back else {
            panic!("a stem came back as {back:?}")
        };
        assert_eq!(b.diameter, 0.3001f32 as Real);
        assert_eq!(b.method, Method::CircleFit);
        assert_eq!(back.mode(), Mode::Cylinder);
        assert_eq!(back.flags(), Flags::TILT_IGNORED);
        assert_eq!(b.exposures, 1);
    }

    /// A stem reading recorded before protocol version 7 (a field log's JSON without
    /// `exposures`) reads as one exposure.
    #[test]
    fn a_reading_without_exposures_reads_as_one() {
        let Measurement::Stem(s) = stem() else {
            unreachable!()
        };
        let recorded = StemReading { exposures: 4, ..s };
        let mut json = serde_json::to_value(Measurement::Stem(recorded)).expect("json");
        assert_eq!(json["Stem"]["exposures"], 4);
        json["Stem"]
            .as_object_mut()
            .expect("an object")
            .remove("exposures");
        let back: Measurement = serde_json::from_value(json).expect("an older reading decodes");
        let Measurement::Stem(b) = back else {
            panic!("{back:?}")
        };
        assert_eq!(b.exposures, 1);
    }

    #[test]
    fn a_wall_reading_travels_as_f32_and_names_itself() {
        let vs = |value: Real, sigma: Real| ValueSigma { value, sigma };
        let wall = Measurement::Wall(WallReading {
            walls: 2,
            distance: 2.0,
            distance_sigma: 1e-4,
            yaw: vs(0.78, 2e-4),
            pitch: vs(0.001, 2e-3),
            quality: 0.999,
            rms: 4e-4,
            corner: Some(vs(1.55, 3e-4)),
            parallel: None,
            segment: Some((vs(0.6, 6e-4), true)),
            plumb: None,
            method: Method::PlanePca,
            flags: Flags::default(),
        });
        let mut buf = [0u8; 128];
        let bytes = postcard::to_slice(&wall, &mut buf).expect("fits");
        // Variant + walls + 8 scalars + corner (1 + 8) + None + segment (1 + 8 + 1) + None
        // + method + flags.
        assert_eq!(bytes.len(), 1 + 1 + 32 + 9 + 1 + 10 + 1 + 1 + 1);
        let back: Measurement = postcard::from_bytes(bytes).expect("decodes");
        assert_eq!((back.mode(), back.kind()), (Mode::Wall, "wall"));
        assert_eq!(back.value(), 2.0);
        assert_eq!(back.method(), Method::PlanePca);
    }
}
