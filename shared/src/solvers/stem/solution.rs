//! What the stem solver returns for one capture ([`super::solve`]) or for several exposures
//! of one stem ([`super::combine_exposures`]).

use crate::real::{Real, Vec3};
use crate::solvers::result::{Flags, Method, Tilt};

/// The diameter of one capture, with how it was obtained and how far to trust it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CylinderSolution {
    /// Reported diameter (metres).
    pub diameter: Real,
    /// Method of the reported diameter.
    pub method: Method,
    /// 1σ uncertainty of `diameter` (metres): random (point noise, edges) and calibration,
    /// from the points' σ, the noise model ([`crate::noise`]) and the data.
    pub uncertainty: Real,
    /// The part of `uncertainty` the calibration contributes (metres): common to every
    /// exposure measured with the same calibration, so several exposures do not average it
    /// ([`super::combine_exposures`]).
    pub calibration_uncertainty: Real,
    /// Stem tilt, when two planes measured it.
    pub tilt: Option<Tilt>,
    /// Quality flags.
    pub flags: Flags,
    /// RMS residual of the fit (metres), 0 if it failed.
    pub fit_rms: Real,
    /// Measured points the reading used: plane 0's for a one-plane reading, every plane's for
    /// a two-plane one (before the point budget's binning).
    pub n_points: usize,
    /// Exposures (frame pairs) the reading combines: 1 for one pair ([`super::combine_exposures`]).
    pub exposures: usize,
    /// Three-tangent diameter (plane 0, or generalised), if it succeeded.
    pub three_tangent_diameter: Option<Real>,
    /// Its 1σ.
    pub three_tangent_uncertainty: Option<Real>,
    /// Fit diameter (circle or cylinder), if it succeeded.
    pub fit_diameter: Option<Real>,
    /// Its 1σ.
    pub fit_uncertainty: Option<Real>,
    /// 1σ of the fit diameter that the points' own σ and their correlation along the stripe
    /// allow: the single-exposure information bound (`docs/error-model.md` §6), without the
    /// residuals' χ², the coherent bending and the calibration of `fit_uncertainty`. The
    /// evaluation's bound columns come from it.
    pub information_uncertainty: Option<Real>,
    /// The diameter the second-order pull correction removed from the fit (metres,
    /// `docs/error-model.md` §5e, "The pull to second order"): how far the fit's noise bends
    /// it, to second order; 0 where no pull was evaluated (the two-plane fit).
    pub pull_correction: Real,
    /// Distance from the source of plane 0 to the stem (nearest point, metres).
    pub distance: Real,
    /// Centre of the section in plane 0 (camera frame, metres).
    pub centre: Vec3,
    /// Major and minor diameters (metres) of an elliptic section ([`Flags::ELLIPTIC`]).
    pub axes: Option<(Real, Real)>,
}
