//! The scripted and recorded pins, in virtual time (the workspace's 1 kHz tick).

use embassy_time::{Duration, Instant, Timer};
use embedded_hal::digital::{InputPin, OutputPin, StatefulOutputPin};
use embedded_hal::pwm::SetDutyCycle;
use embedded_hal_async::digital::Wait;
use psmpa_testkit::pins::{DutyAboveMax, RecordedPin, RecordedPwm, ScriptedPin};
use psmpa_testkit::sim::{SimError, simulate};

fn ms(t: u64) -> Instant {
    Instant::from_millis(t)
}

#[test]
fn a_scripted_level_follows_its_edges_and_an_edge_to_the_same_level_is_no_change() {
    let pin = ScriptedPin::new(false, &[(10, true), (20, true), (30, false)]);
    assert!(!pin.level_at(ms(9)));
    assert!(pin.level_at(ms(10)));
    assert!(pin.level_at(ms(29)));
    assert!(!pin.level_at(ms(30)));
    assert_eq!(pin.next_change(ms(0)), Some(ms(10)));
    assert_eq!(pin.next_change(ms(10)), Some(ms(30)));
    assert_eq!(pin.next_change(ms(30)), None);
}

#[test]
fn waits_end_at_the_scripts_edges_and_reads_are_recorded() {
    let pin = ScriptedPin::new(true, &[(5, false), (7, true), (12, false), (15, true)]);
    let mut p = pin.clone();
    let done = simulate(
        async move {
            let mut at = Vec::new();
            // Already high: at once.
            p.wait_for_high().await.unwrap();
            at.push(Instant::now());
            // The next rising edge, not the current level.
            p.wait_for_rising_edge().await.unwrap();
            at.push(Instant::now());
            p.wait_for_falling_edge().await.unwrap();
            at.push(Instant::now());
            p.wait_for_any_edge().await.unwrap();
            at.push(Instant::now());
            let high = p.is_high().unwrap();
            Timer::after(Duration::from_millis(1)).await;
            let low = p.is_low().unwrap();
            (at, high, low)
        },
        Duration::from_secs(1),
    )
    .unwrap();
    assert_eq!(
        done.output,
        (vec![ms(0), ms(7), ms(12), ms(15)], true, false)
    );
    assert_eq!(pin.reads(), [ms(15), ms(16)]);
}

#[test]
fn a_wait_past_the_last_edge_never_ends() {
    let mut pin = ScriptedPin::constant(false);
    let result = simulate(
        async move { pin.wait_for_high().await },
        Duration::from_secs(1),
    );
    assert!(
        matches!(result, Err(SimError::Deadlock { .. })),
        "{result:?}"
    );
}

#[test]
#[should_panic(expected = "time order")]
fn edges_out_of_order_are_refused() {
    ScriptedPin::new(false, &[(10, true), (5, false)]);
}

#[test]
fn a_recorded_pin_keeps_every_write_and_its_edges() {
    let pin = RecordedPin::new();
    let mut p = pin.clone();
    simulate(
        async move {
            p.set_low().unwrap();
            p.set_high().unwrap();
            Timer::after(Duration::from_millis(3)).await;
            p.set_high().unwrap();
            p.set_low().unwrap();
            p.is_set_low().unwrap()
        },
        Duration::from_secs(1),
    )
    .map(|done| assert!(done.output))
    .unwrap();
    assert_eq!(
        pin.log(),
        [(ms(0), false), (ms(0), true), (ms(3), true), (ms(3), false)]
    );
    assert_eq!(pin.edges(), [(ms(0), false), (ms(0), true), (ms(3), false)]);
    assert_eq!(pin.level_at(ms(2)), Some(true));
    assert_eq!(pin.level(), Some(false));
    assert_eq!(RecordedPin::new().level(), None);
}

#[test]
fn a_recorded_pwm_keeps_the_duties_and_refuses_one_above_its_maximum() {
    let pwm = RecordedPwm::new(100);
    let mut p = pwm.clone();
    simulate(
        async move {
            p.set_duty_cycle_percent(40).unwrap();
            Timer::after(Duration::from_millis(2)).await;
            assert_eq!(
                p.set_duty_cycle(101),
                Err(DutyAboveMax {
                    duty: 101,
                    max: 100
                })
            );
            p.set_duty_cycle_fully_on().unwrap();
        },
        Duration::from_secs(1),
    )
    .unwrap();
    assert_eq!(pwm.log(), [(ms(0), 40), (ms(2), 100)]);
    assert_eq!(pwm.duty_at(ms(1)), Some(40));
    assert_eq!(pwm.duty(), Some(100));
}
