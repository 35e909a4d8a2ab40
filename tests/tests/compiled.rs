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
    assert_eq!(loaded.mission, fetch_tea::TABLES);
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
    assert_eq!(loaded.mission, dock::TABLES);
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
    // Room for a sensor's sample and the keys the mission declares (none here) by default;
    // what `keys` says otherwise.
    assert_eq!(fetch_tea::K, 1);
    assert_eq!(dock::K, 8);
}

#[test]
fn names_are_enums_with_the_missions_names_and_ids() {
    use fetch_tea::{Action, Event, Fact, Plan, Sensor};
    let d = &fetch_tea::TABLES.domain;
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

/// A platform written for the dock mission (a platform for another mission does not compile:
/// `tests/ui/platform_of_another_mission.rs`).
struct DockOnly;

impl psmpa_core::Sensor<dock::Dock> for DockOnly {
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

impl psmpa_core::Actuator<dock::Dock> for DockOnly {
    fn halt(&self, _: dock::Action) {} // nothing to stop

    async fn run(&self, _: psmpa_core::Act<'_, dock::Dock>) -> psmpa_core::Outcome {
        psmpa_core::Outcome::Success
    }
}

impl psmpa_core::Platform for DockOnly {
    type Mutex = embassy_sync::blocking_mutex::raw::NoopRawMutex;
}

psmpa_core::include_mission!(mod paired = "missions/paired.json", keys = 1);

/// A sensor whose reading carries a pair its store has no room for.
struct Paired;

impl psmpa_core::Sensor<paired::Paired> for Paired {
    async fn switch_on(&self, _: paired::Sensor) -> Result<(), psmpa_core::SensorFault> {
        Ok(())
    }
    async fn switch_off(&self, _: paired::Sensor) {}
    async fn sample(
        &self,
        _: paired::Sensor,
    ) -> Result<Option<psmpa_core::Reading>, psmpa_core::SensorFault> {
        let reading = psmpa_core::Reading::flag(true)
            .with(psmpa_core::Key(1), psmpa_core::Value::Int(1_500))
            .map_err(|_| psmpa_core::SensorFault::Device(0))?;
        Ok(Some(reading))
    }
}

impl psmpa_core::Actuator<paired::Paired> for Paired {
    fn halt(&self, _: paired::Action) {} // nothing to stop

    async fn run(&self, _: psmpa_core::Act<'_, paired::Paired>) -> psmpa_core::Outcome {
        psmpa_core::Outcome::Success
    }
}

impl psmpa_core::Platform for Paired {
    type Mutex = embassy_sync::blocking_mutex::raw::NoopRawMutex;
}

/// A sensor store with no room: the sample is an error that fails the state, never dropped.
#[test]
fn a_full_sensor_store_is_an_error_not_a_silent_drop() {
    use psmpa_core::{ControlError, Failure, TraceEvent};
    // Room for the sample alone (`keys = 1`, no key declared), and the sonar puts a pair
    // under an undeclared key beside it.
    assert_eq!(paired::K, 1);
    let mut config = psmpa_core::Config::default();
    config.max_failures = 0;
    let mut rt = paired::Runtime::new(
        paired::Paired,
        &Paired,
        psmpa_testkit::Recorder::default(),
        config,
    );
    let done = psmpa_testkit::simulate(rt.run_with_sensing(), embassy_time::Duration::from_secs(5))
        .unwrap();
    // The very first sample, establishing the model, finds no room for its pair.
    assert_eq!(
        done.output,
        Err(ControlError::InitialModel {
            failure: Failure::StoreFull {
                key: psmpa_core::Key(1)
            }
        })
    );
    let trace = rt.into_sink().events;
    assert!(
        !trace
            .iter()
            .any(|(_, e)| matches!(e, TraceEvent::Sample { .. }))
    );
}

#[test]
fn a_compiled_runtime_is_named_by_its_module_and_built_by_inference() {
    // `dock::Runtime::new` infers the platform and the sink from its arguments.
    let mut rt = dock::Runtime::new(
        dock::Dock,
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

impl psmpa_core::Sensor<blind::Blind> for Blind {
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

impl psmpa_core::Actuator<blind::Blind> for Blind {
    fn halt(&self, _: blind::Action) {} // nothing to stop

    async fn run(&self, _: psmpa_core::Act<'_, blind::Blind>) -> psmpa_core::Outcome {
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
        blind::Blind,
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
    let loaded: psmpa_core::Loaded<
        '_,
        (),
        (),
        { described::NS },
        { described::NA },
        { described::NP },
        { described::L },
        { described::W },
        { described::NF },
    > = psmpa_core::mission::load(json, &psmpa_core::mission::AnyBehaviour).unwrap();
    assert_eq!(loaded.mission.domain, described::TABLES.domain);
}

/// Algorithm 2 at build time against Algorithm 2 at run time, for the compiled missions of
/// these tests: the plans from their constant states and through the run-time FSM give one
/// trace.
#[test]
fn the_constant_states_and_the_run_time_fsm_run_alike() {
    fn both<M, P>(
        mission: M,
        platform: &P,
    ) -> [Vec<(embassy_time::Instant, psmpa_core::TraceEvent)>; 2]
    where
        M: psmpa_core::Mission<Facts = psmpa_core::FactSet> + Copy,
        P: psmpa_core::Platform + psmpa_core::Sensor<M> + psmpa_core::Actuator<M>,
    {
        [psmpa_core::Plans::Compiled, psmpa_core::Plans::RunTime].map(|plans| {
            let mut config = psmpa_core::Config::default();
            config.plans = plans;
            let mut rt = psmpa_core::Runtime::new(
                mission,
                platform,
                psmpa_testkit::Recorder::<M>::default(),
                config,
            );
            let done = psmpa_testkit::simulate(
                rt.run_with_sensing(),
                embassy_time::Duration::from_secs(10),
            )
            .unwrap();
            assert!(done.output.is_ok());
            rt.into_sink().events
        })
    }
    let [constant, fsm] = both(dock::Dock, &DockOnly);
    assert!(constant.len() > 10);
    assert_eq!(constant, fsm);
    let [constant, fsm] = both(blind::Blind, &Blind);
    assert!(constant.len() > 3);
    assert_eq!(constant, fsm);
}
