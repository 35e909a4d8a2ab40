// A 20 ms period at 10 Hz would be one tick, 100 ms: refused, naming the sensor, its period
// and the rate.
psmpa_core::include_mission!(mod fast = "fast-bumper.json");

fn main() {}
