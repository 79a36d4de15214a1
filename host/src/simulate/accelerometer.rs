//! The simulated accelerometer (`docs/building.md` §6): the ADXL355's mean reading over a
//! capture, with its noise, its true bias and misalignment, and the calibration the device
//! would have of them (each off by its calibration σ). Drawn from a random stream of its
//! own, so a capture's frames are the same with or without it.

use nalgebra::{Rotation3, Vector3};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use rand_pcg::Pcg64;
use serde::{Deserialize, Serialize};

use crate::capture::{AccelerometerRecord, STANDARD_GRAVITY};

/// The accelerometer of a simulated capture: the truth and the error budget.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AccelerometerSim {
    /// True gravity in the camera frame (pointing down, any length).
    pub gravity_camera: [f64; 3],
    /// Samples averaged over the capture.
    pub samples: u32,
    /// 1σ of one sample per axis (m/s²).
    pub sample_sigma_m_s2: f64,
    /// 1σ of the true bias per axis (m/s²): drawn once per capture.
    pub bias_m_s2: f64,
    /// 1σ of the bias calibration's error per axis (m/s²).
    pub bias_sigma_m_s2: f64,
    /// 1σ of the true sensor-to-camera misalignment about each axis (radians).
    pub misalignment_rad: f64,
    /// 1σ of the alignment calibration's error about each axis (radians).
    pub alignment_sigma_rad: f64,
}

impl AccelerometerSim {
    /// The reference: an ADXL355 at 62.5 Hz, 16 samples (0.26 s) per capture; noise
    /// 22.5 µg/√Hz over 1.6 × 15.6 Hz ≈ 0.11 mg per sample; offset up to 25 mg before
    /// calibration, 0.75 mg after (the drift of ±0.15 mg/°C over 5 °C since the
    /// six-position calibration); mounting within 1°, aligned to 0.05° by captures of a
    /// plumb wall (`docs/building.md` §6). A level camera: gravity along the image's +y.
    pub fn reference() -> Self {
        let mg = 1e-3 * STANDARD_GRAVITY;
        AccelerometerSim {
            gravity_camera: [0.0, 1.0, 0.0],
            samples: 16,
            sample_sigma_m_s2: 0.11 * mg,
            bias_m_s2: 25.0 * mg,
            bias_sigma_m_s2: 0.75 * mg,
            misalignment_rad: 1f64.to_radians(),
            alignment_sigma_rad: 0.05f64.to_radians(),
        }
    }

    /// The device's record of one capture, drawn from `seed`.
    pub fn record(&self, seed: u64) -> AccelerometerRecord {
        // A stream of its own (not the frames'): the seed mixed with a fixed tag.
        let mut rng = Pcg64::seed_from_u64(seed ^ 0xACCE_1E50_0000_0355);
        let mut normal = |s: f64| -> f64 {
            Normal::new(0.0, s.max(0.0))
                .map(|d| d.sample(&mut rng))
                .unwrap_or(0.0)
        };
        let mut vector = |s: f64| Vector3::new(normal(s), normal(s), normal(s));
        let g = Vector3::from(self.gravity_camera);
        let down = if g.norm() > 0.0 {
            g.normalize()
        } else {
            Vector3::y()
        };
        let misalignment = vector(self.misalignment_rad);
        let camera_from_sensor = Rotation3::new(misalignment);
        let bias = vector(self.bias_m_s2);
        let noise = vector(self.sample_sigma_m_s2 / (self.samples.max(1) as f64).sqrt());
        // At rest the sensor reads the specific force: up, 1 g.
        let mean = camera_from_sensor.inverse() * (-down * STANDARD_GRAVITY) + bias + noise;
        let bias_estimate = bias + vector(self.bias_sigma_m_s2);
        let alignment_estimate = misalignment + vector(self.alignment_sigma_rad);
        AccelerometerRecord {
            mean_m_s2: mean.into(),
            samples: self.samples,
            sample_sigma_m_s2: self.sample_sigma_m_s2,
            bias_m_s2: bias_estimate.into(),
            bias_sigma_m_s2: self.bias_sigma_m_s2,
            camera_from_sensor_rad: alignment_estimate.into(),
            alignment_sigma_rad: self.alignment_sigma_rad,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_recorded_gravity_scatters_as_its_sigma_says() {
        let sim = AccelerometerSim::reference();
        let truth = Vector3::from(sim.gravity_camera).normalize();
        let (mut inside, n) = (0, 2000);
        let mut sigma = 0.0;
        for seed in 0..n {
            let (g, s) = sim.record(seed).gravity_camera().unwrap();
            sigma = s;
            // The angle about x (the one a wall's plumb reading sees for a level camera).
            let err = (Vector3::from(g) - truth).z.abs();
            if err <= 2.0 * s {
                inside += 1;
            }
        }
        let coverage = inside as f64 / n as f64;
        assert!((0.93..=0.97).contains(&coverage), "2σ coverage {coverage}");
        // The budget: 0.75 mg of bias and 0.05° of alignment: ≈ 0.066°.
        assert!(
            (sigma.to_degrees() - 0.066).abs() < 0.005,
            "σ {}°",
            sigma.to_degrees()
        );
    }

    #[test]
    fn a_record_of_a_moving_device_or_a_bad_sigma_is_refused_by_name() {
        let good = AccelerometerSim::reference().record(7);
        let mut moving = good.clone();
        moving.mean_m_s2 = moving.mean_m_s2.map(|v| 2.0 * v);
        let e = moving.gravity_camera().unwrap_err();
        assert!(e.contains("mean_m_s2") && e.contains("not at rest"), "{e}");
        let mut bad = good.clone();
        bad.bias_sigma_m_s2 = -1.0;
        assert!(bad
            .gravity_camera()
            .unwrap_err()
            .contains("bias_sigma_m_s2"));
        let mut none = good;
        none.samples = 0;
        assert!(none.gravity_camera().unwrap_err().contains("samples"));
    }
}
