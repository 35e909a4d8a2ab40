//! A bench run as a picture: the pins over time (the sonar's trigger and echo, the bump
//! switch, the marker and the handle, the H-bridge's STBY, direction pins and duties) beside
//! the world's events (an obstacle put down and taken away, detected, collided with; the
//! robot at the door) and the firmware's resets. One SVG a run, `target/hil/NAME.svg`.

use std::fmt::Write as _;
use std::path::Path;

use psmpa_sim::world::WorldEvent;

use super::{PinLog, Report};

const WIDTH: f64 = 1400.0;
const LEFT: f64 = 110.0;
const RIGHT: f64 = 40.0;
const LANE: f64 = 26.0;

/// The lanes: a label and the pin log's name for it.
const LANES: [(&str, &str); 12] = [
    ("trigger GP2", "out2"),
    ("echo GP3", "in3"),
    ("bumper GP4", "in4"),
    ("marker GP5", "in5"),
    ("handle GP6", "in6"),
    ("STBY GP9", "out9"),
    ("left IN1", "out10"),
    ("left IN2", "out11"),
    ("left duty", "duty12"),
    ("right IN1", "out13"),
    ("right IN2", "out14"),
    ("right duty", "duty15"),
];

/// Writes `report`'s run as an SVG to `path`.
pub fn write(path: &Path, report: &Report, pins: &PinLog) -> Result<(), String> {
    let end_ns = (report.emulated_s * 1e9).max(1.0);
    let x = |ns: u64| LEFT + (WIDTH - LEFT - RIGHT) * (ns as f64 / end_ns);
    let height = 80.0 + LANE * (LANES.len() as f64 + 3.0);
    let mut s = String::new();
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{WIDTH}" height="{height}" font-family="sans-serif" font-size="11">"#
    );
    let _ = writeln!(
        s,
        r#"<text x="10" y="18" font-size="13">{} on the emulated Pico: {:.1} s, detected {} of {}, collisions {}, reached the door {}</text>"#,
        escape(&report.scenario),
        report.emulated_s,
        report.detected,
        report.interferences,
        report.collisions,
        report.reached_door
    );
    for (i, (label, name)) in LANES.iter().enumerate() {
        let top = 40.0 + LANE * i as f64;
        let _ = writeln!(s, r#"<text x="10" y="{}">{label}</text>"#, top + 15.0);
        let duty = name.starts_with("duty");
        // Inputs start high (pulled up) but the echo; outputs low.
        let mut level: i64 = i64::from(matches!(*name, "in4" | "in5" | "in6"));
        let mut since = 0u64;
        let draw = |s: &mut String, from: u64, to: u64, level: i64| {
            if level <= 0 || to <= from {
                return;
            }
            let h = if duty {
                (LANE - 6.0) * level.min(1000) as f64 / 1000.0
            } else {
                LANE - 6.0
            };
            let _ = writeln!(
                s,
                r##"<rect x="{:.2}" y="{:.2}" width="{:.2}" height="{h:.2}" fill="{}"/>"##,
                x(from),
                top + 3.0 + (LANE - 6.0 - h),
                (x(to) - x(from)).max(0.5),
                if duty { "#c77" } else { "#47a" }
            );
        };
        for (ns, _, value) in pins.entries.iter().filter(|(_, w, _)| w == name) {
            draw(&mut s, since, *ns, level);
            level = *value;
            since = *ns;
        }
        draw(&mut s, since, end_ns as u64, level);
    }
    let top = 40.0 + LANE * LANES.len() as f64;
    let _ = writeln!(s, r#"<text x="10" y="{}">world</text>"#, top + 15.0);
    // Labels of events close together alternate between two rows.
    let mut last_x = f64::NEG_INFINITY;
    let mut row = 0.0;
    for (ms, _, event) in &pins.world {
        let (colour, what) = match event {
            WorldEvent::Appeared { index, .. } => ("#080", format!("+{}", index + 1)),
            WorldEvent::Removed(i) => ("#888", format!("-{}", i + 1)),
            WorldEvent::Detected(i, _) => ("#00c", format!("d{}", i + 1)),
            WorldEvent::Collided(i) => ("#c00", format!("X{}", i + 1)),
            WorldEvent::Arrived(_) => ("#000", "door".to_owned()),
            _ => continue,
        };
        let at = x(ms * 1_000_000);
        row = if at - last_x < 24.0 { 13.0 - row } else { 0.0 };
        last_x = at;
        let _ = writeln!(
            s,
            r#"<line x1="{at:.2}" y1="40" x2="{at:.2}" y2="{:.2}" stroke="{colour}" stroke-opacity="0.35"/><text x="{at:.2}" y="{:.2}" fill="{colour}">{what}</text>"#,
            top + 4.0,
            top + 15.0 + row
        );
    }
    for (ns, what, _) in pins
        .entries
        .iter()
        .filter(|(_, w, _)| w == "reset" || w.starts_with("inject"))
    {
        let at = x(*ns);
        let _ = writeln!(
            s,
            r##"<line x1="{at:.2}" y1="40" x2="{at:.2}" y2="{:.2}" stroke="#f0f"/><text x="{at:.2}" y="{:.2}" fill="#f0f">{what}</text>"##,
            top + LANE,
            top + LANE + 12.0
        );
    }
    let axis = top + LANE + 28.0;
    let _ = writeln!(
        s,
        r##"<text x="10" y="{:.2}" fill="#444">world: +n obstacle n put down, -n taken away, dn detected, Xn collided with; door: the robot at the kitchen door. Blue: a pin high; red: a duty, its height the fraction.</text>"##,
        axis + 20.0
    );
    for tick in 0..=10 {
        let ns = (end_ns / 10.0 * f64::from(tick)) as u64;
        let _ = writeln!(
            s,
            r#"<text x="{:.2}" y="{axis:.2}" text-anchor="middle">{:.1} s</text>"#,
            x(ns),
            ns as f64 / 1e9
        );
    }
    s.push_str("</svg>\n");
    std::fs::write(path, s).map_err(|e| e.to_string())
}

fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}
