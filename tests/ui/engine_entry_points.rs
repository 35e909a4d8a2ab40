// The lower-level entry points are not public: the sides are the way in (`split`).
use psmpa_core::{Actions, Body, Caps, Keys, Plans, Runtime, Sensors};
use psmpa_tests::tiny::TinyWorld;

type Rt<'r> = Runtime<'r, TinyWorld, Caps<Sensors<2>, Actions<4>, Plans<4>, Body<4>, Keys<4>>>;

fn entry_points(rt: &Rt<'_>) {
    let _ = rt.sensing();
    let _ = rt.run();
    let _ = rt.establish_initial_model();
}

fn main() {
    let _ = entry_points;
}
