//! The pieces of the `psmpa-sim` command line: reports, Table I, sweeps, the sensitivity study and the trace, plot and
//! timeline outputs, and the MCAP log for Foxglove.

pub mod check;
pub mod files;
pub mod foxglove;
pub mod outputs;
pub mod plan;
pub mod report;
pub mod sensitivity;
pub mod sweep;
pub mod table1;
