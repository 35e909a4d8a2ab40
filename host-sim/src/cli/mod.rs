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

/// Starts the worker threads of `sweep`, `table1` and `sensitivity` once: a machine that will
/// not start them (an address-space or thread limit) is [`files::Stop::Resource`], one line,
/// instead of a panic inside the first parallel loop.
pub fn workers() -> Result<(), files::Stop> {
    static STARTED: std::sync::OnceLock<Result<(), String>> = std::sync::OnceLock::new();
    STARTED
        .get_or_init(|| {
            rayon::ThreadPoolBuilder::new()
                .build_global()
                .map_err(|e| format!("cannot start the worker threads: {e}"))
        })
        .clone()
        .map_err(files::Stop::Resource)
}
