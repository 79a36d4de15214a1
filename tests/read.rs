//! The one way the corpus tests read a capture: measured as `tangent measure` does (default
//! pipeline and stem parameters, the capture's own calibration), an error being a test failure.

use tangent_core::pipeline::PipelineConfig;
use tangent_core::solvers::stem::CylinderParams;
use tangent_host::measure::{measure_capture, Reading};

/// The reading of the corpus capture `name`; panics with the capture's name and the error.
pub fn read(name: &str) -> Reading {
    measure_capture(
        &tangent_corpus::captures().join(name),
        None,
        &PipelineConfig::default(),
        &CylinderParams::default(),
    )
    .unwrap_or_else(|e| panic!("{name}: {e}"))
    .reading
}
