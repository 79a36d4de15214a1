//! What a forester reads for each quality flag: the warning in words, with what to do.
//! The flags' names ([`codes::FLAG_NAMES`]) are what exports and scripts read; these
//! sentences are what the field app shows beside a reading.

use tangent_core::protocol::codes;
use tangent_core::solvers::result::Flags;

/// The sentence for every flag of [`codes::FLAG_NAMES`], in the same order (a test checks
/// that each flag has one).
pub const FLAG_ADVICE: [(Flags, &str); 17] = [
    (
        Flags::ARC_TOO_SHORT,
        "too little of the stem was lit: step back or aim at its centre",
    ),
    (
        Flags::POOR_FIT,
        "bark or branches disturbed the fit: aim at clean bark and measure again",
    ),
    (
        Flags::TILT_IGNORED,
        "the lean was not measured: hold the caliper square to the stem",
    ),
    (
        Flags::INCONSISTENT,
        "an edge of the stem was hidden or dark: measure again from another side",
    ),
    (
        Flags::THREE_TANGENT_FAILED,
        "the stem's edges were not seen: step back so both edges are lit",
    ),
    (Flags::FIT_FAILED, "the fit failed: measure again"),
    (
        Flags::RANGE_LIMIT,
        "outside the working distance: step closer or back",
    ),
    (
        Flags::TILT_FIT_FAILED,
        "the lean could not be measured: hold still and measure again",
    ),
    (
        Flags::LARGE_TILT,
        "the stem leans strongly: measure square to the stem",
    ),
    (
        Flags::SEVERAL_OBJECTS,
        "several objects in view: aim at one stem only",
    ),
    (
        Flags::STRIPE_SATURATED,
        "the laser line was too bright: measure again",
    ),
    (
        Flags::AMBIENT_BRIGHT,
        "sunlit bark makes the reading noisy: shade the stem or measure from its shady side",
    ),
    (
        Flags::OTHER_OBJECTS,
        "another stem or branch was beside it: aim at its centre",
    ),
    (
        Flags::ELLIPTIC,
        "the stem is not round: the mean of its two diameters is shown",
    ),
    (
        Flags::NEAR_POLE,
        "a laser line crosses the ball near its top or bottom: aim at the ball's middle",
    ),
    (
        Flags::NOT_SPHERICAL,
        "the object is not a ball: this reading is not a sphere's diameter",
    ),
    (
        Flags::FAINT_STRIPE,
        "the laser line was barely visible (sun or a dark, far stem): shade it or step closer",
    ),
];

/// Flags that describe the instrument rather than the reading: a one-laser caliper sets
/// `TILT_IGNORED` on every reading, and a warning on every reading is one nobody reads.
pub const NOT_WARNINGS: Flags = Flags::TILT_IGNORED;

/// The warnings for `flags`, in bit order, without [`NOT_WARNINGS`]; a bit this version does
/// not know gets a sentence naming it.
pub fn warnings(flags: u32) -> Vec<String> {
    let mut out: Vec<String> = FLAG_ADVICE
        .iter()
        .filter(|(f, _)| flags & f.0 != 0 && NOT_WARNINGS.0 & f.0 == 0)
        .map(|(_, s)| s.to_string())
        .collect();
    let rest = flags & !codes::known_flags().0;
    if rest != 0 {
        out.push(format!("unknown quality flag 0x{rest:04X}: update the app"));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_flag_has_advice() {
        for ((named, name), (advised, _)) in codes::FLAG_NAMES.iter().zip(FLAG_ADVICE.iter()) {
            assert_eq!(named.0, advised.0, "advice for {name}");
        }
        assert_eq!(codes::FLAG_NAMES.len(), FLAG_ADVICE.len());
        assert_eq!(warnings(0), Vec::<String>::new());
        assert_eq!(warnings(Flags::TILT_IGNORED.0), Vec::<String>::new());
        let w = warnings(Flags::ARC_TOO_SHORT.0 | Flags::NEAR_POLE.0);
        assert_eq!(w.len(), 2);
        assert!(w[0].contains("step back or aim at its centre"));
        assert!(w[1].contains("the ball's middle"));
    }
}
