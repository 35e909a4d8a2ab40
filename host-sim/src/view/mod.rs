//! `psmpa-sim view`: the running mission, live, in a browser.
//!
//! One event stream for every source, the recorder's frames ([`psmpa_core::record::Frame`]):
//! the simulator's trace events become frames as they are traced, a recording's frames are
//! played at their instants, a board's come on standard input. [`decode`] reads a frame back
//! as its trace event, [`model`] keeps what the page shows (bounded), [`source`] paces the
//! sources, and [`server`] serves the page, `GET /snapshot` and the live updates.

pub mod decode;
pub mod model;
pub mod server;
pub mod source;
