//! Missions compiled in with `include_mission!`: the same mission the loader gives, names as
//! enums, capacities from the file.

use psmpa_core::mission::{AnyBehaviour, Loaded, load};

psmpa_core::include_mission!(pub mod fetch_tea = "../missions/fetch-tea.json");
psmpa_core::include_mission!(mod dock = "../examples/dock/mission.json", keys = 8);

const FETCH_TEA: &[u8] = include_bytes!("../../missions/fetch-tea.json");
const DOCK: &[u8] = include_bytes!("../../examples/dock/mission.json");

#[test]
fn a_compiled_mission_is_the_mission_the_loader_gives() {
    use fetch_tea::{L, NA, NF, NP, NS, W};
    let loaded: Loaded<'_, (), (), NS, NA, NP, L, W, NF> = load(FETCH_TEA, &AnyBehaviour).unwrap();
    assert_eq!(loaded.mission, fetch_tea::MISSION);
    let loaded: Loaded<
        '_,
        (),
        (),
        { dock::NS },
        { dock::NA },
        { dock::NP },
        { dock::L },
        { dock::W },
        { dock::NF },
    > = load(DOCK, &AnyBehaviour).unwrap();
    assert_eq!(loaded.mission, dock::MISSION);
}

#[test]
fn capacities_come_from_the_file() {
    // 8 facts, 4 sensors, 6 actions, 1 plan of 3 actions in one word.
    assert_eq!(
        (
            fetch_tea::NF,
            fetch_tea::NS,
            fetch_tea::NA,
            fetch_tea::NP,
            fetch_tea::L,
            fetch_tea::W
        ),
        (8, 4, 6, 1, 3, 1)
    );
    // A reading and all its pairs by default; what `keys` says otherwise.
    assert_eq!(fetch_tea::K, psmpa_core::platform::MAX_PAIRS + 1);
    assert_eq!(dock::K, 8);
}

#[test]
fn names_are_enums_with_the_missions_names_and_ids() {
    use fetch_tea::{Action, Event, Fact, Plan, Sensor};
    let d = &fetch_tea::MISSION.domain;
    assert_eq!(Action::GoToDoor.name(), "go to door");
    assert_eq!(Some(Action::GoToDoor.id()), d.action_id("go to door"));
    assert_eq!(
        Action::from_id(Action::EnterByBackDoor.id()),
        Some(Action::EnterByBackDoor)
    );
    assert_eq!(
        Sensor::ALL.map(Sensor::name),
        ["sonar", "bumper", "camera", "handle"]
    );
    assert_eq!(Some(Fact::PathClear.id()), d.fact_id("path_clear"));
    assert_eq!(Event::FetchTea.to_string(), "fetch_tea");
    assert_eq!(Plan::GetInKitchen.name(), "GetIn Kitchen");
    assert_eq!(Sensor::from_id(psmpa_core::SensorId::new(9).unwrap()), None);
}

/// A platform written for the dock mission: its ids are `dock`'s enums.
struct DockOnly;

impl psmpa_core::Sensor for DockOnly {
    type Id = dock::Sensor;

    async fn switch_on(&self, _: dock::Sensor) -> Result<(), psmpa_core::SensorFault> {
        Ok(())
    }
    async fn switch_off(&self, _: dock::Sensor) {}
    async fn sample(
        &self,
        _: dock::Sensor,
    ) -> Result<Option<psmpa_core::Reading>, psmpa_core::SensorFault> {
        Ok(Some(psmpa_core::Reading::flag(true)))
    }
}

impl psmpa_core::Actuator for DockOnly {
    type Id = dock::Action;
    fn halt(&self, _: dock::Action) {} // nothing to stop

    async fn run(&self, _: dock::Action, _: &psmpa_core::ActionIo<'_>) -> psmpa_core::Outcome {
        psmpa_core::Outcome::Success
    }
}

impl psmpa_core::Platform for DockOnly {
    type Mutex = embassy_sync::blocking_mutex::raw::NoopRawMutex;
}

#[test]
fn a_platform_written_for_another_mission_is_an_error_before_anything_runs() {
    use fetch_tea::{K, L, NA, NF, NP, NS, W};
    // Fetch Tea has six actions, the dock's enum four: the fifth has no name on the platform.
    let mut rt: psmpa_core::Engine<'_, DockOnly, psmpa_testkit::Recorder, NS, NA, NP, L, K, W, NF> =
        psmpa_core::Engine::new(
            &fetch_tea::MISSION,
            &DockOnly,
            psmpa_testkit::Recorder::default(),
            psmpa_core::Config::default(),
        );
    let done = psmpa_testkit::simulate(rt.run_with_sensing(), embassy_time::Duration::from_secs(1))
        .unwrap();
    let error = done.output.unwrap_err();
    assert_eq!(
        error,
        psmpa_core::ControlError::Unbound {
            sensor: None,
            action: Some(fetch_tea::Action::ALL[4].id()),
        }
    );
    use psmpa_core::Describe;
    assert_eq!(
        fetch_tea::MISSION.describe_error(error).to_string(),
        format!(
            "the platform is written for another mission: it has no action {}",
            fetch_tea::Action::ALL[4]
        )
    );
    // Nothing ran: no sensor switched on, no state entered, at no time.
    assert_eq!(done.elapsed, embassy_time::Duration::from_ticks(0));
    assert!(rt.into_sink().0.is_empty());
}

#[test]
fn a_compiled_runtime_is_named_by_its_module_and_built_by_inference() {
    // `dock::Runtime::new` infers the platform and the sink from its arguments.
    let mut rt = dock::Runtime::new(
        &dock::MISSION,
        &DockOnly,
        psmpa_testkit::Recorder::default(),
        psmpa_core::Config::default(),
    );
    let done =
        psmpa_testkit::simulate(rt.run_with_sensing(), embassy_time::Duration::from_secs(10))
            .unwrap();
    // Every sensor says all it perceives holds: "drive in" runs to the goal.
    let report = done.output.unwrap();
    assert!(report.beliefs.contains(dock::Fact::Docked.id()));
    assert_eq!(
        rt.into_sink().plans_selected::<dock::Plan>(),
        [dock::Plan::DriveIn]
    );
}

psmpa_core::include_mission!(mod blind = "missions/no-sensors.json");
psmpa_core::include_mission!(mod unplanned = "missions/no-plans.json");

/// A robot with no sensors: its sensor enum has no value, so it has nothing to match.
struct Blind;

impl psmpa_core::Sensor for Blind {
    type Id = blind::Sensor;

    async fn switch_on(&self, id: blind::Sensor) -> Result<(), psmpa_core::SensorFault> {
        match id {}
    }
    async fn switch_off(&self, id: blind::Sensor) {
        match id {}
    }
    async fn sample(
        &self,
        id: blind::Sensor,
    ) -> Result<Option<psmpa_core::Reading>, psmpa_core::SensorFault> {
        match id {}
    }
}

impl psmpa_core::Actuator for Blind {
    type Id = blind::Action;
    fn halt(&self, _: blind::Action) {} // nothing to stop

    async fn run(&self, _: blind::Action, _: &psmpa_core::ActionIo<'_>) -> psmpa_core::Outcome {
        psmpa_core::Outcome::Success
    }
}

impl psmpa_core::Platform for Blind {
    type Mutex = embassy_sync::blocking_mutex::raw::NoopRawMutex;
}

#[test]
fn a_mission_with_no_sensors_or_no_plans_compiles_as_check_accepts_it() {
    assert_eq!((blind::NS, unplanned::NP), (0, 0));
    assert!(blind::Sensor::ALL.is_empty() && unplanned::Plan::ALL.is_empty());
    assert_eq!(
        blind::Sensor::from_id(psmpa_core::SensorId::new(0).unwrap()),
        None
    );
    // With no sensor, the plan's actions still run to the goal.
    let mut rt = blind::Runtime::new(
        &blind::MISSION,
        &Blind,
        psmpa_testkit::Recorder::default(),
        psmpa_core::Config::default(),
    );
    let done =
        psmpa_testkit::simulate(rt.run_with_sensing(), embassy_time::Duration::from_secs(10))
            .unwrap();
    assert!(
        done.output
            .unwrap()
            .beliefs
            .contains(blind::Fact::Done.id())
    );
}

psmpa_core::include_mission!(mod symbols = "missions/unicode-names.json");

#[test]
fn names_of_digits_and_symbols_outside_ascii_make_identifiers() {
    // `²`, `①`, `½` continue no identifier (split there); `٣` continues one but cannot start it.
    assert_eq!(
        format!("{:?}", symbols::Fact::ALL),
        "[X, N\u{663}x, Unnamed, Cup]"
    );
    assert_eq!(
        symbols::Fact::ALL.map(symbols::Fact::name),
        ["x²", "٣x", "①", "½cup"]
    );
    assert_eq!(format!("{:?}", symbols::Plan::ALL), "[Pour]");
}

psmpa_core::include_mission!(mod described = "missions/described.json");

#[test]
fn a_description_reaches_its_variant_and_loads_at_run_time() {
    assert_eq!(
        described::Sensor::Bumper.description(),
        Some("A switch on the front bumper, closed by a touch.")
    );
    // Not a string: no description (and no doc comment).
    assert_eq!(described::Action::Drive.description(), None);
    assert_eq!(
        described::Plan::GoThere.description(),
        Some("Straight ahead.")
    );
    assert_eq!(
        described::Fact::Clear.description(),
        Some("Nothing touches the bumper.")
    );
    assert_eq!(described::Fact::There.description(), None);
    // The loader reads the same file.
    let json = include_bytes!("../missions/described.json");
    let loaded: psmpa_core::LoadedOf<'_, psmpa_core::mission::AnyBehaviour, described::Caps> =
        psmpa_core::mission::load(json, &psmpa_core::mission::AnyBehaviour).unwrap();
    assert_eq!(loaded.mission.domain, described::MISSION.domain);
}
