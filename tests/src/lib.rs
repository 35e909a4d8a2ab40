//! Fixtures for the end-to-end tests: a trace recorder and a tiny world.
//!
//! The tiny world is a corridor: the robot walks to a door 2 m ahead and opens it. A range
//! sensor (cyclic, 100 ms) decides `path_clear`, which "walk" needs; a camera (one-shot)
//! decides `handle_seen`, which "open" needs. Obstacles block the corridor during given time
//! windows. It is written against the core's traits the way an application would be.
#![deny(missing_docs)]

pub mod tiny;

use embassy_time::Instant;
use psmpa_core::{TraceEvent, TraceSink};

/// A sink that keeps every event (of a runtime with fact sets of `W` words).
#[derive(Debug, Default)]
pub struct Recorder<const W: usize = 1>(pub Vec<(Instant, TraceEvent<W>)>);

impl<const W: usize> TraceSink<W> for Recorder<W> {
    fn record(&mut self, at: Instant, event: &TraceEvent<W>) {
        self.0.push((at, *event));
    }
}
