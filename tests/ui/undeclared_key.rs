// Store keys are declared in the mission: a key the mission does not declare, a key of another
// behaviour's store, and a sensor's key in an action's own store do not compile.
use psmpa_core::{Act, Value};

psmpa_core::include_mission!(mod keyed = "../../../../tests/ui/keyed.json");

async fn run(act: Act<'_, keyed::Keyed>) {
    match act.typed() {
        keyed::Run::Walk(io) => {
            let _ = io.get(keyed::sensor::Sonar, keyed::key::EchoUs); // declared: fine
            let _ = io.put(keyed::key::Progress, Value::Int(1)); // declared: fine
            let _ = io.put(keyed::key::Speed, Value::Int(1));
            let _ = io.put(keyed::key::EchoUs, Value::Int(1));
            let _ = io.get(keyed::sensor::Sonar, keyed::key::Progress);
        }
        keyed::Run::Look(io) => {
            let _ = io.put(keyed::key::Progress, Value::Int(1));
        }
    }
}

fn main() {
    let _ = run;
}
