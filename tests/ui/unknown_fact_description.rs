// A description of a fact the mission does not declare is refused (a typo would lose it).
psmpa_core::include_mission!(mod m = "../../../../tests/ui/unknown-fact-description.json");

fn main() {}
