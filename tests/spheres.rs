//! End-to-end checks of the sphere instrument on the sphere captures of the corpus
//! (`tests/captures/sphere-*`, `notsphere-*`, `two-balls-*`; `docs/sphere.md`): each capture
//! is measured as `tangent measure` does and compared with the simulator's scene.
//!
//! The rule is the product's promise for spheres: a ball both lines cross is read within 3σ
//! of its true diameter (the reading's own stated σ), matt or polished steel with its glints;
//! an object that is not one ball is flagged (`not_spherical`) or refused with the error that
//! names its cause (not a ball; two objects in view; one line on it).

use tangent_corpus::captures as corpus;

#[path = "read.rs"]
mod read;
use read::read;

/// Balls both lines cross: matt, off-centre, on a floor (one beside the aim, where the floor's
/// lines cross the central column), and polished steel (one with the laser's own glint
/// saturating its stripe, one with a saturated sun glint beside it), and a small ball cut
/// near both poles.
const BALLS: [&str; 11] = [
    "sphere-d100-z080-matt-2p",
    "sphere-d150-z100-offcentre-2p",
    "sphere-d160-z100-floor-2p",
    "sphere-d080-z090-floor-offcentre-2p",
    "sphere-d200-z120-matt-2p",
    "sphere-d400-z200-matt-2p",
    "sphere-d120-z100-shiny-2p",
    "sphere-d250-z150-shiny-offcentre-2p",
    "sphere-d100-z080-steel-sun-2p",
    "sphere-d300-z100-steel-glint-2p",
    "sphere-d055-z120-nearpole-2p",
];

#[test]
fn balls_are_read_within_three_stated_sigma() {
    for name in BALLS {
        let r = read(name);
        let (Some(d), Some(sigma), Some(truth)) =
            (r.diameter_m, r.uncertainty_m, r.truth_diameter_m)
        else {
            panic!("{name}: expected a reading with truth, got {}", r.summary());
        };
        assert_eq!(r.instrument, Some("sphere"), "{name}");
        assert!(
            (d - truth).abs() <= 3.0 * sigma,
            "{name}: {d} m against {truth} m is beyond 3σ = {} m",
            3.0 * sigma
        );
        assert!(
            !r.flags.contains(&"not_spherical"),
            "{name}: a ball flagged not spherical: {:?}",
            r.flags
        );
    }
}

/// The small ball cut near both poles takes the path it is in the corpus for: its sections
/// miss the sphere's axis, one sphere fits every point, and the reading says so.
#[test]
fn a_ball_whose_sections_miss_the_axis_is_read_and_flagged() {
    let r = read("sphere-d055-z120-nearpole-2p");
    assert!(r.diameter_m.is_some(), "{}", r.summary());
    assert!(r.flags.contains(&"inconsistent"), "{:?}", r.flags);
}

/// The glint capture does saturate its stripe (the scene tests what it claims to).
#[test]
fn the_steel_glint_saturates_the_stripe() {
    let capture =
        tangent_host::capture::Capture::read(&corpus().join("sphere-d300-z100-steel-glint-2p"))
            .expect("capture reads");
    let on = &capture.frames[1];
    let saturated = on.to_u16().iter().filter(|&&v| v >= on.maxval).count();
    assert!(saturated >= 10, "only {saturated} saturated pixels");
}

/// Objects that are not one ball, and what each must say.
const NOT_BALLS: [(&str, Expect); 6] = [
    (
        "notsphere-elliptic-post-z100-2p",
        Expect::Flag("not_spherical"),
    ),
    ("notsphere-ellipsoid-z100-2p", Expect::Flag("not_spherical")),
    (
        "notsphere-cylinder-end-z100-2p",
        Expect::Error("not a ball"),
    ),
    ("notsphere-wall-z120-2p", Expect::Error("not a ball")),
    (
        "notsphere-two-balls-z100-2p",
        Expect::Error("two objects in view"),
    ),
    // Both lines across both balls: the pipeline keeps one ball's stripes and says that
    // another object crosses the lines (`docs/sphere.md`, "Two balls in view").
    ("two-balls-d120-z100-2p", Expect::Flag("other_objects")),
];

#[derive(Debug, Clone, Copy)]
enum Expect {
    /// A reading carrying this flag.
    Flag(&'static str),
    /// No reading, an error containing this.
    Error(&'static str),
}

#[test]
fn objects_that_are_not_one_ball_are_flagged_or_refused_with_their_cause() {
    for (name, expect) in NOT_BALLS {
        let r = read(name);
        match expect {
            Expect::Flag(flag) => assert!(
                r.diameter_m.is_some() && r.flags.contains(&flag),
                "{name}: expected a reading flagged {flag}, got {}",
                r.summary()
            ),
            Expect::Error(needle) => {
                assert!(
                    r.diameter_m.is_none(),
                    "{name}: expected an error, got {}",
                    r.summary()
                );
                let e = r.error.unwrap_or_default();
                assert!(
                    e.contains(needle),
                    "{name}: expected an error containing {needle:?}, got {e:?}"
                );
            }
        }
    }
}

/// One laser line on the ball (a one-plane head, or a ball one line misses): the radius is
/// unobservable, and the error says what to do.
#[test]
fn one_section_is_refused_with_advice() {
    for name in ["sphere-d200-z100", "sphere-d060-z060-matt-2p"] {
        let r = read(name);
        assert!(r.diameter_m.is_none(), "{name}: {}", r.summary());
        let e = r.error.unwrap_or_default();
        assert!(
            e.contains("fewer than two laser lines cross the object"),
            "{name}: {e:?}"
        );
    }
}
