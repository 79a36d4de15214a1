//! The normal-residual pull of the whole-arc fit (`docs/error-model.md` §5e, "The pull to
//! second order"): the expected bias of [`super::fit_weighted`]'s circle when each point is
//! displaced only along its noise direction, with correlated noise along the stripe.
//!
//! The fit solves `F(θ, ε) = Σᵢ wᵢ dᵢ Jᵢ = 0` (`dᵢ = |qᵢ − c| − r`, `Jᵢ = ∂dᵢ/∂θ = (−nᵢ, −1)`,
//! `wᵢ = τᵢ/(σᵢ²((nᵢ·ĝᵢ)² + f²))`, `τᵢ` the frozen Tukey factor) for points `qᵢ = q̄ᵢ + εᵢĝᵢ`.
//! Expanding `θ̂(ε)` to second order in the noise and taking the expectation with
//! `E[εᵢεⱼ] = Cᵢⱼ`:
//!
//! ```text
//! E[θ̂ − θ] = −½ A⁻¹ [ Σᵢ Cᵢᵢ F_εᵢεᵢ + 2 Σᵢ F_θεᵢ mᵢ + F_θθ[S] ],
//! A = Σ wᵢJᵢJᵢᵀ,  θᵢ = −A⁻¹ wᵢaᵢJᵢ,  mᵢ = Σⱼ Cᵢⱼ θⱼ,  S = Σᵢ θᵢ mᵢᵀ
//! ```
//!
//! with, per point (`aᵢ = nᵢ·ĝᵢ`, `tᵢ` the circle's tangent, `γᵢ = tᵢ·ĝᵢ`, `pᵢ = aᵢ² + f²`):
//! `∂d/∂ε = a`, `∂²d/∂ε² = γ²/r` (the point slides off the circle by `δ²γ²/2r`),
//! `∂J/∂ε = (−tγ/r, 0)`, `∂w/∂ε = −2waγ²/(rp)`, `∂w/∂c = 2waγ t/(rp)`, `∂J/∂θ = t̃t̃ᵀ/r`
//! (`t̃ = (t, 0)`). The noise covariance is the data's: `Cᵢⱼ = ρ_{|k|} κ σᵢσⱼ` over the
//! inliers `k` apart along the curve (`ρ` the residuals' autocorrelation, summed while
//! positive as for the correlation length; `κ σᵢ²` each point's measured variance,
//! [`FittedArc::variance_factor`]). The
//! essential term (`Cᵢᵢ F_εε`) pulls the circle in, the cross terms push it out, and
//! correlation along the stripe multiplies only the latter: the Monte Carlo of
//! `tools/stem_pull_mc.py` (white and 7-point Savitzky–Golay noise) agrees within its error
//! where `σ_z ≪ r`.

// `!(x > 0.0)` is deliberate throughout: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

#[allow(unused_imports)]
use crate::real::Float;
use crate::real::{self, Mat3, Real, Vec2, Vec3};

use super::Normalisation;
use crate::solvers::correlation::MAX_CORRELATION_LAG;

/// The data of a finished [`super::fit_weighted`], normalised: the points and their noise,
/// the final weights and the residuals' variance and autocorrelation.
pub(super) struct FittedArc<'a> {
    /// The points (raw; `norm` maps them).
    pub(super) points: &'a [Vec2],
    /// The fit's normalisation.
    pub(super) norm: &'a Normalisation,
    /// The fitted circle `(cx, cy, r)`, normalised.
    pub(super) theta: Vec3,
    /// Each point's σ along its noise direction (normalised; infinite: no weight).
    pub(super) sigmas: &'a [Real],
    /// Unit noise directions, x components.
    pub(super) dir_x: &'a [Real],
    /// Unit noise directions, y components.
    pub(super) dir_y: &'a [Real],
    /// The final weights `wᵢ` (0: outlier).
    pub(super) weights: &'a [Real],
    /// Autocorrelation of the normalised residuals along the inliers, `rho[0] = 1`.
    pub(super) rho: &'a [Real],
    /// The fit's lateral floor `f` (`weighted::LATERAL_FLOOR`): a residual's σ is
    /// `σᵢ·√((nᵢ·ĝᵢ)² + f²)`. Handed over rather than imported, so the pull depends on the
    /// fit's description alone.
    pub(super) lateral_floor: Real,
}

/// One point's terms of the expansion (module documentation).
struct Local {
    /// `∂d/∂θ`.
    j: Vec3,
    /// The tangent `(t, 0)`.
    tangent: Vec3,
    /// `a = n·ĝ`.
    a: Real,
    /// The weight.
    w: Real,
    /// `∂w/∂ε`.
    dw_de: Real,
    /// `∂w/∂θ`.
    dw_dtheta: Vec3,
    /// `∂J/∂ε`.
    dj_de: Vec3,
    /// `½ ∂²d/∂ε²`.
    half_curvature: Real,
    /// The point's variance along its noise direction, `κ σ²`.
    variance: Real,
}

impl FittedArc<'_> {
    /// Point `i`'s terms, `None` for an outlier or a point without σ.
    fn local(&self, i: usize, kappa: Real) -> Option<Local> {
        let w = *self.weights.get(i)?;
        let sigma = *self.sigmas.get(i)?;
        if !(w > 0.0 && sigma.is_finite()) {
            return None;
        }
        let g = Vec2::new(*self.dir_x.get(i)?, *self.dir_y.get(i)?);
        let r = self.theta.z;
        let d = self.norm.apply(*self.points.get(i)?) - Vec2::new(self.theta.x, self.theta.y);
        let len = real::norm(&d);
        if !(len > 0.0 && r > 0.0) {
            return None;
        }
        let n = d / len;
        let t = Vec2::new(-n.y, n.x);
        let a = n.dot(&g);
        let gamma = t.dot(&g);
        let p = a * a + self.lateral_floor * self.lateral_floor;
        let tangent = Vec3::new(t.x, t.y, 0.0);
        Some(Local {
            j: Vec3::new(-n.x, -n.y, -1.0),
            tangent,
            a,
            w,
            dw_de: -2.0 * w * a * gamma * gamma / (r * p),
            dw_dtheta: tangent * (2.0 * w * a * gamma / (r * p)),
            dj_de: tangent * (-gamma / r),
            half_curvature: gamma * gamma / (2.0 * r),
            variance: kappa * sigma * sigma,
        })
    }

    /// The points' variance over their σ², `κ = Σdᵢ²/sᵢ² / Σσᵢ²aᵢ²(1 − hᵢ)/sᵢ²` over the
    /// inliers (`sᵢ² = σᵢ²(aᵢ² + f²)`, `hᵢ = wᵢJᵢᵀA⁻¹Jᵢ` the point's leverage): what the
    /// residuals normal to the circle show against what σᵢ along ĝᵢ predicts for them after
    /// the fit, without the Tukey factor (`E[τu²]/E[τ]` ≈ 0.83 for Gaussian `u`). Not the
    /// fit's χ²_ν, whose lateral
    /// floor over-states the normal σ of the points near the silhouette (there `aᵢ → 0`), and
    /// whose `n − 3` misses that those heavy points take most of the fit's three degrees of
    /// freedom.
    fn variance_factor(&self, a_inv: &Mat3) -> Option<Real> {
        let centre = Vec2::new(self.theta.x, self.theta.y);
        let (mut observed, mut predicted) = (0.0, 0.0);
        for (i, p) in self.points.iter().enumerate() {
            let (Some(&w), Some(&sigma), Some(&gx), Some(&gy)) = (
                self.weights.get(i),
                self.sigmas.get(i),
                self.dir_x.get(i),
                self.dir_y.get(i),
            ) else {
                break;
            };
            let d = self.norm.apply(*p) - centre;
            let len = real::norm(&d);
            if !(w > 0.0 && sigma.is_finite() && len > 0.0) {
                continue;
            }
            let n = d / len;
            let a = n.dot(&Vec2::new(gx, gy));
            let j = Vec3::new(-n.x, -n.y, -1.0);
            let leverage = w * j.dot(&(a_inv * j));
            let residual = len - self.theta.z;
            // Without the Tukey factor, which lowers the larger residuals' share.
            let p = sigma * sigma * (a * a + self.lateral_floor * self.lateral_floor);
            observed += residual * residual / p;
            predicted += sigma * sigma * a * a * (1.0 - leverage).max(0.0) / p;
        }
        let kappa = observed / predicted;
        (kappa.is_finite() && kappa > 0.0).then_some(kappa)
    }
}

/// Expected bias `E[θ̂ − θ]` of the fitted circle `(cx, cy, r)` (normalised units) under the
/// arc's own noise (module documentation), `None` when it cannot be evaluated (singular
/// normal matrix, no inliers). Cost: one pass for `A`, one over the inliers (each point's
/// terms once; `mᵢ` from a window of its correlated neighbours' `hⱼ`, below), one for
/// `F_θθ[S]`.
///
/// `mᵢ = Σⱼ Cᵢⱼ θⱼ = −κσᵢ A⁻¹ Σ_k ρ_|k| hᵢ₊ₖ` with `hⱼ = wⱼaⱼσⱼJⱼ`: the neighbours enter only
/// through `hⱼ`, so each point's `hⱼ` is formed once and kept in a window of the last
/// `2K + 1` inliers (`K = rho.len() − 1`) instead of recomputing every neighbour's terms for
/// every point — on the device that was most of the solver's cost (`docs/performance.md`).
pub(super) fn expected_bias(arc: &FittedArc<'_>) -> Option<Vec3> {
    let n = arc.points.len();
    // A does not depend on κ.
    let mut a = Mat3::zeros();
    for i in 0..n {
        if let Some(l) = arc.local(i, 1.0) {
            a += l.j * l.j.transpose() * l.w;
        }
    }
    let a_inv = a.try_inverse()?;
    let kappa = arc.variance_factor(&a_inv)?;
    let mut sums = Sums {
        total: Vec3::zeros(),
        s: Mat3::zeros(),
    };
    let mut window = Window::new(arc.rho.len().saturating_sub(1));
    for i in 0..n {
        if !arc.weights.get(i).is_some_and(|w| *w > 0.0) {
            continue;
        }
        let h = arc
            .local(i, 1.0)
            .map_or(Vec3::zeros(), |l| h_term(arc, i, &l));
        window.push(i, h);
        if let Some(centre) = window.ready() {
            centre_terms(arc, kappa, &a_inv, &window, centre, &mut sums);
        }
    }
    while let Some(centre) = window.drain() {
        centre_terms(arc, kappa, &a_inv, &window, centre, &mut sums);
    }
    let r = arc.theta.z;
    let (mut total, s) = (sums.total, sums.s);
    // F_θθ contracted with S (symmetric in expectation).
    for i in 0..n {
        let Some(l) = arc.local(i, kappa) else {
            continue;
        };
        let sj = s * l.j;
        let tst = l.tangent.dot(&(s * l.tangent));
        total += l.j * (2.0 * l.dw_dtheta.dot(&sj) + l.w * tst / r)
            + l.tangent * (2.0 * l.w * l.tangent.dot(&sj) / r);
    }
    let bias = a_inv * total * -0.5;
    (bias.x.is_finite() && bias.y.is_finite() && bias.z.is_finite()).then_some(bias)
}

/// `hⱼ = wⱼaⱼσⱼJⱼ` of point `j` (see [`expected_bias`]).
fn h_term(arc: &FittedArc<'_>, j: usize, l: &Local) -> Vec3 {
    let sigma = arc.sigmas.get(j).copied().unwrap_or(0.0);
    l.j * (l.w * l.a * sigma)
}

/// The running sums of [`expected_bias`]: `Σᵢ Cᵢᵢ F_εε + 2F_θε mᵢ` and `S = Σᵢ θᵢ mᵢᵀ`.
struct Sums {
    total: Vec3,
    s: Mat3,
}

/// Point `i`'s (the window's `centre`-th inlier) terms of the expansion.
fn centre_terms(
    arc: &FittedArc<'_>,
    kappa: Real,
    a_inv: &Mat3,
    window: &Window,
    centre: usize,
    sums: &mut Sums,
) {
    let i = window.index(centre);
    let Some(li) = arc.local(i, kappa) else {
        return;
    };
    let sigma_i = arc.sigmas.get(i).copied().unwrap_or(0.0);
    let r = arc.theta.z;
    // First-order response of θ̂ to point i's displacement.
    let theta_i = -(a_inv * li.j) * (li.w * li.a);
    // mᵢ = Σⱼ Cᵢⱼ θⱼ over the correlated neighbours (and i itself, ρ₀ = 1).
    let m = -(a_inv * window.correlated_sum(centre, arc.rho)) * (kappa * sigma_i);
    // Cᵢᵢ F_εε: the slide off the circle, the normal's turn, the weight's change.
    let f_ee = li.j * (2.0 * li.w * li.half_curvature + 2.0 * li.dw_de * li.a)
        + li.dj_de * (2.0 * li.w * li.a);
    // F_θε applied to mᵢ.
    let jm = li.j.dot(&m);
    let f_te = li.j * (li.dw_de * jm + li.w * li.dj_de.dot(&m) + li.a * li.dw_dtheta.dot(&m))
        + li.dj_de * (li.w * jm)
        + li.tangent * (li.w * li.a * li.tangent.dot(&m) / r);
    sums.total += f_ee * li.variance + f_te * 2.0;
    sums.s += theta_i * m.transpose();
}

/// Slots of [`Window`]: `2·MAX_CORRELATION_LAG + 1` inliers.
const WINDOW: usize = 2 * MAX_CORRELATION_LAG + 1;

/// The last `2K + 1` inliers' `hⱼ` in curve order (a ring on the stack: ≈ 2 KB in `f32`).
/// Inlier `p` (in inlier order) is a centre once the `K` inliers after it are in, or at
/// the end.
struct Window {
    h: [Vec3; WINDOW],
    index: [usize; WINDOW],
    lag: usize,
    pushed: usize,
    centred: usize,
}

impl Window {
    fn new(lag: usize) -> Self {
        Window {
            h: [Vec3::zeros(); WINDOW],
            index: [0; WINDOW],
            lag: lag.min(MAX_CORRELATION_LAG),
            pushed: 0,
            centred: 0,
        }
    }

    fn push(&mut self, index: usize, h: Vec3) {
        self.h[self.pushed % WINDOW] = h;
        self.index[self.pushed % WINDOW] = index;
        self.pushed += 1;
    }

    /// The next centre, if the `K` inliers after it are in.
    fn ready(&mut self) -> Option<usize> {
        (self.pushed > self.centred + self.lag).then(|| {
            self.centred += 1;
            self.centred - 1
        })
    }

    /// The next centre after the last inlier.
    fn drain(&mut self) -> Option<usize> {
        (self.centred < self.pushed).then(|| {
            self.centred += 1;
            self.centred - 1
        })
    }

    /// The point index of inlier `p`.
    fn index(&self, p: usize) -> usize {
        self.index[p % WINDOW]
    }

    /// `Σ_k ρ_|k| h_{p+k}` over the inliers within `K` of `p`.
    fn correlated_sum(&self, p: usize, rho: &[Real]) -> Vec3 {
        let mut sum = self.h[p % WINDOW];
        for k in 1..=self.lag {
            let Some(&r) = rho.get(k) else {
                break;
            };
            if let Some(before) = p.checked_sub(k) {
                sum += self.h[before % WINDOW] * r;
            }
            if p + k < self.pushed {
                sum += self.h[(p + k) % WINDOW] * r;
            }
        }
        sum
    }
}
