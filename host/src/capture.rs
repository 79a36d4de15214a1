//! Capture directories: `capture.toml` + PGM frames (+ ground truth for synthetic captures).
//!
//! A capture is what one trigger press records: a laser-off frame, one or more laser-on
//! frames, the metadata needed to interpret them (sensor, exposure, which lasers were lit,
//! the calibration) and, for synthetic or reference captures, the ground truth. The format is
//! specified for people writing captures by hand in `docs/formats.md`; this module is its
//! reader and writer. Every malformation is a specific [`CaptureError`].
//!
//! Errors name the files of a capture relative to its directory (`capture.toml`,
//! `frame on.pgm`, `calibration file ../unit.toml`); whoever chose the directory names it in
//! front, once (`tangent measure` prints `DIR: frame on.pgm: truncated PGM raster …`).

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use tangent_core::accelerometer;
use tangent_core::calibration::Calibration;

use crate::calibration_file::{self, CalibrationFileError};
use crate::pgm::{Pgm, PgmError};
use crate::truth::{Object, PhysicsModel, TruthPoint};

mod truth_curve;
pub use truth_curve::{format_truth_curve, parse_truth_curve};

/// The largest frame side a capture may declare (pixels). With [`MAX_FRAME_PIXELS`] this
/// bounds the memory reading (and inspecting) a capture takes; the sensor (MT9V034,
/// 752 × 480) is far below it (`docs/formats.md`, "Bounds").
pub const MAX_FRAME_SIDE: u32 = 4096;
/// The most pixels a capture's frames may have (4 Mpx, 8 MiB per 16-bit frame).
pub const MAX_FRAME_PIXELS: u64 = 4 * 1024 * 1024;

/// The `format_version` this reader understands.
pub const FORMAT_VERSION: u32 = 1;

/// Name of the metadata file inside a capture directory.
pub const META_FILE: &str = "capture.toml";

/// Header line of the truth-curve CSV.
pub const TRUTH_CURVE_HEADER: &str = "plane,column,row_px,x_m,y_m,z_m,object";

/// What the capture measures: its `mode` key selects the instrument (`tangent_core::instrument`).
pub use tangent_core::measurement::Mode;

/// One frame of the capture: its PGM file and the laser planes lit while it was exposed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FrameEntry {
    /// File name, relative to the capture directory (no directories, no `..`).
    pub file: String,
    /// Indices (into the calibration's planes) of the lasers that were on; `[]` for the
    /// laser-off (ambient) frame.
    pub lasers_on: Vec<usize>,
    /// The exposure pair the frame belongs to: 0, 1, … A capture taken while the trigger was
    /// held has several pairs, each with its own laser-off frame (`docs/formats.md` §3).
    #[serde(default, skip_serializing_if = "is_first_pair")]
    pub pair: usize,
}

fn is_first_pair(pair: &usize) -> bool {
    *pair == 0
}

/// Most exposure pairs one capture holds ([`tangent_core::solvers::stem::MAX_EXPOSURES`]:
/// a reading combines at most that many).
pub const MAX_PAIRS: usize = tangent_core::solvers::stem::MAX_EXPOSURES;

/// The `[truth]` table: the exact scene and the exact laser curves.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Truth {
    /// CSV file (relative to the capture directory) with the true laser-curve rows
    /// (header [`TRUTH_CURVE_HEADER`]); absent when not known.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub truth_curve: Option<String>,
    /// The objects of the scene, in the camera frame of the laser-on frame (metres).
    #[serde(default)]
    pub objects: Vec<Object>,
    /// The physics model a synthetic capture was rendered with (`docs/simulator.md`, §10).
    /// Absent: the reference model if the capture has a `[simulation]` table, else unknown.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub physics_model: Option<PhysicsModel>,
    /// The true direction of gravity in the camera frame (unit, pointing down), when the
    /// capture simulates an accelerometer.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gravity: Option<[f64; 3]>,
}

/// `capture.toml`, as written on disk.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CaptureMeta {
    /// Format version; must equal [`FORMAT_VERSION`].
    pub format_version: u32,
    /// Sensor name (free text, e.g. `"MT9V034"` or `"simulated MT9V034"`).
    pub sensor: String,
    /// Frame width (pixels).
    pub width: u32,
    /// Frame height (pixels).
    pub height: u32,
    /// Significant bits per sample; every PGM's maxval must be `2^bit_depth − 1`.
    pub bit_depth: u8,
    /// Exposure time of every frame (seconds).
    pub exposure_s: f64,
    /// Analogue gain (dimensionless, 1 = unity).
    pub gain: f64,
    /// What is measured.
    pub mode: Mode,
    /// When the capture was taken (TOML offset date-time, RFC 3339).
    pub timestamp: toml::value::Datetime,
    /// Free-text note (what the capture shows).
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub description: String,
    /// The frames: exactly one with `lasers_on = []`, at least one with lasers on.
    pub frames: Vec<FrameEntry>,
    /// The calibration: a path (relative to the capture directory) to a calibration TOML
    /// file, or the calibration inline as a table.
    pub calibration: toml::Value,
    /// Ground truth, for synthetic and reference captures.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub truth: Option<Truth>,
    /// The simulator's parameters for synthetic captures (`docs/simulator.md`); readers that
    /// are not the simulator ignore it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub simulation: Option<toml::Value>,
    /// The accelerometer's mean reading over the capture and the calibration it is taken
    /// with (`docs/building.md` §6); absent in captures of a device without one (and in
    /// every capture older than it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub accelerometer: Option<AccelerometerRecord>,
}

/// The `[accelerometer]` table: what the device records of gravity with each capture
/// (`docs/building.md` §6, `docs/formats.md`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AccelerometerRecord {
    /// Mean specific force over the capture along the sensor's axes (m/s²; at rest it
    /// points up).
    pub mean_m_s2: [f64; 3],
    /// Samples averaged.
    pub samples: u32,
    /// 1σ of one sample on each axis (m/s²; the sensor's noise).
    pub sample_sigma_m_s2: f64,
    /// The calibrated bias subtracted from the mean (sensor axes, m/s²).
    pub bias_m_s2: [f64; 3],
    /// 1σ of that bias on each axis (m/s²).
    pub bias_sigma_m_s2: f64,
    /// The calibrated rotation from the sensor's axes into the camera frame (rotation
    /// vector, radians).
    pub camera_from_sensor_rad: [f64; 3],
    /// 1σ of that rotation about each axis (radians).
    pub alignment_sigma_rad: f64,
}

impl AccelerometerRecord {
    /// Gravity in the camera frame (unit vector, pointing down) and the 1σ of its direction
    /// about any axis across it (radians): `ĝ = −R (a − b)/|a − b|`,
    /// `σ² = (σ_b² + σ_a²/N)/|a − b|² + σ_R²` (`docs/building.md`, eq. (B9)). `Err` names the
    /// field that makes it unusable.
    pub fn gravity_camera(&self) -> Result<([f64; 3], f64), String> {
        let (reading, alignment) = self.to_core();
        let v = accelerometer::vertical(&reading, &alignment).map_err(|e| e.to_string())?;
        Ok(([v.down.x, v.down.y, v.down.z], v.sigma_rad))
    }

    /// The record as the core's mean reading and alignment (the device's own types, so
    /// the host's gravity is computed as the device's: [`accelerometer::vertical`]).
    pub fn to_core(&self) -> (accelerometer::MeanReading, accelerometer::Alignment) {
        let v = |a: [f64; 3]| nalgebra::Vector3::new(a[0], a[1], a[2]);
        (
            accelerometer::MeanReading {
                mean_m_s2: v(self.mean_m_s2),
                samples: self.samples,
                sample_sigma_m_s2: self.sample_sigma_m_s2,
            },
            accelerometer::Alignment {
                bias_m_s2: v(self.bias_m_s2),
                bias_sigma_m_s2: self.bias_sigma_m_s2,
                camera_from_sensor_rad: v(self.camera_from_sensor_rad),
                alignment_sigma_rad: self.alignment_sigma_rad,
            },
        )
    }
}

/// Standard gravity (m/s²).
pub const STANDARD_GRAVITY: f64 = 9.806_65;

/// Why a capture could not be read or written. Files are named relative to the capture
/// directory, which the message does not repeat: the caller puts it in front.
#[derive(Debug, thiserror::Error)]
pub enum CaptureError {
    /// The capture directory does not exist.
    #[error("no such capture directory")]
    NoSuchDirectory,
    /// The path exists but is not a directory.
    #[error("not a directory (a capture is a directory holding {META_FILE})")]
    NotADirectory,
    /// A directory that is neither a capture nor holds any.
    #[error("neither a capture (no {META_FILE}) nor a directory of captures")]
    NoCaptures,
    /// The capture directory could not be listed or created (the caller names it).
    #[error("{0}")]
    Directory(std::io::Error),
    /// A file of the capture could not be read or written.
    #[error("{file}: {error}")]
    Io {
        /// The file, relative to the capture directory.
        file: String,
        /// The I/O error (named in the message, so not also a `source()`).
        error: std::io::Error,
    },
    /// `capture.toml` has a key the format does not define.
    #[error("capture.toml: unknown key `{key}`{}", at(.line))]
    UnknownKey {
        /// The key.
        key: String,
        /// 1-based line, when known.
        line: Option<usize>,
    },
    /// `capture.toml` lacks a required key.
    #[error("capture.toml: missing key `{key}`{}", at(.line))]
    MissingKey {
        /// The key.
        key: String,
        /// 1-based line of the enclosing table, when known.
        line: Option<usize>,
    },
    /// `capture.toml` is not valid TOML or a value has the wrong type.
    #[error("capture.toml{}: {message}", at(.line))]
    Syntax {
        /// The parser's message.
        message: String,
        /// 1-based line, when known.
        line: Option<usize>,
    },
    /// `format_version` is not [`FORMAT_VERSION`].
    #[error("capture format version {0} is not supported (this reader knows {FORMAT_VERSION})")]
    UnsupportedVersion(u32),
    /// A field has an impossible value (message says which).
    #[error("capture.toml: {0}")]
    InvalidField(String),
    /// The inline calibration (`[calibration]` table) is invalid.
    #[error("calibration: {0}")]
    Calibration(#[from] CalibrationFileError),
    /// The calibration file the capture refers to is invalid.
    #[error("calibration file {file}: {error}")]
    CalibrationFile {
        /// The file, as `capture.toml` names it (relative to the capture directory).
        file: String,
        /// What is wrong with it.
        error: CalibrationFileError,
    },
    /// A frame file is not a valid PGM (an I/O error on it is [`CaptureError::Io`]).
    #[error("frame {file}: {source}")]
    Pgm {
        /// The frame file.
        file: String,
        /// What is wrong with it.
        source: PgmError,
    },
    /// A frame's size differs from the `width × height` of `capture.toml`.
    #[error("frame {file} is {actual:?} pixels, capture.toml says {expected:?}")]
    FrameSizeMismatch {
        /// The frame file.
        file: String,
        /// `(width, height)` from `capture.toml`.
        expected: (u32, u32),
        /// `(width, height)` of the PGM.
        actual: (usize, usize),
    },
    /// The capture's frame size differs from the calibration's image size.
    #[error("frames are {frames:?} pixels but the calibration is for {calibration:?}")]
    CalibrationSizeMismatch {
        /// `(width, height)` of the frames.
        frames: (u32, u32),
        /// `(width, height)` of the calibration's camera.
        calibration: (u32, u32),
    },
    /// A frame's maxval is not `2^bit_depth − 1`.
    #[error("frame {file} has maxval {actual}, bit_depth {bit_depth} needs {expected}")]
    WrongMaxval {
        /// The frame file.
        file: String,
        /// Declared bit depth.
        bit_depth: u8,
        /// `2^bit_depth − 1`.
        expected: u32,
        /// The PGM's maxval.
        actual: u16,
    },
    /// No frame has `lasers_on = []`, or more than one has.
    #[error("a capture needs exactly one laser-off frame (lasers_on = []), found {0}")]
    OffFrameCount(usize),
    /// An exposure pair of a capture with several lacks its laser-off or its laser-on frame,
    /// or has two laser-off frames.
    #[error(
        "exposure pair {pair} needs exactly one laser-off frame (lasers_on = []) and at least \
         one laser-on frame, found {off} and {on}"
    )]
    PairFrames {
        /// The `pair` number.
        pair: usize,
        /// Its laser-off frames.
        off: usize,
        /// Its laser-on frames.
        on: usize,
    },
    /// No frame has a laser on.
    #[error("a capture needs at least one laser-on frame")]
    NoOnFrame,
    /// A frame lights a plane the calibration does not have.
    #[error("frame {file} lights laser plane {plane}, the calibration has {count}")]
    NoSuchPlane {
        /// The frame file.
        file: String,
        /// The plane index.
        plane: usize,
        /// Number of planes in the calibration.
        count: usize,
    },
    /// A file name is absolute, contains a directory or `..`.
    #[error("file name {0:?} must be a plain name inside the capture directory")]
    BadFileName(String),
    /// The truth-curve CSV is malformed.
    #[error("truth curve {file} line {line}: {message}")]
    TruthCurve {
        /// The CSV file.
        file: String,
        /// 1-based line.
        line: usize,
        /// What is wrong.
        message: String,
    },
}

fn at(line: &Option<usize>) -> String {
    line.map(|l| format!(" (line {l})")).unwrap_or_default()
}

/// A capture in memory.
#[derive(Debug, Clone)]
pub struct Capture {
    /// The metadata (`capture.toml`).
    pub meta: CaptureMeta,
    /// The calibration, resolved (inline or from its file) and validated.
    pub calibration: Calibration,
    /// The frames, in the order of `meta.frames`.
    pub frames: Vec<Pgm>,
    /// The true laser curve, when the capture has one.
    pub truth_curve: Option<Vec<TruthPoint>>,
    /// Why the truth curve that `capture.toml` names could not be read (its file and the
    /// cause); the capture is measured all the same.
    pub truth_curve_unreadable: Option<String>,
}

/// The capture directories `path` names: `path` itself when it holds [`META_FILE`], else
/// its sub-directories that do, sorted by name. The error says why `path` holds none.
pub fn find_captures(path: &Path) -> Result<Vec<PathBuf>, CaptureError> {
    check_directory(path)?;
    if path.join(META_FILE).is_file() {
        return Ok(vec![path.to_path_buf()]);
    }
    let entries = std::fs::read_dir(path).map_err(CaptureError::Directory)?;
    let mut captures: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.join(META_FILE).is_file())
        .collect();
    if captures.is_empty() {
        return Err(CaptureError::NoCaptures);
    }
    captures.sort();
    Ok(captures)
}

/// `dir` exists and is a directory (other failures surface when its files are read).
fn check_directory(dir: &Path) -> Result<(), CaptureError> {
    match std::fs::metadata(dir) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Err(CaptureError::NoSuchDirectory),
        Ok(m) if !m.is_dir() => Err(CaptureError::NotADirectory),
        _ => Ok(()),
    }
}

fn check_file_name(name: &str) -> Result<(), CaptureError> {
    let p = Path::new(name);
    let plain = !name.is_empty()
        && p.components().count() == 1
        && matches!(p.components().next(), Some(std::path::Component::Normal(_)));
    if plain {
        Ok(())
    } else {
        Err(CaptureError::BadFileName(name.to_string()))
    }
}

fn map_meta_error(err: &toml::de::Error, text: &str) -> CaptureError {
    match calibration_file::map_toml_error(err, text) {
        CalibrationFileError::UnknownKey { key, line } => CaptureError::UnknownKey { key, line },
        CalibrationFileError::MissingKey { key, line } => CaptureError::MissingKey { key, line },
        CalibrationFileError::Syntax { message, line } => CaptureError::Syntax { message, line },
        other => CaptureError::Syntax {
            message: other.to_string(),
            line: None,
        },
    }
}

impl CaptureMeta {
    /// Parses `capture.toml` text (syntax, keys and types only; [`Capture::read`] checks the
    /// rest against the frames and the calibration). Never panics.
    pub fn parse(text: &str) -> Result<Self, CaptureError> {
        let meta: CaptureMeta = toml::from_str(text).map_err(|e| map_meta_error(&e, text))?;
        if meta.format_version != FORMAT_VERSION {
            return Err(CaptureError::UnsupportedVersion(meta.format_version));
        }
        if !(1..=16).contains(&meta.bit_depth) {
            return Err(CaptureError::InvalidField(format!(
                "bit_depth {} is outside 1..=16",
                meta.bit_depth
            )));
        }
        if meta.width == 0 || meta.height == 0 {
            return Err(CaptureError::InvalidField(
                "width and height must be positive".into(),
            ));
        }
        if meta.width > MAX_FRAME_SIDE
            || meta.height > MAX_FRAME_SIDE
            || u64::from(meta.width) * u64::from(meta.height) > MAX_FRAME_PIXELS
        {
            return Err(CaptureError::InvalidField(format!(
                "frame size {}x{} exceeds the format's maximum ({MAX_FRAME_SIDE} px a side, \
                 {MAX_FRAME_PIXELS} px in all; the MT9V034 is 752x480)",
                meta.width, meta.height
            )));
        }
        if !(meta.exposure_s.is_finite() && meta.exposure_s > 0.0) {
            return Err(CaptureError::InvalidField(
                "exposure_s must be positive".into(),
            ));
        }
        if !(meta.gain.is_finite() && meta.gain > 0.0) {
            return Err(CaptureError::InvalidField("gain must be positive".into()));
        }
        let ts = &meta.timestamp;
        if ts.date.is_none() || ts.time.is_none() || ts.offset.is_none() {
            return Err(CaptureError::InvalidField(format!(
                "timestamp {ts} must be a full RFC 3339 date-time with offset (e.g. 2025-06-01T10:00:00Z)"
            )));
        }
        for f in &meta.frames {
            check_file_name(&f.file)?;
        }
        if let Some(name) = meta.truth.as_ref().and_then(|t| t.truth_curve.as_ref()) {
            check_file_name(name)?;
        }
        let pairs = meta.pairs();
        if pairs > MAX_PAIRS {
            return Err(CaptureError::InvalidField(format!(
                "frame pair {} is beyond the format's {MAX_PAIRS} exposure pairs (pair = 0 to {})",
                pairs - 1,
                MAX_PAIRS - 1
            )));
        }
        for pair in 0..pairs {
            let frames = || meta.frames.iter().filter(|f| f.pair == pair);
            let off = frames().filter(|f| f.lasers_on.is_empty()).count();
            let on = frames().count() - off;
            match (pairs, off, on) {
                (_, 1, 1..) => {}
                (1, 1, 0) => return Err(CaptureError::NoOnFrame),
                (1, _, _) => return Err(CaptureError::OffFrameCount(off)),
                _ => return Err(CaptureError::PairFrames { pair, off, on }),
            }
        }
        Ok(meta)
    }

    /// How many exposure pairs the frames form: one more than the highest `pair` (1 for a
    /// single trigger's pair).
    pub fn pairs(&self) -> usize {
        self.frames.iter().map(|f| f.pair + 1).max().unwrap_or(1)
    }

    /// The calibration this metadata names (inline table, or a file relative to `dir`).
    pub fn resolve_calibration(&self, dir: &Path) -> Result<Calibration, CaptureError> {
        match &self.calibration {
            toml::Value::String(name) => {
                // A calibration may live next to several captures, so `..` is allowed here.
                // Read here rather than by `calibration_file::read` so that the error names
                // the file as `capture.toml` does, relative to the capture.
                let text = read_text(dir, name)?;
                calibration_file::parse(&text).map_err(|error| CaptureError::CalibrationFile {
                    file: name.clone(),
                    error,
                })
            }
            toml::Value::Table(_) => Ok(calibration_file::from_value(self.calibration.clone())?),
            other => Err(CaptureError::InvalidField(format!(
                "calibration must be a file name or a table, not a {}",
                other.type_str()
            ))),
        }
    }
}

/// Largest text file a capture may have (`capture.toml`, a calibration, the truth curve):
/// far above any real one (a truth curve of 752 columns and four planes is ≈ 200 kB), so a
/// wrong file is refused before it is read whole.
pub const MAX_TEXT_FILE_BYTES: u64 = 16 << 20;

/// Reads the text file `name` of the capture in `dir`: a regular file (a FIFO or a device
/// would block the read) of at most [`MAX_TEXT_FILE_BYTES`]. Errors name the file.
fn read_text(dir: &Path, name: &str) -> Result<String, CaptureError> {
    use std::io::{Error, ErrorKind, Read};
    let path = dir.join(name);
    let fail = |error| CaptureError::Io {
        file: name.into(),
        error,
    };
    let meta = std::fs::metadata(&path).map_err(fail)?;
    if !meta.is_file() {
        return Err(fail(Error::new(
            ErrorKind::InvalidInput,
            "not a regular file",
        )));
    }
    if meta.len() > MAX_TEXT_FILE_BYTES {
        let msg = format!(
            "{} bytes, more than the {MAX_TEXT_FILE_BYTES} a capture's text file may have",
            meta.len()
        );
        return Err(fail(Error::new(ErrorKind::InvalidData, msg)));
    }
    let mut text = String::new();
    // `take`: the file may have grown since its size was read.
    std::fs::File::open(&path)
        .map_err(fail)?
        .take(MAX_TEXT_FILE_BYTES)
        .read_to_string(&mut text)
        .map_err(fail)?;
    Ok(text)
}

impl Capture {
    /// Reads and checks a capture directory.
    pub fn read(dir: &Path) -> Result<Self, CaptureError> {
        check_directory(dir)?;
        let text = read_text(dir, META_FILE)?;
        let meta = CaptureMeta::parse(&text)?;
        let calibration = meta.resolve_calibration(dir)?;
        let cam = (calibration.camera.width, calibration.camera.height);
        if cam != (meta.width, meta.height) {
            return Err(CaptureError::CalibrationSizeMismatch {
                frames: (meta.width, meta.height),
                calibration: cam,
            });
        }
        let count = calibration.planes.len();
        for f in &meta.frames {
            if let Some(&plane) = f.lasers_on.iter().find(|&&p| p >= count) {
                return Err(CaptureError::NoSuchPlane {
                    file: f.file.clone(),
                    plane,
                    count,
                });
            }
        }
        let expected_maxval = (1u32 << meta.bit_depth) - 1;
        let mut frames = Vec::with_capacity(meta.frames.len());
        for f in &meta.frames {
            // The header's size is checked before the raster is read: a frame takes at most
            // the memory `capture.toml` declares (itself bounded by `MAX_FRAME_PIXELS`).
            let pgm = Pgm::read_expecting(
                &dir.join(&f.file),
                meta.width as usize,
                meta.height as usize,
            )
            .map_err(|e| frame_error(&f.file, e))?;
            if pgm.maxval as u32 != expected_maxval {
                return Err(CaptureError::WrongMaxval {
                    file: f.file.clone(),
                    bit_depth: meta.bit_depth,
                    expected: expected_maxval,
                    actual: pgm.maxval,
                });
            }
            frames.push(pgm);
        }
        // The truth curve is optional ground truth: one that cannot be read is named, and the
        // capture is still measured without it.
        let (truth_curve, truth_curve_unreadable) =
            match meta.truth.as_ref().and_then(|t| t.truth_curve.as_ref()) {
                Some(name) => {
                    match read_text(dir, name).and_then(|text| parse_truth_curve(&text, name)) {
                        Ok(curve) => (Some(curve), None),
                        Err(e) => (None, Some(e.to_string())),
                    }
                }
                None => (None, None),
            };
        Ok(Capture {
            meta,
            calibration,
            frames,
            truth_curve,
            truth_curve_unreadable,
        })
    }

    /// Writes the capture into `dir` (created if needed): `capture.toml`, the frames, and
    /// the truth curve when present. An inline calibration is written from
    /// `self.calibration`; a calibration given by path is left where it is.
    pub fn write(&self, dir: &Path) -> Result<(), CaptureError> {
        std::fs::create_dir_all(dir).map_err(CaptureError::Directory)?;
        if self.frames.len() != self.meta.frames.len() {
            return Err(CaptureError::InvalidField(format!(
                "{} frames for {} frame entries",
                self.frames.len(),
                self.meta.frames.len()
            )));
        }
        for (entry, pgm) in self.meta.frames.iter().zip(&self.frames) {
            check_file_name(&entry.file)?;
            pgm.write(&dir.join(&entry.file))
                .map_err(|e| frame_error(&entry.file, e))?;
        }
        if let (Some(points), Some(name)) = (
            &self.truth_curve,
            self.meta
                .truth
                .as_ref()
                .and_then(|t| t.truth_curve.as_ref()),
        ) {
            check_file_name(name)?;
            std::fs::write(dir.join(name), format_truth_curve(points)).map_err(|error| {
                CaptureError::Io {
                    file: name.clone(),
                    error,
                }
            })?;
        }
        std::fs::write(dir.join(META_FILE), self.meta_text()?).map_err(|error| CaptureError::Io {
            file: META_FILE.into(),
            error,
        })
    }

    /// The `capture.toml` text [`Capture::write`] writes.
    pub fn meta_text(&self) -> Result<String, CaptureError> {
        let mut meta = self.meta.clone();
        if matches!(meta.calibration, toml::Value::Table(_)) {
            let c = calibration_file::CalibrationToml::from_calibration(&self.calibration);
            meta.calibration =
                toml::Value::try_from(c).map_err(|e| CaptureError::InvalidField(e.to_string()))?;
        }
        toml::to_string(&meta).map_err(|e| CaptureError::InvalidField(e.to_string()))
    }

    /// The laser-off frame (of the first exposure pair).
    pub fn off_frame(&self) -> &Pgm {
        // `CaptureMeta::parse` guarantees exactly one per pair; `position` cannot fail on
        // read captures, and a hand-built one falls back to the first frame.
        let i = self
            .meta
            .frames
            .iter()
            .position(|f| f.lasers_on.is_empty() && f.pair == 0)
            .unwrap_or(0);
        &self.frames[i]
    }

    /// The laser-on frames (of the first exposure pair) with the planes each one lit.
    pub fn on_frames(&self) -> impl Iterator<Item = (&[usize], &Pgm)> {
        self.meta
            .frames
            .iter()
            .zip(&self.frames)
            .filter(|(e, _)| !e.lasers_on.is_empty() && e.pair == 0)
            .map(|(e, p)| (e.lasers_on.as_slice(), p))
    }

    /// How many exposure pairs the capture holds (1 for a single trigger's pair).
    pub fn pairs(&self) -> usize {
        self.meta.pairs()
    }

    /// The capture of exposure pair `pair` alone, as if it had been taken by itself (its
    /// frames become pair 0); `None` beyond [`Capture::pairs`].
    pub fn exposure_pair(&self, pair: usize) -> Option<Capture> {
        if pair >= self.pairs() {
            return None;
        }
        let (entries, frames): (Vec<FrameEntry>, Vec<Pgm>) = self
            .meta
            .frames
            .iter()
            .zip(&self.frames)
            .filter(|(e, _)| e.pair == pair)
            .map(|(e, p)| {
                (
                    FrameEntry {
                        pair: 0,
                        ..e.clone()
                    },
                    p.clone(),
                )
            })
            .unzip();
        Some(Capture {
            meta: CaptureMeta {
                frames: entries,
                ..self.meta.clone()
            },
            calibration: self.calibration.clone(),
            frames,
            truth_curve: self.truth_curve.clone(),
            truth_curve_unreadable: self.truth_curve_unreadable.clone(),
        })
    }
}

/// A frame's error, its file named as `capture.toml` names it: an I/O error is the capture's,
/// a malformed PGM is [`CaptureError::Pgm`].
fn frame_error(file: &str, error: PgmError) -> CaptureError {
    match error {
        PgmError::Io { error, .. } => CaptureError::Io {
            file: file.to_string(),
            error,
        },
        PgmError::UnexpectedSize { expected, actual } => CaptureError::FrameSizeMismatch {
            file: file.to_string(),
            // `expected` is the `capture.toml` size, which fits `u32`.
            expected: (expected.0 as u32, expected.1 as u32),
            actual,
        },
        source => CaptureError::Pgm {
            file: file.to_string(),
            source,
        },
    }
}
