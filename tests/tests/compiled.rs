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
