// A behaviour reads the sensors that run beside its action, and no other: the walk reading the
// camera (which runs beside the look) does not compile, and the error names both.
use psmpa_core::Act;

psmpa_core::include_mission!(mod keyed = "../../../../tests/ui/keyed.json");

async fn run(act: Act<'_, keyed::Keyed>) {
    match act.typed() {
        keyed::Run::Walk(io) => {
            let _ = io.sample(keyed::sensor::Sonar); // beside the walk: fine
            let _ = io.sample(keyed::sensor::Camera);
        }
        keyed::Run::Look(io) => {
            let _ = io.sample(keyed::sensor::Camera);
        }
    }
}

fn main() {
    let _ = run;
}
