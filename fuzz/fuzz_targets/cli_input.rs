//! Any bytes as a scenario or mission file, through the entry points `psmpa-sim run` and
//! `psmpa-sim check` use: a result, or an error of one non-empty line with no control
//! character, never a panic. What strict JSON accepts, it decodes to strict JSON again, which
//! needs no more decoding.
#![no_main]

use std::borrow::Cow;
use std::path::Path;

use libfuzzer_sys::fuzz_target;
use psmpa_sim::cli::check::check_bytes;
use psmpa_sim::json::strict;
use psmpa_sim::load::parse;

fn one_line(message: &str) {
    assert!(!message.is_empty());
    assert!(!message.chars().any(char::is_control), "{message:?}");
}

fuzz_target!(|data: &[u8]| {
    let file = Path::new("fuzz.json");
    if let Err(e) = parse(file, data) {
        one_line(&e.to_string());
    }
    for any_platform in [false, true] {
        if let Err(message) = check_bytes(file, data, any_platform) {
            one_line(&message);
        }
    }
    match strict(data) {
        Ok(doc) => {
            let again = strict(&doc).expect("decoded JSON is strict JSON");
            assert!(
                matches!(again, Cow::Borrowed(_)),
                "decoding twice changes nothing"
            );
            let lines = |b: &[u8]| b.iter().filter(|c| **c == b'\n').count();
            assert_eq!(lines(&doc), lines(data), "decoding keeps the lines");
        }
        Err(e) => one_line(&e.to_string()),
    }
});
