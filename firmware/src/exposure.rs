//! Auto-exposure: keeps the laser stripe bright but below saturation.
//!
//! The stripe's peak grey level grows linearly with exposure time (the sensor is linear
//! below saturation, `docs/firmware.md`), so after each laser-on frame the exposure is
//! scaled by `TARGET / peak`, clamped to a factor in `[1/2, 2]` per step so a single odd
//! frame (a specular glint, the stripe leaving the trunk) cannot swing it wildly. A
//! saturated peak says nothing about how far above full scale the stripe is, so it halves
//! the exposure.

/// Shortest exposure (µs).
pub const MIN_EXPOSURE_US: u32 = 20;
/// Longest exposure (µs). Also bounds the laser on-time of one frame.
pub const MAX_EXPOSURE_US: u32 = 8_000;
/// Exposure at boot (µs).
pub const DEFAULT_EXPOSURE_US: u32 = 1_000;
/// Peak grey level aimed at: 80 % of full scale leaves head-room for speckle.
pub const TARGET_PEAK: u32 = 200;
/// Grey level counted as saturated (8-bit data).
pub const SATURATED: u8 = 250;
/// Below this peak the stripe is too dim to trust the linear model (noise): double.
const MIN_USEFUL_PEAK: u32 = 16;

/// Exposure state: fixed by the host, or automatic.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Exposure {
    fixed: Option<u32>,
    auto_us: u32,
}

impl Default for Exposure {
    fn default() -> Self {
        Self::new()
    }
}

impl Exposure {
    /// Automatic, starting at [`DEFAULT_EXPOSURE_US`].
    pub const fn new() -> Self {
        Exposure {
            fixed: None,
            auto_us: DEFAULT_EXPOSURE_US,
        }
    }

    /// The exposure to use now (µs).
    pub fn current(&self) -> u32 {
        self.fixed.unwrap_or(self.auto_us)
    }

    /// Fixes the exposure (clamped to the limits), or returns to automatic with `None`.
    pub fn set_fixed(&mut self, us: Option<u32>) {
        self.fixed = us.map(|u| u.clamp(MIN_EXPOSURE_US, MAX_EXPOSURE_US));
    }

    /// Updates the automatic exposure from the peak grey level of the last laser-on frame.
    pub fn update(&mut self, peak: u8) {
        let cur = self.auto_us;
        let next = if peak >= SATURATED {
            cur / 2
        } else if (peak as u32) < MIN_USEFUL_PEAK {
            cur.saturating_mul(2)
        } else {
            // cur · TARGET / peak, with the per-step factor clamped to [1/2, 2].
            let scaled = (cur as u64 * TARGET_PEAK as u64 / peak as u64) as u32;
            scaled.clamp(cur / 2, cur.saturating_mul(2))
        };
        self.auto_us = next.clamp(MIN_EXPOSURE_US, MAX_EXPOSURE_US);
    }
}

/// Brightest pixel of `frame`, looking at every `step`-th row (`width` bytes per row):
/// the stripe is several rows thick and spans many columns, so sampled rows find its
/// peak at a fraction of the cost.
pub fn peak(frame: &[u8], width: usize, step: usize) -> u8 {
    if width == 0 {
        return 0;
    }
    frame
        .chunks_exact(width)
        .step_by(step.max(1))
        .flat_map(|row| row.iter().copied())
        .max()
        .unwrap_or(0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn converges_to_the_target_for_a_linear_sensor() {
        // Simulated linear sensor: peak = 0.05 grey levels per µs.
        let mut e = Exposure::new();
        for _ in 0..10 {
            let p = (e.current() as f64 * 0.05).min(255.0) as u8;
            e.update(p);
        }
        let p = e.current() as f64 * 0.05;
        assert!((p - TARGET_PEAK as f64).abs() <= 1.0, "{p}");
    }

    #[test]
    fn saturation_halves_and_limits_hold() {
        let mut e = Exposure::new();
        e.update(255);
        assert_eq!(e.current(), DEFAULT_EXPOSURE_US / 2);
        for _ in 0..40 {
            e.update(255);
        }
        assert_eq!(e.current(), MIN_EXPOSURE_US);
        for _ in 0..40 {
            e.update(0);
        }
        assert_eq!(e.current(), MAX_EXPOSURE_US);
        e.set_fixed(Some(1));
        assert_eq!(e.current(), MIN_EXPOSURE_US);
        e.set_fixed(None);
        assert_eq!(e.current(), MAX_EXPOSURE_US);
    }

    #[test]
    fn peak_samples_rows() {
        let mut f = [0u8; 12];
        f[4] = 9; // row 1
        f[9] = 7; // row 2
        assert_eq!(peak(&f, 4, 1), 9);
        assert_eq!(peak(&f, 4, 2), 7);
        assert_eq!(peak(&f, 0, 2), 0);
    }
}
