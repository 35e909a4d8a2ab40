// The safety stop is required: an actuator that does not say how it stops does not compile.
use psmpa_core::{Act, Actuator, Outcome};

psmpa_core::include_mission!(mod hello = "../../../../testkit/tests/hello.json");

struct Robot;

impl Actuator<hello::Hello> for Robot {
    async fn run(&self, _: Act<'_, hello::Hello>) -> Outcome {
        Outcome::Success
    }
}

fn main() {}
