// One control loop at a time: running the deciding side twice at once does not compile
// (one after the other does).
use psmpa_core::{Actions, Body, Caps, Keys, Plans, Runtime, Sensors};
use psmpa_tests::tiny::TinyWorld;

type Rt<'r> = Runtime<'r, TinyWorld, Caps<Sensors<2>, Actions<4>, Plans<4>, Body<4>, Keys<4>>>;

async fn twice(rt: &mut Rt<'_>) {
    let (_, mut deciding) = rt.split();
    let _ = psmpa_core::embassy_futures::join::join(deciding.run(), deciding.run()).await;
}

fn main() {
    let _ = twice;
}
