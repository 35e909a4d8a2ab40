// Capacities are named: actions where the sensors go is refused, saying what is expected.
use psmpa_core::{Actions, Body, Caps, Keys, MissionOf, Plans, Sensors};

type Swapped = Caps<Actions<6>, Sensors<4>, Plans<2>, Body<4>, Keys<8>>;

fn main() {
    let _: Option<MissionOf<'static, Swapped>> = None;
}
