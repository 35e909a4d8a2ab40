// A trace's typed views name what they list with its mission's names: another mission's
// `Plan` does not compile, and the error names the mission.
use psmpa_testkit::Recorder;

psmpa_core::include_mission!(mod hello = "../../../../testkit/tests/hello.json");
psmpa_core::include_mission!(mod dock = "../../../../examples/dock/mission.json");

fn main() {
    let trace: Recorder<hello::Hello> = Recorder::default();
    let _ = trace.plans_selected::<dock::Plan>();
}
