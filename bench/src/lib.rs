//! Shared pieces of the psmpa benchmarks.
#![deny(missing_docs)]

use psmpa_sim::scenario::Scenario;

pub mod alloc;
pub mod bonsai_plan;
pub mod hand;
pub mod psmpa_plan;
pub mod statig_plan;
pub mod workload;

/// A scenario file of `scenarios/`, by name.
pub fn scenario(name: &str) -> Scenario {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../scenarios")
        .join(format!("{name}.json"));
    match psmpa_sim::load::load(&path) {
        Ok(s) => s,
        Err(e) => panic!("{e}"),
    }
}
