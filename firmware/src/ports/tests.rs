//! The strobe keeps the lasers to the exposure: lit only between `on()` and `off()`, never
//! after `trip()`, off when dropped whatever happened, and its lit time measured.

use std::cell::RefCell;

use super::{Clock, Strobe};
use crate::fakes::{poll_bounded, FakeClock, FakeLaser, Time};

fn fakes() -> (Time, FakeClock, FakeLaser) {
    let time = Time::default();
    (time.clone(), FakeClock(time.clone()), FakeLaser::new(&time))
}

fn last_mask(switches: &RefCell<Vec<(u64, u8)>>) -> u8 {
    switches.borrow().last().map_or(0xff, |s| s.1)
}

#[test]
fn strobe_lights_only_between_on_and_off() {
    let (time, clock, mut laser) = fakes();
    let switches = laser.switches.clone();
    {
        let strobe = Strobe::new(&mut laser, &clock, 0b11);
        assert_eq!(
            *switches.borrow(),
            [(0, 0)],
            "new() switches every laser off first"
        );
        assert!(!strobe.is_lit());
        time.set(100);
        strobe.on();
        assert!(strobe.is_lit());
        time.set(1_100);
        assert_eq!(strobe.lit_for_us(), 1_000);
        strobe.off();
        assert!(!strobe.is_lit());
        assert_eq!(strobe.lit_for_us(), 0);
        assert!(!strobe.tripped());
    }
    assert_eq!(
        *switches.borrow(),
        [(0, 0), (100, 0b11), (1_100, 0), (1_100, 0)]
    );
}

#[test]
fn lit_time_counts_from_the_first_on() {
    let (time, clock, mut laser) = fakes();
    let strobe = Strobe::new(&mut laser, &clock, 0b01);
    time.set(50);
    strobe.on();
    time.set(300);
    // A second `on()` (a driver that re-arms) does not restart the count.
    strobe.on();
    time.set(800);
    assert_eq!(strobe.lit_for_us(), 750);
}

#[test]
fn a_dark_strobe_lights_nothing() {
    let (_, clock, mut laser) = fakes();
    let switches = laser.switches.clone();
    let strobe = Strobe::new(&mut laser, &clock, 0);
    strobe.on();
    assert!(!strobe.is_lit());
    drop(strobe);
    assert!(switches.borrow().iter().all(|&(_, m)| m == 0));
}

#[test]
fn on_after_trip_lights_nothing() {
    let (time, clock, mut laser) = fakes();
    let switches = laser.switches.clone();
    {
        let strobe = Strobe::new(&mut laser, &clock, 0b11);
        strobe.on();
        time.set(20_000);
        strobe.trip();
        assert!(strobe.tripped());
        assert!(!strobe.is_lit());
        assert_eq!(last_mask(&switches), 0, "trip() switches the lasers off");
        let after_trip = switches.borrow().len();
        strobe.on();
        assert!(!strobe.is_lit());
        assert_eq!(strobe.lit_for_us(), 0);
        assert_eq!(
            switches.borrow().len(),
            after_trip,
            "on() after trip() switched a laser"
        );
    }
    assert_eq!(last_mask(&switches), 0);
}

#[test]
fn dropping_a_lit_strobe_switches_the_lasers_off() {
    let (_, clock, mut laser) = fakes();
    let switches = laser.switches.clone();
    let strobe = Strobe::new(&mut laser, &clock, 0b10);
    strobe.on();
    assert_eq!(last_mask(&switches), 0b10);
    drop(strobe);
    assert_eq!(last_mask(&switches), 0);
}

#[test]
fn every_way_a_capture_ends_leaves_the_lasers_off() {
    // A driver future lights the strobe and then finishes, fails, or is cancelled (dropped
    // while pending, as the guard's `select` does): the lasers are off afterwards each time.
    for ending in ["finishes", "fails", "cancelled"] {
        let (_, clock, mut laser) = fakes();
        let switches = laser.switches.clone();
        {
            let strobe = Strobe::new(&mut laser, &clock, 0b11);
            let capture = async {
                strobe.on();
                match ending {
                    "finishes" => {
                        clock.delay_us(1_000).await;
                        strobe.off();
                        Ok(())
                    }
                    "fails" => {
                        clock.delay_us(500).await;
                        Err(())
                    }
                    _ => core::future::pending().await,
                }
            };
            let outcome = poll_bounded(capture, 10);
            assert_eq!(outcome.is_none(), ending == "cancelled", "{ending}");
        }
        let switches = switches.borrow();
        assert!(
            switches.iter().any(|&(_, m)| m == 0b11),
            "{ending}: never lit"
        );
        assert_eq!(
            switches.last().map(|s| s.1),
            Some(0),
            "{ending}: {switches:?}"
        );
    }
}
