// Both sides on one executor, twice at once on one runtime: does not compile (it reported
// `SensingStalled` at run time, which misled).
use psmpa_core::{Actions, Body, Caps, Keys, Plans, Runtime, Sensors};
use psmpa_tests::tiny::TinyWorld;

type Rt<'r> = Runtime<'r, TinyWorld, Caps<Sensors<2>, Actions<4>, Plans<4>, Body<4>, Keys<4>>>;

async fn twice(rt: &mut Rt<'_>) {
    let _ = psmpa_core::embassy_futures::join::join(rt.run_with_sensing(), rt.run_with_sensing())
        .await;
}

fn main() {
    let _ = twice;
}
