//! The ultrasonic ranger's driver on a recorded trigger and a scripted echo, in virtual time.
//!
//! At the tests' 1 kHz tick the 10 µs trigger pulse lasts one tick: a read started at 0 ms
//! raises the trigger at 0 and drops it at 1 ms. Echo widths are whole milliseconds, so a
//! pulse from 2 ms to 8 ms is 6 ms: 6,000 µs × 343 / 2,000 = 1,029 mm.

use embassy_time::{Duration, Instant};
use psmpa_drivers::hcsr04::{
    Hcsr04, Hcsr04Error, MAX_MM, MIN_MM, PULSE_LIMIT, RISE_TIMEOUT, Range, mm_from_echo_us,
    range_from_echo_us,
};
use psmpa_testkit::pins::{RecordedPin, ScriptedPin};
use psmpa_testkit::sim::simulate;

/// One read at 0 ms against `echo`: what it found, when it returned, and the trigger's writes.
fn read(echo: ScriptedPin) -> (Result<Range, Hcsr04Error>, u64, Vec<(u64, bool)>) {
    let trigger = RecordedPin::new();
    let mut sonar = Hcsr04::new(trigger.clone(), echo);
    let done = simulate(
        async {
            let range = sonar.measure().await;
            (range, Instant::now().as_millis())
        },
        Duration::from_secs(1),
    )
    .unwrap();
    let writes = trigger
        .log()
        .iter()
        .map(|(at, level)| (at.as_millis(), *level))
        .collect();
    (done.output.0, done.output.1, writes)
}

/// An echo that rises at 2 ms (1 ms after the trigger falls) and lasts `ms`.
fn pulse(ms: u64) -> ScriptedPin {
    ScriptedPin::new(false, &[(2, true), (2 + ms, false)])
}

#[test]
fn echo_widths_become_distances_at_343_m_s() {
    // width_us * 343 / 2000, in whole milliseconds of width.
    for (ms, mm) in [(1, 171), (6, 1_029), (12, 2_058), (23, 3_944)] {
        let (range, ended, _) = read(pulse(ms));
        assert_eq!(range, Ok(Range::Mm(mm)), "a {ms} ms echo");
        // The read ends when the echo falls: it waited, it did not give up early.
        assert_eq!(ended, 2 + ms);
    }
}

#[test]
fn a_read_pulses_the_trigger_for_at_least_10_us_before_listening() {
    let (_, _, writes) = read(pulse(6));
    // Low first (a cancelled read may have left it high), high at 0, low one tick later.
    assert_eq!(writes, [(0, false), (0, true), (1, false)]);
}

#[test]
fn beyond_4_m_and_the_modules_38_ms_no_echo_pulse_are_nothing_in_range() {
    // 24 ms is 4,116 mm, past the rated 4 m; 38 ms is the module's own "no echo" pulse.
    for ms in [24, 30, 38] {
        let (range, ended, _) = read(pulse(ms));
        assert_eq!(range, Ok(Range::NothingInRange), "a {ms} ms echo");
        assert_eq!(ended, 2 + ms);
    }
}

#[test]
fn an_echo_that_never_rises_is_no_echo_after_the_rise_timeout() {
    let (range, ended, _) = read(ScriptedPin::constant(false));
    assert_eq!(range, Err(Hcsr04Error::NoEcho));
    // The trigger falls at 1 ms; the driver waits RISE_TIMEOUT for the rise, no longer.
    assert_eq!(ended, 1 + RISE_TIMEOUT.as_millis());
}

#[test]
fn an_echo_that_rises_late_is_no_echo_too() {
    let late = 1 + RISE_TIMEOUT.as_millis() + 1;
    let (range, _, _) = read(ScriptedPin::new(false, &[(late, true), (late + 6, false)]));
    assert_eq!(range, Err(Hcsr04Error::NoEcho));
}

#[test]
fn an_echo_high_for_the_pulse_limit_before_the_trigger_is_busy_and_nothing_is_triggered() {
    let (range, ended, writes) = read(ScriptedPin::constant(true));
    assert_eq!(range, Err(Hcsr04Error::Busy));
    assert_eq!(ended, PULSE_LIMIT.as_millis());
    assert_eq!(writes, []);
}

#[test]
fn a_pulse_still_running_is_waited_out_before_the_trigger() {
    // A cancelled read's 38 ms pulse ends at 20 ms; this read triggers then and measures.
    let echo = ScriptedPin::new(true, &[(20, false), (22, true), (28, false)]);
    let (range, ended, writes) = read(echo);
    assert_eq!(range, Ok(Range::Mm(1_029)));
    assert_eq!(ended, 28);
    assert_eq!(writes, [(20, false), (20, true), (21, false)]);
}

#[test]
fn an_echo_that_never_falls_is_stuck_after_the_pulse_limit() {
    let (range, ended, _) = read(ScriptedPin::new(false, &[(2, true)]));
    assert_eq!(range, Err(Hcsr04Error::Stuck));
    assert_eq!(ended, 2 + PULSE_LIMIT.as_millis());
}

#[test]
fn reads_follow_each_other_on_one_driver() {
    // Two pulses: one answering a read at 0 ms, one answering a read at 50 ms.
    let echo = ScriptedPin::new(false, &[(2, true), (8, false), (52, true), (64, false)]);
    let trigger = RecordedPin::new();
    let mut sonar = Hcsr04::new(trigger, echo);
    let done = simulate(
        async {
            let first = sonar.measure().await;
            embassy_time::Timer::at(Instant::from_millis(50)).await;
            (first, sonar.measure().await)
        },
        Duration::from_secs(1),
    )
    .unwrap();
    assert_eq!(done.output, (Ok(Range::Mm(1_029)), Ok(Range::Mm(2_058))));
}

/// At 1 kHz a pulse is at least 1 ms (171 mm): the limits at the low end are checked on the
/// conversion itself, in microseconds, as a 1 MHz board measures them.
#[test]
fn the_conversion_bounds_the_rated_range_in_microseconds() {
    assert_eq!(mm_from_echo_us(6_000), 1_029);
    // 117 µs is 20.06 mm: the minimum; 116 µs is 19.89 mm: too near to measure.
    assert_eq!(range_from_echo_us(116), Err(Hcsr04Error::OutOfRange));
    assert_eq!(range_from_echo_us(117), Ok(Range::Mm(MIN_MM as u16)));
    assert_eq!(range_from_echo_us(0), Err(Hcsr04Error::OutOfRange));
    // 23,324 µs is 4,000.07 mm: the maximum; 23,330 µs is 4,001 mm: out of range, so nothing.
    assert_eq!(range_from_echo_us(23_324), Ok(Range::Mm(MAX_MM as u16)));
    assert_eq!(range_from_echo_us(23_330), Ok(Range::NothingInRange));
    // No overflow for absurd widths.
    assert_eq!(range_from_echo_us(u64::MAX), Ok(Range::NothingInRange));
}

#[test]
fn a_module_that_answers_later_is_read_with_its_own_rise_timeout() {
    // The echo rises 20 ms after the trigger falls: past the default rise timeout.
    let late = || ScriptedPin::new(false, &[(21, true), (27, false)]);
    let (range, ended, _) = read(late());
    assert_eq!(range, Err(Hcsr04Error::NoEcho));
    assert_eq!(ended, 1 + RISE_TIMEOUT.as_millis());
    // Given 25 ms to rise, the same echo is 1,029 mm.
    let trigger = RecordedPin::new();
    let mut sonar = Hcsr04::new(trigger, late()).with_rise_timeout(Duration::from_millis(25));
    let done = simulate(sonar.measure(), Duration::from_secs(1)).unwrap();
    assert_eq!(done.output, Ok(Range::Mm(1_029)));
}
