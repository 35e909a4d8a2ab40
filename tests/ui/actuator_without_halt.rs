// The safety stop is required: an actuator that does not say how it stops does not compile.
use psmpa_core::{ActionId, ActionIo, Actuator, Outcome};

struct Robot;

impl Actuator for Robot {
    type Id = ActionId;

    async fn run(&self, _: ActionId, _: &ActionIo<'_>) -> Outcome {
        Outcome::Success
    }
}

fn main() {}
