// A platform is written for one mission: a robot of the dock mission given to a runtime of
// Fetch Tea does not compile, and the error names the mission.
use embassy_sync::blocking_mutex::raw::NoopRawMutex;
use psmpa_core::{Act, Actuator, Config, Outcome, Platform, Reading, Sensor, SensorFault};

psmpa_core::include_mission!(mod fetch_tea = "../../../../missions/fetch-tea.json");
psmpa_core::include_mission!(mod dock = "../../../../examples/dock/mission.json");

struct DockRobot;

impl Sensor<dock::Dock> for DockRobot {
    async fn switch_on(&self, _: dock::Sensor) -> Result<(), SensorFault> {
        Ok(())
    }
    async fn switch_off(&self, _: dock::Sensor) {}
    async fn sample(&self, _: dock::Sensor) -> Result<Option<Reading>, SensorFault> {
        Ok(None)
    }
}

impl Actuator<dock::Dock> for DockRobot {
    async fn run(&self, _: Act<'_, dock::Dock>) -> Outcome {
        Outcome::Success
    }
    fn halt(&self, _: dock::Action) {}
}

impl Platform for DockRobot {
    type Mutex = NoopRawMutex;
}

async fn fly() {
    let mut rt = fetch_tea::Runtime::new(fetch_tea::FetchTea, &DockRobot, (), Config::default());
    let _ = rt.run_with_sensing().await;
}

fn main() {
    let _ = fly;
}
