//! The world's events as the firmware logs them: four small numbers each, one defmt line
//! (`w MS KIND A B VALUE`). `cargo xtask qemu` turns them back into events, and those into
//! the text of `scenarios/traces/`. One table for both directions, so the two cannot drift;
//! a new kind of event fails to compile here until it has its numbers.

use psmpa_sim::scenario::Kind;
use psmpa_sim::world::{Device, Place, WorldEvent};

/// One event in numbers; fields an event does not have are 0.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Fields {
    /// Which kind of event.
    pub kind: u8,
    /// A device, an obstacle's index, a door or a flag.
    pub a: u8,
    /// A second small field: a device, a box (0) or a ball (1), or whether an index is given.
    pub b: u8,
    /// A reading, a position (µm), a time (ms) or a speed.
    pub value: i64,
}

fn device(d: Device) -> u8 {
    match d {
        Device::Sonar => 0,
        Device::Bumper => 1,
        Device::Camera => 2,
        Device::Handle => 3,
    }
}

fn place(p: Place) -> u8 {
    match p {
        Place::KitchenDoor => 0,
        Place::BackDoor => 1,
    }
}

/// The numbers of `e`.
pub fn encode(e: &WorldEvent) -> Fields {
    let f = |kind, a, b, value| Fields { kind, a, b, value };
    let index = |i: Option<u8>| i.map_or((0, 0), |i| (i, 1));
    match *e {
        WorldEvent::SensorOn(d) => f(0, device(d), 0, 0),
        WorldEvent::SensorOff(d) => f(1, device(d), 0, 0),
        WorldEvent::Sample(d, v) => f(2, device(d), 0, i64::from(v)),
        WorldEvent::SampleLost(d) => f(3, device(d), 0, 0),
        WorldEvent::Appeared { index, kind, at_um } => {
            f(4, index, u8::from(kind == Kind::Ball), at_um)
        }
        WorldEvent::Removed(i) => f(5, i, 0, 0),
        WorldEvent::Skipped(i) => f(6, i, 0, 0),
        WorldEvent::Detected(i, d) => f(7, i, device(d), 0),
        WorldEvent::Collided(i) => f(8, i, 0, 0),
        WorldEvent::Reacted(i, ms) => f(9, i, 0, i64::try_from(ms).unwrap_or(i64::MAX)),
        WorldEvent::Walk => f(10, 0, 0, 0),
        WorldEvent::Stop => f(11, 0, 0, 0),
        WorldEvent::AvoidStarted(i) => {
            let (a, b) = index(i);
            f(12, a, b, 0)
        }
        WorldEvent::AvoidDone(i) => {
            let (a, b) = index(i);
            f(13, a, b, 0)
        }
        WorldEvent::Held(h) => f(14, u8::from(h), 0, 0),
        WorldEvent::Arrived(p) => f(15, place(p), 0, 0),
        WorldEvent::DoorOpened(p) => f(16, place(p), 0, 0),
        WorldEvent::Locked => f(17, 0, 0, 0),
        WorldEvent::InKitchen => f(18, 0, 0, 0),
        WorldEvent::Speed(s) => f(19, 0, 0, i64::from(s)),
    }
}

/// The event of `f`, or `None` when no event has these numbers.
pub fn decode(f: Fields) -> Option<WorldEvent> {
    let device = |n| match n {
        0 => Some(Device::Sonar),
        1 => Some(Device::Bumper),
        2 => Some(Device::Camera),
        3 => Some(Device::Handle),
        _ => None,
    };
    let place = |n| match n {
        0 => Some(Place::KitchenDoor),
        1 => Some(Place::BackDoor),
        _ => None,
    };
    let index = match f.b {
        0 => None,
        _ => Some(f.a),
    };
    Some(match f.kind {
        0 => WorldEvent::SensorOn(device(f.a)?),
        1 => WorldEvent::SensorOff(device(f.a)?),
        2 => WorldEvent::Sample(device(f.a)?, u32::try_from(f.value).ok()?),
        3 => WorldEvent::SampleLost(device(f.a)?),
        4 => WorldEvent::Appeared {
            index: f.a,
            kind: match f.b {
                0 => Kind::Box,
                1 => Kind::Ball,
                _ => return None,
            },
            at_um: f.value,
        },
        5 => WorldEvent::Removed(f.a),
        6 => WorldEvent::Skipped(f.a),
        7 => WorldEvent::Detected(f.a, device(f.b)?),
        8 => WorldEvent::Collided(f.a),
        9 => WorldEvent::Reacted(f.a, u64::try_from(f.value).ok()?),
        10 => WorldEvent::Walk,
        11 => WorldEvent::Stop,
        12 => WorldEvent::AvoidStarted(index),
        13 => WorldEvent::AvoidDone(index),
        14 => WorldEvent::Held(match f.a {
            0 => false,
            1 => true,
            _ => return None,
        }),
        15 => WorldEvent::Arrived(place(f.a)?),
        16 => WorldEvent::DoorOpened(place(f.a)?),
        17 => WorldEvent::Locked,
        18 => WorldEvent::InKitchen,
        19 => WorldEvent::Speed(u16::try_from(f.value).ok()?),
        _ => return None,
    })
}
