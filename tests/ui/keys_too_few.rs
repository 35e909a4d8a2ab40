// A data store must hold what the mission declares: the sonar's sample and its one key need two.
psmpa_core::include_mission!(mod keyed = "../../../../tests/ui/keyed.json", keys = 1);

fn main() {}
