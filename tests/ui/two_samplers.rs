// The sensing side is handed out once: a second split while the first side runs, for a second
// sampler of every sensor, does not compile.
use psmpa_core::{Actions, Body, Caps, Config, Keys, Plans, Runtime, Sensors};
use psmpa_tests::tiny::TinyWorld;

type Rt<'r> = Runtime<'r, TinyWorld, Caps<Sensors<2>, Actions<4>, Plans<4>, Body<4>, Keys<4>>>;

fn twice(rt: &mut Rt<'_>) {
    let (sensing, _) = rt.split();
    let (again, _) = rt.split();
    drop((sensing, again));
}

fn main() {
    let _ = (twice, Config::default());
}
