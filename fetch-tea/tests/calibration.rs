//! The calibration record a board keeps its `Settings` in: what it takes, and what it refuses.

use embassy_time::Duration;
use psmpa_fetch_tea::{RECORD_MAGIC, RECORD_VERSION, RECORD_WORDS, RecordError, Settings, crc32};

/// A record with word `i` set to `value` and its checksum made good again.
fn with(mut record: [u32; RECORD_WORDS], i: usize, value: u32) -> [u32; RECORD_WORDS] {
    record[i] = value;
    record[RECORD_WORDS - 1] = crc32(&record[..RECORD_WORDS - 1]);
    record
}

#[test]
fn the_checksum_is_zlibs_crc32() {
    // CRC-32 of the bytes "abcd", as zlib and every CRC-32 table give it.
    assert_eq!(crc32(&[u32::from_le_bytes(*b"abcd")]), 0xED82_CD11);
    assert_eq!(crc32(&[]), 0);
}

#[test]
fn settings_survive_their_record() {
    assert_eq!(
        Settings::from_record(&Settings::DEFAULT.to_record()),
        Ok(Settings::DEFAULT)
    );
    let bench = Settings {
        clearance_mm: 500,
        walk_mm: 1_500,
        walk_permille: -600,
        walk_mm_s: 100,
        plan: Duration::from_micros(50_000),
        sonar_period: Some(Duration::from_millis(50)),
        bumper_period: Some(Duration::from_millis(10)),
        avoid: Duration::from_millis(1_500),
        sonar_rise: Duration::from_millis(45),
        back_door_mm: 2_500,
        ..Settings::DEFAULT
    };
    let record = bench.to_record();
    assert_eq!(record[0], RECORD_MAGIC);
    assert_eq!(record[1], RECORD_VERSION);
    assert_eq!(Settings::from_record(&record), Ok(bench));
}

#[test]
fn a_record_that_is_not_one_is_refused_with_its_reason() {
    let good = Settings::DEFAULT.to_record();
    // Erased flash, and a RAM or an emulator's flash of zeros.
    assert_eq!(
        Settings::from_record(&[u32::MAX; RECORD_WORDS]),
        Err(RecordError::Blank)
    );
    assert_eq!(
        Settings::from_record(&[0; RECORD_WORDS]),
        Err(RecordError::Blank)
    );
    assert_eq!(
        Settings::from_record(&with(good, 0, 0x1234_5678)),
        Err(RecordError::Magic)
    );
    // Version 2 had no back door (version 1 no side step either): each is shorter.
    assert_eq!(
        Settings::from_record(&with(good, 1, 2)),
        Err(RecordError::Version(2))
    );
    assert_eq!(
        RecordError::Version(2).to_string(),
        "a calibration record of version 2, this firmware reads version 3"
    );
    // One bit flipped anywhere, the checksum included, is caught.
    for i in 0..RECORD_WORDS {
        let mut damaged = good;
        damaged[i] ^= 1 << (i % 32);
        assert!(Settings::from_record(&damaged).is_err(), "word {i}");
        if i >= 2 {
            assert_eq!(
                Settings::from_record(&damaged),
                Err(RecordError::Checksum),
                "word {i}"
            );
        }
    }
}

#[test]
fn settings_out_of_range_are_refused() {
    let good = Settings::DEFAULT.to_record();
    // Word 5: the walking speed; 4: the walking duty; 2: the clearance.
    assert_eq!(
        Settings::from_record(&with(good, 5, 0)),
        Err(RecordError::Invalid)
    );
    assert_eq!(
        Settings::from_record(&with(good, 4, 1_001)),
        Err(RecordError::Invalid)
    );
    assert_eq!(
        Settings::from_record(&with(good, 4, -1_001i32 as u32)),
        Err(RecordError::Invalid)
    );
    assert_eq!(
        Settings::from_record(&with(good, 2, 70_000)),
        Err(RecordError::Invalid)
    );
    assert_eq!(
        Settings::from_record(&with(good, 4, -1_000i32 as u32)).map(|s| s.walk_permille),
        Ok(-1_000)
    );
}
