//! One stem reading from several exposures: the frame pairs taken while the trigger is held
//! (`docs/error-model.md` §6, "Several exposures", (E7)).
//!
//! Each exposure is measured on its own and the diameters are combined: the hand moves
//! between exposures, so their stripes do not line up pixel for pixel and averaging the
//! images would blur them, while the diameter does not depend on where the stem is. The
//! sensor noise of separate frames is independent; the speckle is independent only as far as
//! the hand's motion renewed it, which no single exposure can tell. So the combination
//! estimates how much the exposures' errors share from their own scatter: readings that
//! agree better than their σ allows share part of their error, and the combined σ keeps it.

#[allow(unused_imports)]
use crate::real::Float;
use crate::real::{sqrt, Real};

use super::{CylinderSolution, SolveError};

/// Most exposures one reading combines (the device's frame-pair budget per trigger is far
/// below it; `docs/hardware.md`).
pub const MAX_EXPOSURES: usize = 16;

/// An exposure whose diameter lies this many σ from the mean of the others is dropped (a
/// stray object or a branch in one frame pair), while at least three remain.
const REJECT_Z: Real = 4.0;

/// The smallest independent share of an exposure's variance: a reading whose σ is almost all
/// calibration still weighs as a finite measurement.
const MIN_INDEPENDENT_SHARE: Real = 0.01;

/// One reading of the stem from the readings of several exposures of it ((E7)).
///
/// Each reading's variance splits into its calibration part
/// ([`CylinderSolution::calibration_uncertainty`], the same in every exposure) and the rest,
/// `v_k = σ_k² − c_k²`. Exposures that ignored a lean other exposures saw are set aside,
/// then, while at least three remain, any more than 4σ from the mean of the others. The
/// diameter is the plain mean of the `K` kept ones, each of variance `v̄` (their mean `v_k`).
/// With `r = Σ(d_k − d̄)²/((K−1)·v̄)`, the variance of the mean is `r·v̄/K` when they scatter
/// at least as their σ say (inflated as the scatter demands), and `(K − (K−1)·r)·v̄/K` when
/// they agree better: the share `1 − r` of their errors that they hold in common (speckle
/// the hand did not renew) does not average. The calibration's part is added back whole.
///
/// The other fields come from the first kept exposure, except the counts (summed), the
/// flags (all kept exposures' flags), the fit and three-tangent diameters (means) and the
/// information bound (that of the mean).
///
/// Errors: no readings, or more than [`MAX_EXPOSURES`] ([`SolveError::InvalidParameter`]);
/// a diameter or σ that is not finite and positive ([`SolveError::NonFinite`]).
pub fn combine_exposures(readings: &[CylinderSolution]) -> Result<CylinderSolution, SolveError> {
    let n = readings.len();
    if n == 0 || n > MAX_EXPOSURES {
        return Err(SolveError::InvalidParameter);
    }
    let mut variance = [0.0 as Real; MAX_EXPOSURES];
    for (v, r) in variance.iter_mut().zip(readings) {
        let finite = |x: Real| x.is_finite() && x > 0.0;
        if !(finite(r.diameter) && finite(r.uncertainty) && r.calibration_uncertainty.is_finite()) {
            return Err(SolveError::NonFinite);
        }
        let total = r.uncertainty * r.uncertainty;
        let cal = r.calibration_uncertainty * r.calibration_uncertainty;
        *v = (total - cal).max(MIN_INDEPENDENT_SHARE * total);
    }
    // A reading that ignored the stem's lean (one plane's fallback) is biased on a leaning
    // stem: when some exposure saw the lean, only those that did are combined.
    let any_tilt = readings.iter().any(|r| r.tilt.is_some());
    let mut kept = [false; MAX_EXPOSURES];
    for (k, r) in kept.iter_mut().zip(readings) {
        *k = r.tilt.is_some() || !any_tilt;
    }
    while let Some(stray) = farthest_stray(readings, &variance, &kept) {
        kept[stray] = false;
    }
    let used = || {
        readings
            .iter()
            .zip(variance)
            .zip(kept)
            .filter(|(_, k)| *k)
            .map(|(rv, _)| rv)
    };
    let mut first = used();
    let (best, _) = first.next().ok_or(SolveError::InvalidParameter)?;
    if first.next().is_none() {
        // One exposure: its reading alone, with its own σ.
        return Ok(*best);
    }
    // Equal weights: each exposure's σ is itself an estimate that grows with its diameter,
    // and weighting by it would pull the mean low.
    let k = used().count() as Real;
    let mean =
        |value: fn(&CylinderSolution) -> Real| used().map(|(r, _)| value(r)).sum::<Real>() / k;
    let diameter = mean(|r| r.diameter);
    let calibration = mean(|r| r.calibration_uncertainty);
    let independent = used().map(|(_, v)| v).sum::<Real>() / k;
    let ratio = used()
        .map(|(r, _)| (r.diameter - diameter) * (r.diameter - diameter))
        .sum::<Real>()
        / ((k - 1.0) * independent);
    let variance = independent / k
        * if ratio >= 1.0 {
            ratio
        } else {
            k - (k - 1.0) * ratio
        };
    let optional_mean = |value: fn(&CylinderSolution) -> Option<Real>| {
        let (sum, count) = used()
            .filter_map(|(r, _)| value(r))
            .fold((0.0, 0.0), |(s, n), v| (s + v, n + 1.0));
        (count > 0.0).then(|| sum / count)
    };
    let information = used()
        .filter_map(|(r, _)| r.information_uncertainty)
        .map(|s| 1.0 / (s * s))
        .sum::<Real>();
    let mut flags = best.flags;
    used().for_each(|(r, _)| flags.insert(r.flags));
    Ok(CylinderSolution {
        diameter,
        uncertainty: sqrt(variance + calibration * calibration),
        calibration_uncertainty: calibration,
        flags,
        n_points: used().map(|(r, _)| r.n_points).sum(),
        exposures: used().map(|(r, _)| r.exposures).sum(),
        fit_diameter: optional_mean(|r| r.fit_diameter),
        three_tangent_diameter: optional_mean(|r| r.three_tangent_diameter),
        information_uncertainty: (information > 0.0).then(|| 1.0 / sqrt(information)),
        pull_correction: mean(|r| r.pull_correction),
        ..*best
    })
}

/// The kept exposure farthest from the mean of the other kept ones, if it lies more than
/// [`REJECT_Z`] σ from it (σ of the difference, from the kept exposures' mean independent
/// variance) and at least three would remain.
fn farthest_stray(
    readings: &[CylinderSolution],
    variance: &[Real],
    kept: &[bool],
) -> Option<usize> {
    let kept_ones = || (0..readings.len()).filter(|&i| kept[i]);
    let count = kept_ones().count();
    if count < 4 {
        return None;
    }
    let n = count as Real;
    let independent = kept_ones().map(|i| variance[i]).sum::<Real>() / n;
    let sum = kept_ones().map(|i| readings[i].diameter).sum::<Real>();
    let spread = sqrt(independent * (1.0 + 1.0 / (n - 1.0)));
    kept_ones()
        .map(|i| {
            let others = (sum - readings[i].diameter) / (n - 1.0);
            (i, (readings[i].diameter - others).abs() / spread)
        })
        .filter(|&(_, z)| z > REJECT_Z)
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(i, _)| i)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::real::Vec3;
    use crate::solvers::result::{Flags, Method};

    fn reading(diameter: Real, sigma: Real, calibration: Real) -> CylinderSolution {
        CylinderSolution {
            diameter,
            method: Method::CircleFit,
            uncertainty: sigma,
            calibration_uncertainty: calibration,
            tilt: None,
            flags: Flags::default(),
            fit_rms: 1e-4,
            n_points: 100,
            exposures: 1,
            three_tangent_diameter: None,
            three_tangent_uncertainty: None,
            fit_diameter: Some(diameter),
            fit_uncertainty: Some(sigma),
            information_uncertainty: Some(sigma / 2.0),
            pull_correction: 0.0,
            distance: 2.0,
            centre: Vec3::new(0.0, 0.0, 2.0),
            axes: None,
        }
    }

    /// A deterministic standard normal (Box–Muller on a 64-bit LCG): the tests need many
    /// draws and no crate for them.
    struct Normal(u64);
    impl Normal {
        fn uniform(&mut self) -> f64 {
            self.0 = self
                .0
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((self.0 >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        }
        fn draw(&mut self) -> Real {
            let (u, v) = (self.uniform(), self.uniform());
            ((-2.0 * u.ln()).sqrt() * (2.0 * core::f64::consts::PI * v).cos()) as Real
        }
    }

    /// Coverage and spread of the combined reading over many simulated bursts of `k`
    /// exposures whose independent errors share the fraction `rho` of their variance.
    fn bursts(k: usize, rho: Real, seed: u64) -> (Real, Real, Real) {
        let (truth, sigma, cal) = (0.3, 4e-3, 1e-3);
        let independent = sqrt(sigma * sigma - cal * cal);
        let mut normal = Normal(seed);
        let (mut within, mut sq, mut sigma_sq) = (0usize, 0.0, 0.0);
        let trials = 4000;
        for _ in 0..trials {
            let common = normal.draw() * independent * sqrt(rho) + normal.draw() * cal;
            let mut set = [reading(truth, sigma, cal); 8];
            for r in set.iter_mut().take(k) {
                r.diameter += common + normal.draw() * independent * sqrt(1.0 - rho);
            }
            let c = combine_exposures(&set[..k]).unwrap();
            let e = c.diameter - truth;
            within += usize::from(e.abs() <= 2.0 * c.uncertainty);
            sq += e * e;
            sigma_sq += c.uncertainty * c.uncertainty;
        }
        let rms = sqrt(sq / trials as Real);
        (
            within as Real / trials as Real,
            rms,
            sqrt(sigma_sq / trials as Real),
        )
    }

    #[test]
    fn independent_exposures_average_and_the_sigma_covers() {
        // Four exposures with independent errors: the error of the mean falls by about √4
        // on the independent part (3.87 mm → 1.94 mm, with 1 mm of calibration on top).
        let (coverage, rms, sigma) = bursts(4, 0.0, 1);
        let expected = sqrt((4e-3 * 4e-3 - 1e-6) / 4.0 + 1e-6);
        assert!(
            (rms / expected - 1.0).abs() < 0.06,
            "rms {rms} expected {expected}"
        );
        assert!((0.93..=0.995).contains(&coverage), "coverage {coverage}");
        assert!(sigma >= rms, "σ {sigma} below the spread {rms}");
    }

    #[test]
    fn exposures_that_share_their_error_keep_their_sigma() {
        // Frozen speckle: the exposures' errors are all common; the mean is no better than
        // one exposure, and the σ must not claim it is.
        let (coverage, rms, _) = bursts(4, 1.0, 2);
        assert!((rms / 4e-3 - 1.0).abs() < 0.06, "rms {rms}");
        assert!(coverage >= 0.93, "coverage {coverage}");
        let (coverage, _, _) = bursts(4, 0.5, 3);
        assert!(coverage >= 0.93, "coverage {coverage}");
    }

    #[test]
    fn a_stray_exposure_is_dropped() {
        let mut set = [reading(0.3, 2e-3, 5e-4); 5];
        set[1].diameter = 0.3015;
        set[2].diameter = 0.2990;
        set[3].diameter = 0.36; // another object crossed the stripe in one frame pair
        set[4].diameter = 0.3005;
        let c = combine_exposures(&set).unwrap();
        assert_eq!(c.exposures, 4);
        assert!((c.diameter - 0.30025).abs() < 1e-6, "{}", c.diameter);
        assert_eq!(c.n_points, 400);
    }

    #[test]
    fn a_reading_that_ignored_the_lean_is_not_mixed_with_those_that_saw_it() {
        let tilt = crate::solvers::result::Tilt {
            axis: Vec3::new(0.0, 0.96, 0.28),
            theta: 0.28,
            phi: 0.0,
            total: 0.28,
            azimuth: 0.0,
            sigma: 0.01,
        };
        let mut set = [reading(0.3, 2e-3, 5e-4); 3];
        set[0].tilt = Some(tilt);
        set[2].tilt = Some(tilt);
        set[2].diameter = 0.302;
        set[1].diameter = 0.32; // the fallback's level section of a leaning stem reads wide
        set[1].flags.insert(Flags::TILT_IGNORED);
        let c = combine_exposures(&set).unwrap();
        assert_eq!(c.exposures, 2);
        assert!((c.diameter - 0.301).abs() < 1e-6, "{}", c.diameter);
        assert!(!c.flags.contains(Flags::TILT_IGNORED));
        assert_eq!(c.tilt, Some(tilt));
        // One exposure saw the lean: its reading stands alone, σ and all.
        set[2].tilt = None;
        assert_eq!(combine_exposures(&set), Ok(set[0]));
    }

    #[test]
    fn bad_input_is_a_typed_error() {
        assert_eq!(combine_exposures(&[]), Err(SolveError::InvalidParameter));
        let set = [reading(0.3, 2e-3, 5e-4); MAX_EXPOSURES + 1];
        assert_eq!(combine_exposures(&set), Err(SolveError::InvalidParameter));
        for bad in [Real::NAN, Real::INFINITY, -1.0, 0.0] {
            let set = [reading(0.3, 2e-3, 5e-4), reading(bad, 2e-3, 5e-4)];
            assert_eq!(combine_exposures(&set), Err(SolveError::NonFinite), "{bad}");
            let set = [reading(0.3, 2e-3, 5e-4), reading(0.3, bad, 5e-4)];
            assert_eq!(combine_exposures(&set), Err(SolveError::NonFinite), "{bad}");
        }
        let one = reading(0.3, 2e-3, 5e-4);
        assert_eq!(combine_exposures(&[one]), Ok(one));
    }
}
