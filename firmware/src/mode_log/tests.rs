//! The mode log on a RAM sector with real flash's faults (`crate::fakes::RamSector`): a
//! power cycle keeps the mode, torn and damaged words are skipped and never programmed
//! again, a full sector is erased and the log continues.

use super::*;
use crate::fakes::RamSector;

/// A log on `sector` as after a power cycle: built and loaded afresh.
fn boot(sector: &RamSector) -> (ModeLog<RamSector>, ModeStoreState) {
    let mut log = ModeLog::new(sector.clone());
    let state = log.load();
    (log, state)
}

#[test]
fn an_erased_sector_is_empty_and_each_change_survives_a_power_cycle() {
    let sector = RamSector::new(8);
    let (mut log, state) = boot(&sector);
    assert_eq!(state, ModeStoreState::Empty);
    for mode in [Mode::Sphere, Mode::Wall, Mode::Cylinder, Mode::Road] {
        log.save(mode).unwrap();
        let (again, state) = boot(&sector);
        assert_eq!(state, ModeStoreState::Loaded(mode));
        log = again;
    }
    assert_eq!(log.next_free(), 4, "one word per change, appended");
    assert_eq!(sector.0.borrow().erases, 0);
}

#[test]
fn a_torn_word_is_skipped_and_never_programmed_again() {
    let sector = RamSector::new(8);
    let (mut log, _) = boot(&sector);
    log.save(Mode::Sphere).unwrap();
    // Power cut while the next change is programmed, for every length of the torn write.
    for torn in 1..WORD {
        sector.0.borrow_mut().words.truncate(0);
        sector.0.borrow_mut().words.resize(8, [ERASED; WORD]);
        let (mut log, _) = boot(&sector);
        log.save(Mode::Sphere).unwrap();
        sector.0.borrow_mut().tear_next_program = Some(torn);
        assert!(log.save(Mode::Road).is_err());
        let (mut log, state) = boot(&sector);
        assert_eq!(
            state,
            ModeStoreState::Loaded(Mode::Sphere),
            "torn after {torn} bytes: the unacknowledged change is not taken"
        );
        assert_eq!(log.next_free(), 2, "the torn word stays used");
        log.save(Mode::Wall).unwrap();
        assert_eq!(boot(&sector).1, ModeStoreState::Loaded(Mode::Wall));
        assert!(!sector.0.borrow().programmed_twice);
    }
}

#[test]
fn damaged_and_unreadable_words_give_the_default_with_the_reason() {
    let sector = RamSector::new(4);
    sector.0.borrow_mut().words[1] = [0x00; WORD];
    let (mut log, state) = boot(&sector);
    assert_eq!(state, ModeStoreState::Corrupt);
    assert_eq!(log.next_free(), 2, "the next record goes after the damage");

    sector.0.borrow_mut().unreadable = Some(2);
    assert_eq!(boot(&sector).1, ModeStoreState::Unreadable(7));
    // A valid record before an unreadable word still gives the mode.
    sector.0.borrow_mut().unreadable = None;
    log.save(Mode::Sphere).unwrap();
    sector.0.borrow_mut().unreadable = Some(3);
    assert_eq!(boot(&sector).1, ModeStoreState::Loaded(Mode::Sphere));

    // A record of a mode number this firmware does not know.
    let sector = RamSector::new(4);
    let mut w = record::encode(Mode::Road);
    w[5] = 9;
    let crc = CRC32.checksum(&w[..WORD - 4]);
    w[WORD - 4..].copy_from_slice(&crc.to_le_bytes());
    sector.0.borrow_mut().words[0] = w;
    assert_eq!(boot(&sector).1, ModeStoreState::Unusable(9));
}

#[test]
fn a_full_sector_is_erased_once_and_the_log_continues() {
    let n = 6;
    let sector = RamSector::new(n);
    let (mut log, _) = boot(&sector);
    let modes = [Mode::Sphere, Mode::Wall, Mode::Road, Mode::Cylinder];
    for i in 0..n {
        log.save(modes[i % 4]).unwrap();
    }
    assert_eq!(log.next_free(), n);
    assert_eq!(
        sector.0.borrow().erases,
        0,
        "no erase before the sector is full"
    );
    let (mut log, state) = boot(&sector);
    assert_eq!(state, ModeStoreState::Loaded(modes[(n - 1) % 4]));
    assert_eq!(
        log.next_free(),
        n,
        "a full sector is seen full after a power cycle"
    );
    log.save(Mode::Road).unwrap();
    assert_eq!(sector.0.borrow().erases, 1);
    assert_eq!(log.next_free(), 1);
    assert_eq!(boot(&sector).1, ModeStoreState::Loaded(Mode::Road));
    assert!(!sector.0.borrow().programmed_twice);
}

#[test]
fn a_power_cut_between_erase_and_program_leaves_an_empty_log() {
    let sector = RamSector::new(2);
    let (mut log, _) = boot(&sector);
    log.save(Mode::Sphere).unwrap();
    log.save(Mode::Wall).unwrap();
    sector.0.borrow_mut().tear_next_program = Some(0);
    assert!(log.save(Mode::Road).is_err());
    assert_eq!(sector.0.borrow().erases, 1);
    assert_eq!(boot(&sector).1, ModeStoreState::Empty);
}

#[test]
fn every_single_bit_error_in_a_record_is_detected() {
    for mode in Mode::ALL {
        let good = record::encode(mode);
        assert_eq!(record::decode(&good), record::Word::Record(number_of(mode)));
        for bit in 0..WORD * 8 {
            let mut w = good;
            w[bit / 8] ^= 1 << (bit % 8);
            assert_eq!(record::decode(&w), record::Word::Damaged, "bit {bit}");
        }
    }
    assert_eq!(record::decode(&[ERASED; WORD]), record::Word::Erased);
}

#[test]
fn a_refused_program_is_a_board_code_and_a_sector_without_words_refuses() {
    let sector = RamSector::new(3);
    let (mut log, _) = boot(&sector);
    sector.0.borrow_mut().refuse_programs = true;
    assert_eq!(log.save(Mode::Sphere), Err(4));
    sector.0.borrow_mut().refuse_programs = false;
    assert_eq!(boot(&sector).1, ModeStoreState::Empty);
    let (mut none, state) = boot(&RamSector::new(0));
    assert_eq!(state, ModeStoreState::Empty);
    assert_eq!(none.save(Mode::Sphere), Err(codes::NO_SECTOR));
}
