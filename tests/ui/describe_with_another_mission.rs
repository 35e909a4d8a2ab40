// A trace is described with its own mission's names: the dock mission's do not compile.
use psmpa_testkit::Recorder;

psmpa_core::include_mission!(mod hello = "../../../../testkit/tests/hello.json");
psmpa_core::include_mission!(mod dock = "../../../../examples/dock/mission.json");

fn main() {
    let trace: Recorder<hello::Hello> = Recorder::default();
    let _ = trace.describe(&dock::Dock);
}
