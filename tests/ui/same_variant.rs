// Two names that make one Rust identifier (`go to`, `go-to`: `GoTo`): a compile error that
// names both.
psmpa_core::include_mission!(mod m = "../../../../tests/ui/same_variant.json");

fn main() {}
