// A plan whose body names an action the mission does not have: a compile error that names it.
// (trybuild builds this file in target/tests/trybuild/psmpa-tests, the manifest folder the
// path is relative to.)
psmpa_core::include_mission!(mod m = "../../../../tests/ui/unknown-action.json");

fn main() {}
