//! Fixtures for the end-to-end tests: a trace recorder and a tiny world.
//!
//! The tiny world is a corridor: the robot walks to a door 2 m ahead and opens it. A range
//! sensor (cyclic, 100 ms) decides `path_clear`, which "walk" needs; a camera (one-shot)
//! decides `handle_seen`, which "open" needs. Obstacles block the corridor during given time
//! windows. It is written against the core's traits the way an application would be.
#![deny(missing_docs)]

pub mod tiny;

/// The test kit's trace recorder: a sink that keeps every event.
pub use psmpa_testkit::Recorder;
