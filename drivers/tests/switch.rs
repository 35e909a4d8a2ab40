//! The debounced switch on scripted, bouncing pins, in virtual time (1 kHz: edges fall on
//! whole milliseconds).

use embassy_time::{Duration, Instant, Timer};
use psmpa_drivers::Active;
use psmpa_drivers::switch::{DEBOUNCE, Switch};
use psmpa_testkit::pins::ScriptedPin;
use psmpa_testkit::sim::simulate;

/// A switch to ground (pressed: low) that bounces for 4 ms when pressed at 100 ms and for
/// 2 ms when released at 300 ms.
fn bouncing() -> ScriptedPin {
    ScriptedPin::new(
        true,
        &[
            (100, false),
            (101, true),
            (102, false),
            (103, true),
            (104, false),
            (300, true),
            (301, false),
            (302, true),
        ],
    )
}

/// The instants at which the accepted state changed, and to what.
fn changes(states: &[(u64, bool)]) -> Vec<(u64, bool)> {
    let mut last = false;
    let mut out = Vec::new();
    for &(at, pressed) in states {
        if pressed != last {
            out.push((at, pressed));
            last = pressed;
        }
    }
    out
}

/// Reads `switch` every `every` ms until 400 ms: (instant of each read's end, state).
fn poll(pin: ScriptedPin, active: Active, debounce: Duration, every: u64) -> Vec<(u64, bool)> {
    let mut switch = Switch::new(pin, active, debounce);
    simulate(
        async move {
            let mut states = Vec::new();
            while Instant::now().as_millis() < 400 {
                let pressed = switch.pressed().await.unwrap();
                states.push((Instant::now().as_millis(), pressed));
                Timer::after(Duration::from_millis(every)).await;
            }
            states
        },
        Duration::from_secs(1),
    )
    .unwrap()
    .output
}

#[test]
fn a_bouncing_switch_gives_one_contact_and_one_release() {
    // Without debouncing, reads every millisecond see four contacts (one in the release's
    // bounce).
    let pin = bouncing();
    let raw: Vec<(u64, bool)> = (0..400)
        .map(|ms| (ms, !pin.level_at(Instant::from_millis(ms))))
        .collect();
    assert_eq!(changes(&raw).iter().filter(|(_, p)| *p).count(), 4);
    // Debounced: one contact, accepted once the level held for DEBOUNCE after the last bounce
    // (104 ms), and one release, once it held after 302 ms.
    let states = poll(bouncing(), Active::Low, DEBOUNCE, 1);
    let d = DEBOUNCE.as_millis();
    assert_eq!(changes(&states), [(104 + d, true), (302 + d, false)]);
}

#[test]
fn reads_on_the_bumpers_20_ms_period_give_one_contact_too() {
    // A read at 100 ms sees the press and watches the pin: the bounce at 101 ms rejects it.
    // The next read, at 120 ms (the period counts from the previous read's start), accepts.
    let mut switch = Switch::new(bouncing(), Active::Low, DEBOUNCE);
    let states = simulate(
        async move {
            let mut states = Vec::new();
            let mut due = Instant::from_millis(0);
            while due.as_millis() < 400 {
                Timer::at(due).await;
                states.push((due.as_millis(), switch.pressed().await.unwrap()));
                due += Duration::from_millis(20);
            }
            states
        },
        Duration::from_secs(1),
    )
    .unwrap()
    .output;
    assert_eq!(changes(&states), [(120, true), (320, false)]);
}

#[test]
fn reading_at_each_edge_gives_one_contact() {
    // The pattern of a sensor woken by the switch's edges: await an edge, read.
    let mut switch = Switch::new(bouncing(), Active::Low, DEBOUNCE);
    let states = simulate(
        async move {
            let mut states = Vec::new();
            // Four edges come out of the script's eight (a fifth wait would never end): the
            // read at 100 ms sees the bounce at 101 ms; the edge at 102 ms comes within the
            // debounce time of the one at 100 ms, so it is returned at 105 ms, and that read
            // sees the level hold from 104 ms. The same at 300 ms.
            for _ in 0..4 {
                switch.edge().await.unwrap();
                let pressed = switch.pressed().await.unwrap();
                states.push((Instant::now().as_millis(), pressed));
            }
            states
        },
        Duration::from_secs(1),
    )
    .unwrap()
    .output;
    let d = DEBOUNCE.as_millis();
    assert_eq!(
        states,
        [(101, false), (105 + d, true), (301, true), (305 + d, false)]
    );
}

#[test]
fn a_chattering_line_gives_at_most_one_edge_a_debounce_time() {
    // Noise on the line: an edge every millisecond for 100 ms. Each edge would ask for a read.
    let noise: Vec<(u64, bool)> = (1..=100).map(|ms| (ms, ms % 2 == 0)).collect();
    let mut switch = Switch::new(ScriptedPin::new(true, &noise), Active::Low, DEBOUNCE);
    let edges = simulate(
        async move {
            let mut edges = Vec::new();
            while Instant::now().as_millis() < 100 {
                switch.edge().await.unwrap();
                edges.push(Instant::now().as_millis());
            }
            edges
        },
        Duration::from_secs(1),
    )
    .unwrap()
    .output;
    // The first at once, then one a debounce time: 1, 6, 11, ..., 101.
    let d = DEBOUNCE.as_millis();
    let expected: Vec<u64> = (0..=100 / d).map(|i| 1 + i * d).collect();
    assert_eq!(edges, expected);
}

#[test]
fn a_one_off_read_waits_the_bounces_out() {
    // Read once at 101 ms, in the press's bounce, when the pin shows "released" for a moment:
    // `pressed` returns the old state at once, `settled` the contact once it held.
    let read = |settled: bool| {
        let mut switch = Switch::new(bouncing(), Active::Low, DEBOUNCE);
        simulate(
            async move {
                Timer::at(Instant::from_millis(101)).await;
                let pressed = if settled {
                    switch.settled().await
                } else {
                    switch.pressed().await
                };
                (pressed.unwrap(), switch.last())
            },
            Duration::from_secs(1),
        )
        .unwrap()
    };
    let quick = read(false);
    assert_eq!(
        (quick.output, quick.elapsed.as_millis()),
        ((false, false), 101)
    );
    let settled = read(true);
    let d = DEBOUNCE.as_millis();
    assert_eq!(
        (settled.output, settled.elapsed.as_millis()),
        ((true, true), 104 + d)
    );
}

#[test]
fn a_glitch_shorter_than_the_debounce_time_is_no_contact() {
    // Active high, 10 ms debounce: a 6 ms pulse at 50 ms is noise; a press at 200 ms is not.
    let pin = ScriptedPin::new(false, &[(50, true), (56, false), (200, true)]);
    let states = poll(pin, Active::High, Duration::from_millis(10), 1);
    assert_eq!(changes(&states), [(210, true)]);
}

#[test]
fn an_unchanged_level_is_read_at_once() {
    let mut switch = Switch::new(ScriptedPin::constant(true), Active::Low, DEBOUNCE);
    let done = simulate(
        async move { (switch.pressed().await, switch.last()) },
        Duration::from_secs(1),
    )
    .unwrap();
    assert_eq!(done.output, (Ok(false), false));
    assert_eq!(done.elapsed, Duration::from_ticks(0));
}
