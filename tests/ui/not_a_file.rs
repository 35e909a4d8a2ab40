// A device is not a mission file: refused before it is read (it would never end).
psmpa_core::include_mission!(mod m = "/dev/zero");

fn main() {}
